"""read -> plan -> interpolate -> write for one input file. No printing: callers get reports.

The program is streamed item by item: pass-through lines are copied as bytes, each curve block
is planned, then stepped and written as G1 moves chunk by chunk before the next item is read, so
memory holds one chunk of one curve at a time whatever the output size or the curve's duration.
Output files are written to a temporary file beside the target and renamed into place only when
the whole conversion succeeded (a device or FIFO is written into from a temporary file at the end,
never replaced).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
import shutil
import stat
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Callable, Iterator

import numpy as np

from nurbsfeed.errors import CurveError, InputError, Location
from nurbsfeed.gcode.writer import MoveWriter, cycle_comment
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate import PointChunk, Stepping
from nurbsfeed.json_reader import json_program
from nurbsfeed.machine import Machine
from nurbsfeed.planning.planner import Plan, plan_curve
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem
from nurbsfeed.safety import MotionGuard, feed_cap_mm_s

ENCODING = "utf-8"
ERRORS = "surrogateescape"  # any byte sequence round-trips unchanged
TRACE_HEADER = "curve,k,t,u,s,v,a,j,x,y,z\n"
TRACE_ROW = ",".join(["%d", "%d"] + ["%.17g"] * 9) + "\n"


@dataclass(frozen=True)
class CurveResult:
    """What one converted curve amounted to."""

    index: int
    name: str
    location: Location
    n_points: int
    n_moves: int
    length_mm: float
    cycle_time_s: float
    units: str


@dataclass
class FileReport:
    """What one converted file amounted to (filled in as the conversion streams)."""

    source: str
    curves: list[CurveResult] = field(default_factory=list)

    @property
    def n_points(self) -> int:
        return sum(c.n_points for c in self.curves)

    @property
    def cycle_time_s(self) -> float:
        return sum(c.cycle_time_s for c in self.curves)


def read_text(path: Path) -> str:
    """The file as text that round-trips byte for byte (line endings kept)."""
    try:
        with open(path, encoding=ENCODING, errors=ERRORS, newline="") as handle:
            return handle.read()
    except OSError as exc:
        raise InputError(f"cannot read input ({exc.strerror})", Location(str(path))) from None


def read_program(path: Path, text: str, dialect: str = "auto",
                 decimals: int = 4) -> Iterator[ProgramItem]:
    """JSON curves or a G-code program, as a stream of items."""
    if path.suffix.lower() == ".json" or text.lstrip().startswith("{"):
        return json_program(path, text, decimals)
    from nurbsfeed.gcode.reader import read_gcode

    return read_gcode(path, text, dialect)


def plan_block(block: CurveBlock, machine: Machine) -> Plan:
    """Plan one curve, given in mm (`CurveBlock.in_mm`), under the machine's limits; a curve the
    planner refuses (e.g. longer than max_curve_time_s) is refused at the block."""
    if not block.lengths_in_mm:
        raise ValueError("plan_block takes a block in mm: CurveBlock.in_mm()")
    try:
        return plan_curve(block.curve, machine.limits, block.feed_u, block.feed_mm_s,
                          machine.max_curve_time_s)
    except CurveError as exc:
        raise exc.at(block.location) from None


def write_trace_rows(out: BinaryIO, curve_index: int, chunk: PointChunk, period_s: float,
                     s_mm: float, curve: NurbsCurve) -> float:
    """Trace rows (design §5) of one chunk of points at full precision, u in the input's own
    knot range (curve.input_u); s_mm: the arc at the point before the chunk (0 before the
    first). Returns the arc at its last point."""
    n = chunk.u.size
    s = np.cumsum(np.concatenate(([s_mm], chunk.ds_mm)))[1:]
    v, a, j = chunk.kinematics()
    table = np.column_stack([np.full(n, curve_index), np.arange(chunk.k0, chunk.k0 + n),
                             np.arange(chunk.k0, chunk.k0 + n, dtype=float) * period_s,
                             curve.input_u(chunk.u),
                             s, v, a, j, chunk.points])
    # the rows as np.savetxt writes them, which builds a class per call: garbage that only the
    # cyclic collector frees, a call per chunk
    for row in table:
        out.write((TRACE_ROW % tuple(row)).encode("ascii"))
    return float(s[-1])


def convert_stream(items: Iterator[ProgramItem], out: BinaryIO, machine: Machine, method: str,
                   report: FileReport, trace: BinaryIO | None = None,
                   on_curve: Callable[[CurveResult], None] | None = None) -> None:
    """Write the converted program for `items` to `out`; fill `report` curve by curve."""
    index = 0
    for item in items:
        if isinstance(item, PassThrough):
            out.write(item.text.encode(ENCODING, ERRORS))
            continue
        result = convert_block(item, index, out, machine, method, trace)
        report.curves.append(result)
        if on_curve is not None:
            on_curve(result)
        index += 1


def convert_block(block: CurveBlock, index: int, out: BinaryIO, machine: Machine, method: str,
                  trace: BinaryIO | None) -> CurveResult:
    """Replace one curve block by its comment line and G1 moves.

    The curve is stepped chunk by chunk (interpolate.Stepping) and every chunk goes to the
    writer (and the trace) before the next is stepped: memory does not grow with the curve's
    duration. A curve the planner refuses is refused before anything of it is written.
    `block` comes as read, in the program's unit: converted to mm here, once, and written back
    in its unit by the writer.
    """
    block = block.in_mm()
    label = f'curve {index} "{block.curve.name}"'
    try:
        plan = plan_block(block, machine)
    except CurveError as exc:
        raise CurveError(f"{label}: {exc.message}", exc.location) from None
    n_points = 1 + plan.n_periods
    period_s = plan.limits.period_s
    guard = MotionGuard(dataclasses.replace(plan.limits,
                                            feed_mm_s=feed_cap_mm_s(plan.limits, block)), label)
    eol = block.eol.encode("ascii")
    out.write(cycle_comment(index, block.curve.name, n_points, period_s, method,
                            plan.cycle_time_s, plan.length_mm,
                            block.units).encode(ENCODING, ERRORS) + eol)
    moving = not block.curve.is_degenerate and plan.n_periods > 0
    writer = None
    if not moving:
        out.write(b"(nurbsfeed: zero-length curve, no move written)" + eol)
    else:
        if block.incremental:
            out.write(b"G90" + eol)
        writer = MoveWriter(out, machine.decimals, machine.feed_decimals, period_s, block.eol,
                            block.curve.points[0], block.units)
    s_mm = 0.0
    for chunk in Stepping(plan, method).chunks():
        try:
            guard.check(chunk.points)
        except CurveError as exc:
            raise exc.at(block.location) from None
        if writer is not None and chunk.stretch is not None:  # not the first point: the start
            writer.add_points(chunk.points)
        if trace is not None:
            s_mm = write_trace_rows(trace, index, chunk, period_s, s_mm, block.curve)
    moves = 0
    if writer is not None:
        writer.end_curve()
        moves = writer.moves
        if block.incremental:
            out.write(b"G91" + eol)
        if block.feed_word_after:
            out.write(block.feed_word_after.encode(ENCODING, ERRORS) + eol)
    return CurveResult(index, block.curve.name, block.location, n_points, moves,
                       plan.length_mm, plan.cycle_time_s, block.units)


def _umask_mode() -> int:
    """0666 less the process umask: the mode `open()` would give a new file."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


