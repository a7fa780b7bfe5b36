"""A long chain converted in windows that run on into each other (design §3b, "Long chains").

Each window is planned with its look-ahead (the curves after its cut) to rest at the
look-ahead's end, held until the next window has planned, then written up to its last point
before the cut that keeps clear of every knot; the next window starts there, with the rest of
that curve (planning.chain.curve_after), moving in the state the law had there, seeded with the
last plan's cells (planning.window.hand_on). Where the next window cannot be planned so, the
last one is written whole, through its look-ahead to its own rest, and the next starts after it
from rest: the one bounded fallback. One writer, motion guard and trace run on across the
windows, and so does the merging of the moves beside a rest (rest_moves, `RestMoves.hand_on`);
the comment of a section the next one goes on from ends with CONTINUED, which `check` reads to
join them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

from nurbsfeed.chains import ChainWindow, chain_block
from nurbsfeed.errors import CurveError
from nurbsfeed.files import ENCODING, ERRORS
from nurbsfeed.gcode.profile_record import record_lines
from nurbsfeed.gcode.writer import MoveWriter, chain_comment, comment_line, rapid_line
from nurbsfeed.interpolate.stepping import Stepping
from nurbsfeed.joint_lines import JointLines, write_lines
from nurbsfeed.machine import Machine
from nurbsfeed.planning.basis import AT_REST, ChainEnds
from nurbsfeed.planning.chain import Chain, curve_after
from nurbsfeed.planning.plan import Plan
from nurbsfeed.planning.planner import plan_window
from nurbsfeed.planning.window import Seed, hand_on
from nurbsfeed.program import CurveBlock, PassThrough
from nurbsfeed.rest_moves import RestMoves, rest_move_periods
from nurbsfeed.safety import MotionGuard, feed_cap_mm_s, slowdown_from_readings
from nurbsfeed.trace import write_trace_rows
from nurbsfeed.verified import POSITION_REL, POSITION_SPEED_REL, Checked, Keeper, _checked_block

# the comment of a window the next section continues (the chain goes on: check joins them)
CONTINUED = ", continued"
KNOT_CLEARANCE = 1e-3  # of a piece's span: how near a knot a hand-on point may lie
HAND_ON_TRIES = 16  # points before the cut tried as the hand-on point


# a long chain's windows run on into each other; False plans each to rest at its cut (what
# the conversion did before, and what the tests compare it with): pipeline and check read it
RUN_ON = True


@dataclass
class _Start:
    """How the next window starts: its first curve (the rest of one the last window wrote part
    of, or None), the lines at the last window's cut, the state and the seed."""

    tail: CurveBlock | None
    lines_at_cut: tuple[PassThrough, ...]
    ends: ChainEnds
    seed: Seed | None


@dataclass
class _Planned:
    window: ChainWindow
    start: _Start
    blocks: list[CurveBlock]
    between: list[tuple[PassThrough, ...]]
    block: CurveBlock
    chain: Chain
    # the plan, how it landed and its points where they were kept when it was read
    # (verified.Checked): finding the hand-on point and writing take them from here
    checked: Checked

    @property
    def plan(self) -> Plan:
        return self.checked.plan


class ChainOutput:
    """One chain's writer, motion guard and trace, run on across its windows, and per curve
    (index, periods, length) as its windows write them (a curve split between two windows
    comes twice)."""

    def __init__(self, out: BinaryIO, machine: Machine, method: str,
                 trace: BinaryIO | None = None) -> None:
        self.out, self.machine, self.method, self.trace = out, machine, method, trace
        self.writer: MoveWriter | None = None
        self.guard: MotionGuard | None = None
        self.points = 0
        self.cycle_s = 0.0
        self.trace_s = 0.0
        self.curves: list[tuple[int, int, float]] = []
        periods = rest_move_periods(machine)
        self.rest_periods = periods if periods > 1 else 0
        self.rest: RestMoves | None = None


