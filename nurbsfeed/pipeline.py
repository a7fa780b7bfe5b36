"""read -> plan -> interpolate -> write for one input file. No printing: callers get reports.

The program is streamed item by item: pass-through lines are copied as bytes, each curve block
is planned, interpolated and written as G1 moves before the next item is read, so memory holds one
curve at a time whatever the output size. Output files are written to a temporary file beside the
target and renamed into place only when the whole conversion succeeded (a device or FIFO is
written into from a temporary file at the end, never replaced).
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
from nurbsfeed.interpolate import Interpolation, interpolate
from nurbsfeed.json_reader import json_program
from nurbsfeed.machine import Machine
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.planner import Plan, plan_curve
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem
from nurbsfeed.safety import MotionGuard, feed_cap_mm_s

ENCODING = "utf-8"
ERRORS = "surrogateescape"  # any byte sequence round-trips unchanged
TRACE_HEADER = "curve,k,t,u,s,v,a,j,x,y,z\n"


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
    """Plan one curve under the machine converted to the block's units."""
    units_machine = machine.in_program_units(block.units)
    lim = Limits.from_machine(units_machine)
    return plan_curve(block.curve, lim, block.feed_u, block.feed_mm_s)


def write_trace_rows(out: BinaryIO, curve_index: int, result: Interpolation) -> None:
    """Trace rows (SPEC §5) at full precision."""
    n = result.n_points
    table = np.column_stack([np.full(n, curve_index), np.arange(n), result.t_s, result.u,
                             result.s_mm, result.v_mm_s, result.a_mm_s2, result.j_mm_s3,
                             result.points])
    np.savetxt(out, table, delimiter=",", fmt=["%d", "%d"] + ["%.17g"] * 9)


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
    """Replace one curve block by its comment line and G1 moves."""
    units_machine = machine.in_program_units(block.units)
    plan = plan_block(block, machine)
    interp = interpolate(plan, method)
    guard_limits = dataclasses.replace(plan.limits, feed_mm_s=feed_cap_mm_s(plan.limits, block))
    try:
        MotionGuard(guard_limits, f"curve {index}").check(interp.points)
    except CurveError as exc:
        raise exc.at(block.location) from None
    eol = block.eol.encode("ascii")
    out.write(cycle_comment(index, block.curve.name, interp.n_points, plan.limits.period_s,
                            method, plan.cycle_time_s, plan.length_mm,
                            block.units).encode(ENCODING, ERRORS) + eol)
    if block.curve.is_degenerate or plan.n_periods == 0:
        out.write(b"(nurbsfeed: zero-length curve, no move written)" + eol)
        moves = 0
    else:
        if block.incremental:
            out.write(b"G90" + eol)
        writer = MoveWriter(out, units_machine.decimals, units_machine.feed_decimals,
                            plan.limits.period_s, block.eol, interp.points[0])
        writer.write_curve(interp.points)
        moves = writer.moves
        if block.incremental:
            out.write(b"G91" + eol)
        if block.feed_word_after:
            out.write(block.feed_word_after.encode(ENCODING, ERRORS) + eol)
    if trace is not None:
        write_trace_rows(trace, index, interp)
    return CurveResult(index, block.curve.name, block.location, interp.n_points, moves,
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