_CREATE_MODE = _umask_mode()
# Names of an open descriptor (Linux, BSD): whatever file is behind them belongs to the shell's
# redirection, so it is written into, never replaced (`-o /dev/stdout >> log` must append).
_DESCRIPTOR_PATH = re.compile(r"/dev/(stdout|stderr|fd/\d+)|/proc/(self|thread-self|\d+)/fd/\d+")
_KIND_NAMES = {stat.S_IFDIR: "a directory", stat.S_IFBLK: "a block device",
               stat.S_IFSOCK: "a socket"}


def output_target(path: Path) -> tuple[Path, bool]:
    """Where output named `path` goes, and whether it is written through rather than replaced.

    A new name or a regular file is replaced atomically (temporary file + rename); behind a
    symbolic link, the file it points to is (the link stays). A character device (/dev/null, a
    terminal), a FIFO or a descriptor's name (/dev/stdout) is opened and written, never replaced.
    Anything else (a directory, a block device, a socket, a link to nothing) is refused: nurbsfeed
    never replaces a file that is not a regular file.
    """
    where = Location(str(path))
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        if os.path.islink(path):
            raise InputError(f"cannot write output: a symbolic link to {os.readlink(path)}, "
                             "which does not exist", where) from None
        if not path.parent.is_dir():
            raise InputError(f"cannot write output: directory {path.parent} does not exist",
                             where) from None
        return path, False
    except OSError as exc:
        raise InputError(f"cannot write output ({exc.strerror})", where) from None
    if (stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)
            or _DESCRIPTOR_PATH.fullmatch(os.path.abspath(path))):
        return path, True
    if stat.S_ISREG(mode):
        return Path(os.path.realpath(path)), False
    kind = _KIND_NAMES.get(stat.S_IFMT(mode), "not a regular file")
    raise InputError(f"cannot write output: it is {kind} (nurbsfeed writes regular files, "
                     "character devices and FIFOs)", where)


