"""Program items -> chains: runs of curves that join, in windows of bounded size (design §3b).

A curve joins the one before it when it starts where that one ended, as the output writes
points (equal coordinates at the output's decimals), and everything read between them joins too
(`PassThrough.joins`: comments, N numbers, zero-length G0 / G1 moves, modal words that change
nothing); both curves must be of one degree, unit, distance mode and line ending
(`planning.chain.can_follow` for the geometry), and the next must leave in the direction the
last one arrived in: a corner (a turn above the planner's corner tolerance, CORNER_TURN_RAD) ends
a chain, since the motion comes to rest there whether the curves are planned together or apart,
and apart one curve's plan never depends on another's. In a G91 program only lines without words may
lie between (the moves are written absolute, bracketed by G90 ... G91: a word between them
would be read in the wrong mode).

Memory stays bounded: a chain is handed on in windows of at most MAX_WINDOW_CURVES curves and
about MAX_WINDOW_NODES planning nodes. A window ends at a joint and the motion rests there (the
planner plans a curve from rest to rest); the joint chosen is the most curved one in the
window's second half, where the speed limit sqrt(A_n / kappa) is lowest (inside a chain no joint
turns: a corner ends it). Lines read between two curves are
held until the chain is cut or ends (at most MAX_GAP_LINES of them between two curves, else the
chain ends there).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from nurbsfeed.gcode.writer import round_ticks, written_decimals
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import Machine
from nurbsfeed.planning.chain import (
    CORNER_TURN_RAD,
    Chain,
    Joints,
    can_follow,
    chain_feed,
    chain_weights,
    joint_feed,
    joints,
    merge_curves,
)
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.plan import GRID_STEPS
from nurbsfeed.program import MM_PER_UNIT, CurveBlock, PassThrough, ProgramItem

MAX_WINDOW_CURVES = 400
# the planner's grid nodes a window is expected to need (its length over the grid spacing at
# full feed): the grid refines around curvature peaks, and the planner's sets grow with
# the nodes
MAX_WINDOW_NODES = 12_000
MAX_GAP_LINES = 1000


@dataclass(frozen=True)
class ChainWindow:
    """Consecutive joined curves planned as one: blocks (N,) in mm, and the lines read between
    block i and block i + 1, written where the motion crosses that joint (N - 1,)."""

    blocks: tuple[CurveBlock, ...]
    between: tuple[tuple[PassThrough, ...], ...]
    # a window cut from a longer chain: the curves after its cut, which the next window starts
    # with (its look-ahead), and the lines at the cut and between them (len(ahead),)
    ahead: tuple[CurveBlock, ...] = ()
    ahead_between: tuple[tuple[PassThrough, ...], ...] = ()


def _estimated_nodes(block: CurveBlock, machine: Machine) -> float:
    points = block.curve.points
    length_mm = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    return length_mm / (GRID_STEPS * machine.limits.feed_mm_s * machine.limits.period_s)


def _same_point(a_mm: np.ndarray, b_mm: np.ndarray, machine: Machine, units: str) -> bool:
    """Whether two points (3,) in mm are written as the same point."""
    places = written_decimals(machine.decimals, units)
    ticks = round_ticks(np.stack([a_mm, b_mm]), places, 1.0 / MM_PER_UNIT[units])
    return bool(np.array_equal(ticks[0], ticks[1]))


def _joint_kappa(last: NurbsCurve, nxt: NurbsCurve) -> float:
    """The larger curvature (1/mm) on either side of the joint from `last` to `nxt`: where it is
    high the speed limit sqrt(A_n / kappa) is low."""
    kappas = []
    for curve, u in ((last, np.nextafter(last.u_max, -np.inf)), (nxt, nxt.u_min)):
        _, c1, c2 = curve.derivatives(np.array([u]))
        speed = float(np.linalg.norm(c1[0]))
        kappas.append(float(np.linalg.norm(np.cross(c1[0], c2[0]))) / speed**3
                      if speed > 0.0 else 0.0)
    return max(kappas)


def _turn(last: NurbsCurve, nxt: NurbsCurve) -> float:
    """How far the unit tangent turns from the end of `last` to the start of `nxt` (rad)."""
    _, d_end, _ = last.derivatives(np.array([np.nextafter(last.u_max, -np.inf)]))
    _, d_start, _ = nxt.derivatives(np.array([nxt.u_min]))
    a, b = d_end[0], d_start[0]
    norms = float(np.linalg.norm(a) * np.linalg.norm(b))
    if norms == 0.0:
        return np.pi
    return float(np.arccos(np.clip(a @ b / norms, -1.0, 1.0)))


class _Window:
    """The chain being gathered."""

    def __init__(self, block: CurveBlock, machine: Machine) -> None:
        self.machine = machine
        self.blocks = [block]
        self.between: list[tuple[PassThrough, ...]] = []
        self.gap: list[PassThrough] = []
        self.weights = chain_weights(block.curve)
        self.nodes = _estimated_nodes(block, machine)

    def takes(self, item: PassThrough) -> bool:
        """Hold a line read after the last curve, if a chain may run on across it."""
        last = self.blocks[-1]
        if not item.joins or len(self.gap) >= MAX_GAP_LINES or (last.incremental and item.words):
            return False
        self.gap.append(item)
        return True

    def extends(self, block: CurveBlock) -> bool:
        """Add the block if it joins the chain (module docstring)."""
        last = self.blocks[-1]
        if (block.units, block.incremental, block.eol, block.semicolon_comments) != (
                last.units, last.incremental, last.eol, last.semicolon_comments):
            return False
        if not _same_point(last.curve.points[-1], block.curve.points[0], self.machine,
                           block.units):
            return False
        weights = can_follow(last.curve, block.curve, self.weights)
        if weights is None or _turn(last.curve, block.curve) > CORNER_TURN_RAD:
            return False
        self.weights = weights
        self.blocks.append(block)
        self.between.append(tuple(self.gap))
        self.gap = []
        self.nodes += _estimated_nodes(block, self.machine)
        return True

    @property
    def full(self) -> bool:
        return len(self.blocks) > MAX_WINDOW_CURVES or (self.nodes > MAX_WINDOW_NODES
                                                        and len(self.blocks) > 1)

    def cut(self) -> Iterator[ChainWindow | PassThrough]:
        """The window up to the most curved joint in its second half, then the lines at that
        joint; the curves after it stay, as the start of the next window."""
        n = len(self.blocks)
        first = (n - 1) // 2
        kappas = [_joint_kappa(self.blocks[j].curve, self.blocks[j + 1].curve)
                  for j in range(first, n - 1)]
        j = first + int(np.argmax(kappas))
        yield ChainWindow(tuple(self.blocks[:j + 1]), tuple(self.between[:j]),
                          tuple(self.blocks[j + 1:]), tuple(self.between[j:]))
        self.blocks = self.blocks[j + 1:]
        self.between = self.between[j + 1:]
        self.weights = chain_weights(self.blocks[0].curve)
        for i in range(1, len(self.blocks)):
            weights = can_follow(self.blocks[i - 1].curve, self.blocks[i].curve, self.weights)
            assert weights is not None, "the blocks followed each other before the cut"
            self.weights = weights
        self.nodes = sum(_estimated_nodes(b, self.machine) for b in self.blocks)

    def finish(self) -> Iterator[ChainWindow | PassThrough]:
        yield ChainWindow(tuple(self.blocks), tuple(self.between))
        yield from self.gap


def chain_items(items: Iterator[ProgramItem], machine: Machine
                ) -> Iterator[ChainWindow | PassThrough]:
    """The program's items with its curves gathered into chain windows (blocks in mm), in file
    order: the lines between the curves of a window are inside it; every other line comes as
    it was, in its place."""
    window: _Window | None = None
    for item in items:
        if isinstance(item, PassThrough):
            if window is not None and window.takes(item):
                continue
            if window is not None:
                yield from window.finish()
                window = None
            yield item
            continue
        block = item.in_mm()
        if window is not None and window.extends(block):
            if window.full:
                yield from window.cut()
            continue
        if window is not None:
            yield from window.finish()
        window = _Window(block, machine)
    if window is not None:
        yield from window.finish()


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
