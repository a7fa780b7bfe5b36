"""A curve block's plan, checked from its points before anything is written (design §2d): the
planner's plan stepped and read as positions, slowed where they ask, the S-curve plan the one
bounded fallback (`verified_plan`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from nurbsfeed.errors import CurveError
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate.landing import Landing
from nurbsfeed.interpolate.stepping import PointChunk, Stepping
from nurbsfeed.machine import Machine
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.plan import Plan
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.program import CurveBlock
from nurbsfeed.safety import (
    GUARD_FEED_REL,
    PointReader,
    feed_cap_mm_s,
    slowdown_from_readings,
)

# the path planner's points read as positions (plan_block): the excess they may show, and the
# uniform slowdowns that take it back before the S-curve planner plans the curve instead
POSITION_REL = 0.005
# half the motion guard's allowance on a speed; the stepping's own error (1e-5) stays below it
POSITION_SPEED_REL = 0.5 * GUARD_FEED_REL
POSITION_ROUNDS = 2
# a plan's points read as positions are kept for the conversion up to this many (about 40
# bytes each: u, the point, its target), so that it neither steps them again nor takes their
# differences again; a longer curve is stepped again, chunk by chunk, with its landings
KEPT_POINTS = 1 << 18


@dataclass(frozen=True)
class Checked:
    """A plan, how its stretches landed when `_checked_plan` stepped it (None: it did not, as
    under the paper model), and the chunks of points it read with their differences'
    `PointReader` readings (None: not kept, see KEPT_POINTS)."""

    plan: Plan
    landings: tuple[Landing, ...] | None
    kept: tuple[tuple[PointChunk, np.ndarray], ...] | None = None

    def chunks(self, method: str) -> Iterator[tuple[PointChunk, np.ndarray | None]]:
        """The plan's points, chunk by chunk, each with its reading where it was kept (for
        `MotionGuard.check`): the kept chunks, or the plan stepped again with its landings (the
        same points to the last bit, `Stepping`)."""
        if self.kept is not None:
            yield from self.kept
            return
        for chunk in Stepping(self.plan, method, self.landings).chunks():
            yield chunk, None


class Keeper:
    """Reads a stepping's chunks as positions (`PointReader`), keeping chunks and readings
    while they hold at most KEPT_POINTS points."""

    def __init__(self) -> None:
        self.reader = PointReader()
        self.kept: list[tuple[PointChunk, np.ndarray]] | None = []
        self.points = 0

    def readings(self, chunks: Iterable[PointChunk]) -> Iterator[tuple[int, np.ndarray]]:
        for chunk in chunks:
            n_read, maxima = self.reader.read(chunk.points)
            self.points += chunk.u.size
            if self.kept is not None:
                self.kept.append((chunk, maxima))
                if self.points > KEPT_POINTS:
                    self.kept = None
            yield n_read, maxima

    def checked(self, plan: Plan, landed: tuple[Landing, ...] | None) -> Checked:
        """The plan whose stepping was read, with how it landed (None: its chunks were not all
        read) and the chunks kept."""
        kept = self.kept if landed is not None else None  # (all of them read)
        return Checked(plan, landed, None if kept is None else tuple(kept))


def plan_block(block: CurveBlock, machine: Machine, method: str = "rk2c") -> Plan:
    """Plan one curve, given in mm (`CurveBlock.in_mm`), under the machine's limits
    (`verified_plan`); a curve the planner refuses (e.g. longer than max_curve_time_s) is
    refused at the block."""
    return _checked_block(block, machine, method).plan


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
    return _checked_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, method,
                         feed_cap).plan


def _checked_plan(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                  max_curve_time_s: float, method: str, feed_cap: float) -> Checked:
    """`planner.plan_curve`, and under the path model a look at the plan's points (design §2d):
    stepped by `method`, they are read as positions one period apart
    (`safety.slowdown_from_readings`, feed_cap the highest feed on the curve); where the path's
    speed or an axis's velocity is above its limit by more than POSITION_SPEED_REL, or an axis's
    acceleration or jerk, or the jerk vector, by more than POSITION_REL, the law is slowed
    uniformly by what they ask (POSITION_ROUNDS times at most). The speeds are held closer: the
    motion guard allows them GUARD_FEED_REL (0.1 %), less than POSITION_REL (a law at a
    0.1 mm/s feed stepped to 0.100101 mm/s would be refused as a valid program).
    A path plan still above then gives way to the S-curve plan, read the same way: the one
    bounded fallback. A plan still above after all that goes on to the motion guard, which
    refuses it (exit 2, located, nothing written). The plan comes with how its stretches
    landed when its points were read, and those points with their readings where there are few
    enough (`Checked`): the conversion writes them, or steps the plan again with the landings."""
    planners = [lim.planner] + (["scurve"] if lim.planner == "optimal" else [])
    plan = plan_curve(curve, lim, feed_u, feed_mm_s, max_curve_time_s)
    if lim.jerk_model != "path":  # the paper model's jerk limits are the law's and a proxy
        return Checked(plan, None)
    caps = dataclasses.replace(plan.limits, feed_mm_s=min(feed_cap, plan.limits.feed_mm_s))
    for planner in planners:
        planned = dataclasses.replace(lim, planner=planner)
        if planner != lim.planner:
            plan = plan_curve(curve, planned, feed_u, feed_mm_s, max_curve_time_s)
        slowdown = 1.0
        for round_ in range(POSITION_ROUNDS + 1):
            stepping = Stepping(plan, method)
            keeper = Keeper()
            speed, asks = slowdown_from_readings(caps, keeper.readings(stepping.chunks()))
            landed = stepping.landed
            asks = max(speed if speed > 1.0 + POSITION_SPEED_REL else 1.0,
                       asks if asks > 1.0 + POSITION_REL else 1.0)
            if asks <= 1.0:
                return keeper.checked(plan, landed)
            if round_ == POSITION_ROUNDS:
                break
            slowdown *= asks * (1.0 + POSITION_REL)
            plan = plan_curve(curve, planned, feed_u, feed_mm_s, max_curve_time_s, slowdown)
    return Checked(plan, landed)  # the plan last stepped