def _plan(window: ChainWindow, start: _Start, machine: Machine, method: str,
          with_ahead: bool) -> _Planned | None:
    blocks = ([start.tail] if start.tail is not None else []) + list(window.blocks)
    between = ([start.lines_at_cut] if start.tail is not None else []) + list(window.between)
    if with_ahead:
        between.append(window.ahead_between[0])
        blocks += list(window.ahead)
        between += list(window.ahead_between[1:])
    merged = ChainWindow(tuple(blocks), tuple(between))
    block, chain, _ = chain_block(merged, machine.limits)
    if start.ends.start is None:
        return _Planned(window, start, blocks, between, block, chain,
                        _checked_block(block, machine, method))
    lim = machine.limits
    moving = plan_window(block.curve, lim, block.feed_u, block.feed_mm_s, start.ends,
                         start.seed, machine.max_curve_time_s)
    if moving is None:
        return None
    stepping = Stepping(moving, method)
    caps = dataclasses.replace(lim, feed_mm_s=min(feed_cap_mm_s(lim, block), lim.feed_mm_s))
    # read from its points as any plan is (verified.verified_plan), but not slowed: its start
    # is the state it was handed
    keeper = Keeper()
    speed, asks = slowdown_from_readings(caps, keeper.readings(stepping.chunks()))
    if speed > 1.0 + POSITION_SPEED_REL or asks > 1.0 + POSITION_REL:
        return None
    return _Planned(window, start, blocks, between, block, chain,
                    keeper.checked(moving, stepping.landed))


def _hand_on_point(planned: _Planned, method: str) -> tuple[int, float] | None:
    """The point (index, merged u) the next window starts at: the last before the cut joint,
    clear of every knot."""
    chain = planned.chain
    n_written = len(planned.blocks) - len(planned.window.ahead)
    u_cut = float(chain.u_start[n_written])
    candidates: list[tuple[int, float]] = []
    for chunk, _ in planned.checked.chunks(method):
        keep = chunk.u <= u_cut
        candidates.extend(zip(range(chunk.k0, chunk.k0 + int(keep.sum())), chunk.u[keep]))
        candidates = candidates[-HAND_ON_TRIES:]
        if not keep.all():
            break
    breaks = planned.chain.curve.span_breaks
    for k, u in reversed(candidates):
        at = int(np.searchsorted(breaks, u))
        lo, hi = breaks[max(at - 1, 0)], breaks[min(at, breaks.size - 1)]
        clearance = min(u - lo, hi - u) / max(hi - lo, 1e-300)
        if clearance >= KNOT_CLEARANCE:
            return int(k), float(u)
    return None


def _next_start(planned: _Planned, method: str) -> tuple[_Start, int] | None:
    point = _hand_on_point(planned, method)
    if point is None:
        return None
    k, u = point
    made = hand_on(planned.plan, k)
    if made is None or made[0].start is None:
        return None
    ends, seed = made
    chain = planned.chain
    piece = int(chain.piece_of(np.array([u]))[0])
    n_written = len(planned.blocks) - len(planned.window.ahead)
    if piece != n_written - 1:
        return None  # the point lies before the last written curve: not tried here
    local = float(chain.piece_u(np.array([u]), np.array([piece]))[0])
    block = planned.blocks[piece]
    curve = block.curve
    tail_curve = curve_after(curve, curve.u_min + local * (curve.u_max - curve.u_min))
    feed_u, feed_mm_s = block.feed_u, block.feed_mm_s
    if feed_u.size:  # the feed steps after the point, on the tail's parameter
        u_tail = (feed_u - local) / (1.0 - local)
        keep = u_tail > 0.0
        last_before = np.flatnonzero(~keep)
        lead = feed_mm_s[last_before[-1:]] if last_before.size else np.empty(0)
        feed_u = np.concatenate([[0.0] if lead.size else [], u_tail[keep]])
        feed_mm_s = np.concatenate([lead, feed_mm_s[keep]])
    tail = dataclasses.replace(block, curve=tail_curve, feed_u=feed_u, feed_mm_s=feed_mm_s,
                               rapid_to_start=False)
    return _Start(tail, planned.window.ahead_between[0], ends, seed), k