@contextlib.contextmanager
def atomic_output(path: Path | None) -> Iterator[BinaryIO]:
    """A binary stream whose content reaches `path` only if the block completes.

    Always a temporary file first, removed on every way out (an error, an exception from a
    signal): renamed onto `path` (see `output_target`), or copied into it when `path` is written
    through; None: the caller copies it out (stdout). A failure never leaves partial output.
    """
    final, through = output_target(path) if path is not None else (None, False)
    folder = final.parent if final is not None and not through else None
    handle = tempfile.NamedTemporaryFile(
        "w+b", dir=folder, prefix=f".{final.name}." if folder else "nurbsfeed.", suffix=".part",
        delete=False)
    try:
        with handle:
            yield handle
            handle.flush()
            if through:
                handle.seek(0)
                with open(os.open(final, os.O_WRONLY | os.O_APPEND), "ab") as sink:
                    shutil.copyfileobj(handle, sink, 1 << 20)
            elif final is not None:
                os.fsync(handle.fileno())
        if folder is not None:
            if os.path.lexists(final) and not stat.S_ISREG(os.lstat(final).st_mode):
                raise InputError("cannot write output: it is no longer a regular file",
                                 Location(str(path)))  # swapped since output_target looked
            os.chmod(handle.name, _CREATE_MODE)  # a temp file is 0600; a new file is not
            os.replace(handle.name, final)
        else:
            os.unlink(handle.name)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(handle.name)
        raise


def convert_file(source: Path, target: Path | None, machine: Machine, method: str = "rk2c",
                 dialect: str = "auto", trace_path: Path | None = None,
                 stdout: BinaryIO | None = None,
                 on_curve: Callable[[CurveResult], None] | None = None) -> FileReport:
    """Convert `source` into `target` (or, when target is None, onto `stdout` at the end)."""
    text = read_text(source)
    report = FileReport(str(source))
    items = read_program(source, text, dialect, machine.decimals)
    writing: str | None = str(target or "-")  # which output an OSError is about; None: stdout
    try:
        with atomic_output(target) as out:
            writing = str(trace_path)
            with atomic_output(trace_path) if trace_path else contextlib.nullcontext() as trace:
                writing = str(target or "-")
                if trace is not None:
                    trace.write(TRACE_HEADER.encode("ascii"))
                convert_stream(items, out, machine, method, report, trace, on_curve)
                writing = str(trace_path)
            writing = str(target or "-")
            if target is None and stdout is not None:
                out.flush()
                out.seek(0)
                writing = None
                shutil.copyfileobj(out, stdout, 1 << 20)
                stdout.flush()
    except OSError as exc:
        if writing is None and isinstance(exc, BrokenPipeError):
            raise  # stdout's reader left (`| head`): the caller ends quietly, as Unix tools do
        raise InputError(f"cannot write output ({exc.strerror or exc})",
                         Location(writing or "-")) from None
    return report
