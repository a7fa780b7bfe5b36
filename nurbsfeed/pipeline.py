"""read -> plan -> interpolate -> write for one input file. No printing: callers get reports.

The program is streamed item by item: the reader (readers/) reads the input as the items are
taken, pass-through lines are copied as bytes, each curve block is planned, then stepped and
written as G1 moves chunk by chunk before the next item is read, so memory holds one chunk of one
curve at a time whatever the input size, the output size or the curve's duration. The output
reaches its file only if the whole conversion succeeded (files.atomic_output).
"""

from __future__ import annotations

import contextlib
import dataclasses
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np

from nurbsfeed.errors import CurveError, InputError, Location
from nurbsfeed.files import ENCODING, ERRORS, atomic_output
from nurbsfeed.gcode.writer import MoveWriter, cycle_comment, rapid_line
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate import PointChunk, Stepping
from nurbsfeed.machine import Machine
from nurbsfeed.planning.planner import Plan, plan_curve
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem
from nurbsfeed.readers import read_program
from nurbsfeed.safety import MotionGuard, feed_cap_mm_s

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
    if block.rapid_to_start:
        out.write(rapid_line(block.curve.points[0], machine.decimals, block.units).encode("ascii")
                  + eol)
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


def convert_file(source: Path, target: Path | None, machine: Machine, method: str = "rk2c",
                 dialect: str = "auto", trace_path: Path | None = None,
                 stdout: BinaryIO | None = None,
                 on_curve: Callable[[CurveResult], None] | None = None) -> FileReport:
    """Convert `source` into `target` (or, when target is None, onto `stdout` at the end)."""
    report = FileReport(str(source))
    items = read_program(source, dialect)
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