def _write(planned: _Planned, out: ChainOutput, index: int, upto: int | None,
           continued: bool) -> None:
    """Write the planned window's points after its first, up to point `upto` (None: all), with
    the lines at the joints it crosses; continued: the next section goes on with the chain."""
    machine, plan, block = out.machine, planned.plan, planned.block
    eol = block.eol.encode("ascii")
    period_s = plan.limits.period_s
    last = plan.n_periods if upto is None else upto
    if out.writer is None and block.rapid_to_start:  # a JSON curve's G0 to its start
        out.out.write(rapid_line(block.curve.points[0], machine.decimals, block.units)
                      .encode("ascii") + eol)
    if index == 0 and out.writer is None:
        out.out.write(b"".join(comment_line(line, block.semicolon_comments).encode("ascii") + eol
                               for line in record_lines(machine)))
    n_curves = len(planned.blocks) - (len(planned.window.ahead) if upto is not None else 0)
    first_part = out.writer is None
    length = plan.length_mm
    if upto is not None:
        piece, local, _, _, _ = plan.law.sample(np.array([last * period_s]))
        length = float(plan.law.s0_mm[piece[0]] + local[0])
    comment = chain_comment(index, index + n_curves - 1, block.curve.name,
                            last + (1 if first_part else 0), period_s, out.method,
                            last * period_s, length, block.units)
    if continued:
        comment = comment[:-1] + CONTINUED + comment[-1:]
    if out.writer is not None:
        out.writer.end_curve()
    out.out.write(comment_line(comment, block.semicolon_comments).encode(ENCODING, ERRORS) + eol)
    if out.writer is None:
        if block.incremental:  # the moves are absolute: bracketed by G90 ... G91
            out.out.write(b"G90" + eol)
        out.writer = MoveWriter(out.out, machine.decimals, machine.feed_decimals, period_s,
                                block.eol, block.curve.points[0], block.units)
        out.guard = MotionGuard(dataclasses.replace(
            plan.limits, feed_mm_s=feed_cap_mm_s(plan.limits, block)), block.curve.name,
            out.method)
        if out.rest_periods:
            out.rest = RestMoves(block.curve, plan.limits.chord_mm, out.rest_periods)
    if out.rest is not None:
        out.rest.curve = block.curve  # (no point of the last window is held: `hand_on`)
    between = planned.between[:len(planned.blocks) - 1]
    lines = JointLines(out.writer, out.out, tuple(between))
    joint_u = planned.chain.joint_u
    # (the readings are not taken: the guard reads on from the last window's points)
    for chunk, _ in planned.checked.chunks(out.method):
        if chunk.stretch is None:  # the start: the chain's first point, or the last written
            if first_part and out.trace is not None:
                out.trace_s = write_trace_rows(out.trace, index, chunk, period_s, out.trace_s,
                                               planned.chain)
            if out.rest is not None:
                out.rest.take(chunk)  # where the first move starts
            continue
        ks = np.arange(chunk.k0, chunk.k0 + chunk.u.size)
        keep = ks <= last
        if not keep.any():
            break
        if not keep.all():
            chunk = dataclasses.replace(chunk, u=chunk.u[keep], points=chunk.points[keep],
                                        ds_mm=chunk.ds_mm[keep])
        points, u = chunk.points, chunk.u
        if out.trace is not None:
            out.trace_s = write_trace_rows(out.trace, index,
                                           dataclasses.replace(chunk, k0=chunk.k0 + out.points),
                                           period_s, out.trace_s, planned.chain)
        assert out.guard is not None
        try:
            out.guard.check(points)
        except CurveError as exc:
            raise exc.at(block.location) from None
        while len(lines.crossings) < joint_u.size and u[-1] > joint_u[len(lines.crossings)]:
            before = int(np.searchsorted(u, joint_u[len(lines.crossings)], side="right"))
            lines.crossings.append(chunk.k0 + before - 1)
        lines.add(out.rest.take(chunk) if out.rest is not None else points)
        if ks[-1] >= last:
            break
    crossed = list(lines.crossings)
    if upto is None:
        while len(lines.crossings) < joint_u.size:  # a joint at the end: no length after it
            lines.crossings.append(last)
        crossed = list(lines.crossings)
        if out.rest is not None:
            lines.add(out.rest.finish())
        lines.add(np.empty((0, 3)))
        lines.finish()
    elif out.rest is not None:
        lines.add(out.rest.hand_on())
    ends_k = crossed[:n_curves - 1] + [last]
    grid = plan.grid
    ends_s = [*np.interp(planned.chain.joint_u[:n_curves - 1], grid.u, grid.s_mm).tolist(),
              length]
    k_before, s_before = 0, 0.0
    for b in range(n_curves):
        out.curves.append((index + b, ends_k[b] - k_before, ends_s[b] - s_before))
        k_before, s_before = ends_k[b], ends_s[b]
    out.points += last
    out.cycle_s += last * period_s


