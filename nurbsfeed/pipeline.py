"""read -> plan -> interpolate -> write for one input file. No printing: callers get reports.

The program is streamed item by item: pass-through lines are copied as bytes, each curve block
is planned, interpolated and written as G1 moves before the next item is read, so memory holds one
curve at a time whatever the output size. Output files are written to a temporary file beside the
target and renamed into place only when the whole conversion succeeded.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Callable, Iterator

import numpy as np

from nurbsfeed.errors import InputError, Location
from nurbsfeed.gcode.writer import MoveWriter, cycle_comment
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate import Interpolation, interpolate
from nurbsfeed.json_reader import json_program
from nurbsfeed.machine import Machine
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.planner import Plan, plan_curve
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem

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


def write_trace_rows(out: BinaryIO, curve_index: int, result: Interpolation,
                     curve: NurbsCurve) -> None:
    """Trace rows (SPEC §5) at full precision; u in the input's own knot range."""
    n = result.n_points
    table = np.column_stack([np.full(n, curve_index), np.arange(n), result.t_s,
                             curve.input_u(result.u),
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
        write_trace_rows(trace, index, interp, block.curve)
    return CurveResult(index, block.curve.name, block.location, interp.n_points, moves,
                       plan.length_mm, plan.cycle_time_s, block.units)


def _umask_mode() -> int:
    """0666 less the process umask: the mode `open()` would give a new file."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


_CREATE_MODE = _umask_mode()


@contextlib.contextmanager
def atomic_output(path: Path | None) -> Iterator[BinaryIO]:
    """A binary stream that becomes `path` only if the block completes; None: a temp file the
    caller copies out (stdout), so a failure never leaves partial output anywhere."""
    folder = path.parent if path is not None else None
    handle = tempfile.NamedTemporaryFile(
        "w+b", dir=folder, prefix=f".{path.name}." if path else "nurbsfeed.", suffix=".part",
        delete=False)
    try:
        with handle:
            yield handle
            handle.flush()
            if path is not None:
                os.fsync(handle.fileno())
        if path is not None:
            os.chmod(handle.name, _CREATE_MODE)  # a temp file is 0600; a new file is not
            os.replace(handle.name, path)
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
    writing = target
    try:
        with atomic_output(target) as out, contextlib.ExitStack() as stack:
            writing = trace_path
            trace = stack.enter_context(atomic_output(trace_path)) if trace_path else None
            writing = target
            if trace is not None:
                trace.write(TRACE_HEADER.encode("ascii"))
            convert_stream(items, out, machine, method, report, trace, on_curve)
            if target is None and stdout is not None:
                out.flush()
                out.seek(0)
                while chunk := out.read(1 << 20):
                    stdout.write(chunk)
    except OSError as exc:
        raise InputError(f"cannot write output ({exc.strerror or exc})",
                         Location(str(writing or "-"))) from None
    return report
