"""read -> chain -> plan -> interpolate -> write for one input file. No printing: callers get
reports.

Curves that join are gathered into chains (chains.chain_items) and each chain is merged into one
curve (planning.chain) and converted as one (`convert_window`); a curve alone is a chain of one.

The program is streamed item by item: the reader (readers/) reads the input as the items are
taken, pass-through lines are copied as bytes, each curve block is planned, then stepped and
written as G1 moves chunk by chunk before the next item is read, so memory holds one chunk of one
curve at a time whatever the input size, the output size or the curve's duration. The output
reaches its file only if the whole conversion succeeded (files.atomic_output). On its way to the
writer (gcode.writer) each chunk is guarded (safety.MotionGuard) and, under a profile that asks
for it, its moves beside a rest are merged (rest_moves); --trace writes its rows (trace).
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

from nurbsfeed import windowed
from nurbsfeed.chains import ChainWindow, chain_block, chain_items
from nurbsfeed.errors import CurveError, InputError, Location
from nurbsfeed.files import ENCODING, ERRORS, atomic_output
from nurbsfeed.gcode.profile_record import record_lines
from nurbsfeed.gcode.writer import (
    ZERO_LENGTH_COMMENT,
    MoveWriter,
    chain_comment,
    comment_line,
    cycle_comment,
    rapid_line,
)
from nurbsfeed.interpolate.stepping import Stepping
from nurbsfeed.joint_lines import JointLines
from nurbsfeed.machine import Machine
from nurbsfeed.planning.chain import Chain
from nurbsfeed.planning.plan import Plan
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem
from nurbsfeed.readers import read_program
from nurbsfeed.rest_moves import RestMoves, rest_move_periods
from nurbsfeed.safety import MotionGuard, feed_cap_mm_s
from nurbsfeed.trace import TRACE_HEADER, write_trace_rows
from nurbsfeed.verified import (
    POSITION_REL,
    POSITION_ROUNDS,
    POSITION_SPEED_REL,
    _checked_block,
    plan_block,
    verified_plan,
)
from nurbsfeed.windowed import ChainOutput, convert_windows

# what callers read from here (planning, checking and merging live beside it)
__all__ = ["POSITION_REL", "POSITION_ROUNDS", "POSITION_SPEED_REL", "CurveResult", "FileReport",
           "chain_block", "convert_block", "convert_file", "convert_stream", "convert_window",
           "joint_speeds", "plan_block", "read_program", "verified_plan"]



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


def convert_stream(items: Iterator[ProgramItem], out: BinaryIO, machine: Machine, method: str,
                   report: FileReport, trace: BinaryIO | None = None,
                   on_curve: Callable[[CurveResult], None] | None = None) -> None:
    """Write the converted program for `items` to `out`; fill `report` curve by curve. Curves
    that join are converted as chains (chains.chain_items, design §3b)."""
    index = 0
    stream = iter(chain_items(items, machine))
    for item in stream:
        if isinstance(item, PassThrough):
            out.write(item.text.encode(ENCODING, ERRORS))
            continue
        if item.ahead and windowed.RUN_ON:
            output = ChainOutput(out, machine, method, trace)
            named: list[CurveBlock] = []  # the chain's curves, in order (for their results)
            start = index
            index = convert_windows(_chain_windows(item, stream, named), output, index)
            _windowed_results(start, output, named, report, on_curve)
            continue
        for result in convert_window(item, index, out, machine, method, trace):
            report.curves.append(result)
            if on_curve is not None:
                on_curve(result)
            index += 1
        if item.ahead:  # a window at rest at its cut: the lines there come after it
            out.write(b"".join(line.text.encode(ENCODING, ERRORS)
                               for line in item.ahead_between[0]))


def _chain_windows(first: ChainWindow, stream: Iterator[ChainWindow | PassThrough],
                   named: list[CurveBlock]) -> Iterator[ChainWindow]:
    """The windows of one chain from `first` on (a window that runs on is followed by the
    next window of its chain, chains.chain_items), their curves added to `named`."""
    window = first
    while True:
        named.extend(window.blocks)
        yield window
        if not window.ahead:
            return
        nxt = next(stream)
        assert isinstance(nxt, ChainWindow), "a window with a look-ahead is followed by its next"
        window = nxt


def _windowed_results(start: int, output: ChainOutput, named: list[CurveBlock], report: FileReport,
                      on_curve: Callable[[CurveResult], None] | None) -> None:
    """One result per curve of a chain converted in windows that run on (nurbsfeed.windowed),
    curves from index `start`: a curve split between two windows adds up; the moves are
    counted on the last."""
    totals: dict[int, list[float]] = {}
    for i, periods, length in output.curves:
        row = totals.setdefault(i, [0.0, 0.0])
        row[0] += periods
        row[1] += length
    last = max(totals)
    for i in sorted(totals):
        n_periods, length = totals[i]
        b = named[i - start]
        result = CurveResult(i, b.curve.name, b.location,
                             int(n_periods) + (1 if i == start else 0),
                             (output.writer.moves if output.writer else 0) if i == last else 0,
                             length, n_periods * output.machine.limits.period_s, b.units)
        report.curves.append(result)
        if on_curve is not None:
            on_curve(result)


def convert_block(block: CurveBlock, index: int, out: BinaryIO, machine: Machine, method: str,
                  trace: BinaryIO | None) -> CurveResult:
    """Replace one curve block, alone (a chain of one), by its comment line and G1 moves."""
    return convert_window(ChainWindow((block.in_mm(),), ()), index, out, machine, method,
                          trace)[0]


def convert_window(window: ChainWindow, index: int, out: BinaryIO, machine: Machine,
                   method: str, trace: BinaryIO | None) -> list[CurveResult]:
    """Replace a chain of curve blocks (one or more, in mm) by one comment line and G1 moves,
    with the lines read between the curves written in place; one result per curve.

    The chain is stepped chunk by chunk (interpolate.stepping.Stepping) and every chunk goes to the
    writer (and the trace) before the next is stepped: memory does not grow with the chain's
    duration. A chain the planner refuses is refused before anything of it is written.
    `block` comes in mm, converted once when read, and written back in its unit by the writer.
    """
    block, chain, found = chain_block(window, machine.limits)
    n_curves = len(window.blocks)
    last_index = index + n_curves - 1
    label = (f'curve {index} "{block.curve.name}"' if n_curves == 1
             else f'curves {index}-{last_index} (a chain) "{block.curve.name}"')
    try:
        checked = _checked_block(block, machine, method)
    except CurveError as exc:
        raise CurveError(f"{label}: {exc.message}", exc.location) from None
    plan = checked.plan
    n_points = 1 + plan.n_periods
    period_s = plan.limits.period_s
    guard = MotionGuard(dataclasses.replace(plan.limits,
                                            feed_mm_s=feed_cap_mm_s(plan.limits, block)), label,
                        method)
    eol = block.eol.encode("ascii")
    if block.rapid_to_start:
        out.write(rapid_line(block.curve.points[0], machine.decimals, block.units).encode("ascii")
                  + eol)
    if index == 0:  # the profile record: once, before the first curve's comment line
        out.write(b"".join(comment_line(line, block.semicolon_comments).encode("ascii") + eol
                           for line in record_lines(machine)))
    if n_curves == 1:
        comment = cycle_comment(index, block.curve.name, n_points, period_s, method,
                                plan.cycle_time_s, plan.length_mm, block.units)
    else:
        comment = chain_comment(index, last_index, block.curve.name, n_points, period_s,
                                method, plan.cycle_time_s, plan.length_mm, block.units)
    out.write(comment_line(comment, block.semicolon_comments).encode(ENCODING, ERRORS) + eol)
    moving = not block.curve.is_degenerate and plan.n_periods > 0
    writer = None
    if not moving:
        out.write(comment_line(ZERO_LENGTH_COMMENT, block.semicolon_comments).encode("ascii")
                  + eol)
    else:
        if block.incremental:
            out.write(b"G90" + eol)
        writer = MoveWriter(out, machine.decimals, machine.feed_decimals, period_s, block.eol,
                            block.curve.points[0], block.units)
    lines = JointLines(writer, out, window.between)
    periods = rest_move_periods(machine)
    rest = RestMoves(block.curve, plan.limits.chord_mm, periods) if periods > 1 else None
    s_mm = 0.0
    # per curve: the point index (from the chain's start) of its last point, and the moves
    # written up to it
    last_k: list[int] = []
    joint_u = chain.joint_u
    for chunk, maxima in checked.chunks(method):
        try:
            guard.check(chunk.points, maxima)
        except CurveError as exc:
            raise exc.at(block.location) from None
        while len(last_k) < joint_u.size and chunk.u[-1] > joint_u[len(last_k)]:
            before = int(np.searchsorted(chunk.u, joint_u[len(last_k)], side="right"))
            last_k.append(chunk.k0 + before - 1)
            lines.crossings.append(chunk.k0 + before - 1)
        if rest is not None:
            lines.add(rest.take(chunk))
        elif chunk.stretch is not None:  # not the first point: the start
            lines.add(chunk.points)
        if trace is not None:
            s_mm = write_trace_rows(trace, index, chunk, period_s, s_mm, chain)
    if rest is not None:
        lines.add(rest.finish())
    while len(last_k) < joint_u.size:  # a joint at the chain's end: no length after it
        last_k.append(plan.n_periods)
        lines.crossings.append(plan.n_periods)
    lines.add(np.empty((0, 3)))
    lines.finish()
    moves = 0
    if writer is not None:
        writer.end_curve()
        moves = writer.moves
        if block.incremental:
            out.write(b"G91" + eol)
        if block.feed_word_after:
            out.write(block.feed_word_after.encode(ENCODING, ERRORS) + eol)
    return _curve_results(window, index, plan, chain, last_k, moves)


def _curve_results(window: ChainWindow, index: int, plan: Plan, chain: Chain,
                   last_k: list[int], moves: int) -> list[CurveResult]:
    """One result per curve of a converted chain: its points and cycle from where the motion
    crossed its joints, its length from the planner's arc (the moves are counted for the chain
    as a whole, on its last curve)."""
    if len(window.blocks) == 1:
        b = window.blocks[0]
        return [CurveResult(index, b.curve.name, b.location, 1 + plan.n_periods, moves,
                            plan.length_mm, plan.cycle_time_s, b.units)]
    ends_k = [*last_k, plan.n_periods]
    grid = plan.grid
    ends_s = [*np.interp(chain.joint_u, grid.u, grid.s_mm).tolist(), plan.length_mm]
    results = []
    k_before, s_before = 0, 0.0
    for i, b in enumerate(window.blocks):
        periods = ends_k[i] - k_before
        results.append(CurveResult(index + i, b.curve.name, b.location,
                                   periods + (1 if i == 0 else 0),
                                   moves if i == len(window.blocks) - 1 else 0,
                                   ends_s[i] - s_before, periods * plan.limits.period_s,
                                   b.units))
        k_before, s_before = ends_k[i], ends_s[i]
    return results


def joint_speeds(plan: Plan, chain: Chain, method: str = "rk2c") -> np.ndarray:
    """The speed (J,) at which the stepped points of a chain's plan cross each joint: the chord
    from the last point at or before the joint to the first after it, over one period (0 where
    the motion rests on the joint)."""
    joint_u = chain.joint_u
    speeds = np.zeros(joint_u.size)
    found = 0
    last_u, last_point = -np.inf, np.zeros(3)
    for chunk in Stepping(plan, method).chunks():
        u = np.concatenate(([last_u], chunk.u))
        points = np.concatenate((last_point[None, :], chunk.points))
        while found < joint_u.size and u[-1] > joint_u[found]:
            after = int(np.searchsorted(u, joint_u[found], side="right"))
            if u[after - 1] != joint_u[found]:  # else a point rests on the joint: 0
                step = points[after] - points[after - 1]
                speeds[found] = float(np.linalg.norm(step)) / plan.limits.period_s
            found += 1
        last_u, last_point = float(u[-1]), points[-1]
    return speeds


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