def _drop(window: ChainWindow, k: int
          ) -> tuple[ChainWindow | None, tuple[PassThrough, ...], int]:
    """The window without its first k curves, which the last window wrote (its look-ahead):
    what is left of it (None: nothing), the lines at the joint where the writing ended (to come
    now), and how many of the next window's curves are written too."""
    n = len(window.blocks)
    if k < n:
        return (ChainWindow(window.blocks[k:], window.between[k:], window.ahead,
                            window.ahead_between), window.between[k - 1], 0)
    if k == n:
        return None, window.ahead_between[0] if window.ahead else (), 0
    return None, (), k - n


def convert_windows(windows, out: ChainOutput, index: int) -> int:
    """Convert the windows of one chain (each but the last with a look-ahead), in order; returns
    the index after its last curve. Where the next window cannot be planned from the hand-on
    point, the last one is written whole, through its look-ahead to its own rest, and the next
    starts after it from rest."""
    pending: _Planned | None = None
    skip = 0
    last_block: CurveBlock | None = None
    for given in windows:
        last_block = (given.ahead or given.blocks)[-1]
        window = given
        if skip:
            dropped, lines_now, skip = _drop(given, skip)
            write_lines(out.writer, out.out, lines_now)
            if dropped is None:
                continue
            window = dropped
        if pending is not None:
            made = _next_start(pending, out.method)
            nxt = None
            if made is not None:
                nxt_start, k = made
                nxt = _plan(window, nxt_start, out.machine, out.method, bool(window.ahead))
            if nxt is not None:
                _write(pending, out, index, k, True)
                index += len(pending.blocks) - len(pending.window.ahead) - 1
            else:
                # the last window whole, to its own rest; this one after it, from rest
                skip = len(pending.window.ahead)
                rest_of, _, _ = _drop(window, skip)
                _write(pending, out, index, None, rest_of is not None or bool(window.ahead))
                index += len(pending.blocks)
                dropped, lines_now, skip = _drop(window, skip)
                write_lines(out.writer, out.out, lines_now)
                pending = None
                if dropped is None:
                    continue
                window = dropped
                nxt = _plan(window, _Start(None, (), AT_REST, None), out.machine, out.method,
                            bool(window.ahead))
            pending = nxt
        else:
            pending = _plan(window, _Start(None, (), AT_REST, None), out.machine, out.method,
                            bool(window.ahead))
        if pending is None:
            raise CurveError("a window of a chain could not be planned", window.blocks[0].location)
        if not window.ahead:
            _write(pending, out, index, None, False)
            index += len(pending.blocks)
            pending = None
    if out.writer is not None:
        out.writer.end_curve()
    if out.writer is not None and last_block is not None and last_block.incremental:
        out.out.write(b"G91" + last_block.eol.encode("ascii"))
    if last_block is not None and last_block.feed_word_after:
        out.out.write((last_block.feed_word_after + last_block.eol).encode(ENCODING, ERRORS))
    return index
