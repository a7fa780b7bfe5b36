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
import math
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np

from nurbsfeed.chains import ChainWindow, chain_items
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
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate.landing import Landing
from nurbsfeed.interpolate.stepping import Stepping
from nurbsfeed.machine import Machine
from nurbsfeed.planning.chain import Chain, Joints, chain_feed, joint_feed, joints, merge_curves
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.plan import Plan
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem
from nurbsfeed.readers import read_program
from nurbsfeed.rest_moves import RestMoves, rest_move_periods
from nurbsfeed.safety import GUARD_FEED_REL, MotionGuard, feed_cap_mm_s, slowdown_from_points
from nurbsfeed.trace import TRACE_HEADER, write_trace_rows


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


# the path planner's points read as positions (plan_block): the excess they may show, and the
# uniform slowdowns that take it back before the S-curve planner plans the curve instead
POSITION_REL = 0.005
# half the motion guard's allowance on a speed; the stepping's own error (1e-5) stays below it
POSITION_SPEED_REL = 0.5 * GUARD_FEED_REL
POSITION_ROUNDS = 2


# A plan, and how its stretches landed when `verified_plan` stepped it (None: it did not, as
# under the paper model): `Stepping` given them steps the same points without the search.
Checked = tuple[Plan, tuple[Landing, ...] | None]


def plan_block(block: CurveBlock, machine: Machine, method: str = "rk2c") -> Plan:
    """Plan one curve, given in mm (`CurveBlock.in_mm`), under the machine's limits
    (`verified_plan`); a curve the planner refuses (e.g. longer than max_curve_time_s) is
    refused at the block."""
    return _checked_block(block, machine, method)[0]


def _checked_block(block: CurveBlock, machine: Machine, method: str) -> Checked:
    """`plan_block`, with the landings of `_checked_plan`."""
    if not block.lengths_in_mm:
        raise ValueError("plan_block takes a block in mm: CurveBlock.in_mm()")
    try:
        return _checked_plan(block.curve, machine.limits, block.feed_u, block.feed_mm_s,
                             machine.max_curve_time_s, method,
                             feed_cap_mm_s(machine.limits, block))
    except CurveError as exc:
        raise exc.at(block.location) from None


def verified_plan(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                  max_curve_time_s: float = math.inf, method: str = "rk2c",
                  feed_cap: float = math.inf) -> Plan:
    """The plan of `_checked_plan`."""
    return _checked_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, method, feed_cap)[0]


def _checked_plan(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                  max_curve_time_s: float, method: str, feed_cap: float) -> Checked:
    """`planner.plan_curve`, and under the path model a look at the plan's points (design §2e):
    stepped by `method`, they are read as positions one period apart
    (`safety.slowdown_from_points`, feed_cap the highest feed on the curve); where the path's
    speed or an axis's velocity is above its limit by more than POSITION_SPEED_REL, or an axis's
    acceleration or jerk, or the jerk vector, by more than POSITION_REL, the law is slowed
    uniformly by what they ask (POSITION_ROUNDS times at most). The speeds are held closer: the
    motion guard allows them GUARD_FEED_REL (0.1 %), less than POSITION_REL (a law at a
    0.1 mm/s feed stepped to 0.100101 mm/s would be refused as a valid program).
    A path plan still above then gives way to the S-curve plan, read the same way: the one
    bounded fallback. A plan still above after all that goes on to the motion guard, which
    refuses it (exit 2, located, nothing written). The plan comes with how its stretches
    landed when its points were read (`Checked`): the conversion steps it again with them."""
    planners = [lim.planner] + (["scurve"] if lim.planner == "optimal" else [])
    plan = plan_curve(curve, lim, feed_u, feed_mm_s, max_curve_time_s)
    if lim.jerk_model != "path":  # the paper model's jerk limits are the law's and a proxy
        return plan, None
    caps = dataclasses.replace(plan.limits, feed_mm_s=min(feed_cap, plan.limits.feed_mm_s))
    for planner in planners:
        planned = dataclasses.replace(lim, planner=planner)
        if planner != lim.planner:
            plan = plan_curve(curve, planned, feed_u, feed_mm_s, max_curve_time_s)
        slowdown = 1.0
        for round_ in range(POSITION_ROUNDS + 1):
            stepping = Stepping(plan, method)
            speed, asks = slowdown_from_points(caps, (chunk.points
                                                      for chunk in stepping.chunks()))
            landed = stepping.landed
            asks = max(speed if speed > 1.0 + POSITION_SPEED_REL else 1.0,
                       asks if asks > 1.0 + POSITION_REL else 1.0)
            if asks <= 1.0:
                return plan, landed
            if round_ == POSITION_ROUNDS:
                break
            slowdown *= asks * (1.0 + POSITION_REL)
            plan = plan_curve(curve, planned, feed_u, feed_mm_s, max_curve_time_s, slowdown)
    return plan, landed  # the plan last stepped


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
        if item.ahead and trace is None and rest_move_periods(machine) == 1:
            from nurbsfeed.windowed import ChainOutput, convert_windows

            def chain_windows(first: ChainWindow) -> Iterator[ChainWindow]:
                window = first
                yield window
                while window.ahead:
                    window = next(stream)  # type: ignore[assignment]
                    yield window

            output = ChainOutput(out, machine, method)
            first = item.blocks[0]
            end = convert_windows(chain_windows(item), output, index)
            result = CurveResult(index, first.curve.name, first.location, output.points + 1,
                                 output.writer.moves if output.writer else 0, 0.0,
                                 output.cycle_s, first.units)
            report.curves.append(result)
            if on_curve is not None:
                on_curve(result)
            index = end
            continue
        for result in convert_window(item, index, out, machine, method, trace):
            report.curves.append(result)
            if on_curve is not None:
                on_curve(result)
            index += 1
        if item.ahead:  # a window at rest at its cut: the lines there come after it
            out.write(b"".join(line.text.encode(ENCODING, ERRORS)
                               for line in item.ahead_between[0]))


def convert_block(block: CurveBlock, index: int, out: BinaryIO, machine: Machine, method: str,
                  trace: BinaryIO | None) -> CurveResult:
    """Replace one curve block, alone (a chain of one), by its comment line and G1 moves."""
    return convert_window(ChainWindow((block.in_mm(),), ()), index, out, machine, method,
                          trace)[0]


def chain_block(window: ChainWindow, lim: Limits) -> tuple[CurveBlock, Chain, Joints]:
    """The window's curves as one block (planning.chain.merge_curves): the merged curve, the
    pieces' feeds as one step function with a step down at each joint that the period rule
    slows (`joint_feed`), the first block's modal state and the last one's F to restore."""
    blocks = window.blocks
    if len(blocks) == 1:
        chain = merge_curves([blocks[0].curve])
        return blocks[0], chain, joints(chain, lim)
    names = [b.curve.name for b in blocks if b.curve.name]
    chain = merge_curves([b.curve for b in blocks], names[0] if names else "")
    found = joints(chain, lim)
    feed_u, feed_mm_s = chain_feed(chain, [(b.feed_u, b.feed_mm_s) for b in blocks])
    feed_u, feed_mm_s = joint_feed(chain, found.cap_mm_s, feed_u, feed_mm_s)
    for arr in (feed_u, feed_mm_s):
        arr.setflags(write=False)
    block = dataclasses.replace(blocks[0], curve=chain.curve, feed_u=feed_u, feed_mm_s=feed_mm_s,
                                feed_word_after=blocks[-1].feed_word_after)
    return block, chain, found


class _JointLines:
    """Hands points to the writer and, where the motion crosses a joint, writes the lines read
    there, in place (design §3b): after the last point at or before the joint. `crossings`
    (J,): the count of points handed on (the chain's first point not counted) after which
    each joint's lines come; a joint whose count is not known yet is None."""

    def __init__(self, writer: MoveWriter | None, out: BinaryIO,
                 between: tuple[tuple[PassThrough, ...], ...]) -> None:
        self.writer = writer
        self.out = out
        self.between = between
        self.crossings: list[int] = []
        self.given = 0
        self.written = 0  # joints whose lines are written

    def add(self, points: np.ndarray) -> None:
        while (self.written < len(self.crossings)
               and self.crossings[self.written] <= self.given + len(points)):
            cut = self.crossings[self.written] - self.given
            self._give(points[:cut])
            points = points[cut:]
            self._lines(self.written)
            self.written += 1
        self._give(points)

    def finish(self) -> None:
        while self.written < len(self.between):  # joints at the very end (none: a safeguard)
            self._lines(self.written)
            self.written += 1

    def _give(self, points: np.ndarray) -> None:
        if len(points) and self.writer is not None:
            self.writer.add_points(points)
        self.given += len(points)

    def _lines(self, joint: int) -> None:
        lines = self.between[joint]
        if not lines:
            return
        if self.writer is not None:
            self.writer.end_curve()
        self.out.write(b"".join(line.text.encode(ENCODING, ERRORS) for line in lines))
        if self.writer is not None and any(line.words for line in lines):
            self.writer.after_lines()


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
        plan, landings = _checked_block(block, machine, method)
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
    lines = _JointLines(writer, out, window.between)
    periods = rest_move_periods(machine)
    rest = RestMoves(block.curve, plan.limits.chord_mm, periods) if periods > 1 else None
    s_mm = 0.0
    # per curve: the point index (from the chain's start) of its last point, and the moves
    # written up to it
    last_k: list[int] = []
    joint_u = chain.joint_u
    for chunk in Stepping(plan, method, landings).chunks():
        try:
            guard.check(chunk.points)
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
