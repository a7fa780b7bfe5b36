"""What every analysis needs: the curves of an input, and the time-optimal bound."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nurbsfeed.planning.limits import speed_limit
from nurbsfeed.planning.plan import Plan, feed_at
from nurbsfeed.program import CurveBlock
from nurbsfeed.readers import read_program


def time_optimal_bound_s(plan: Plan, block: CurveBlock | None = None) -> float:
    """Lower bound on the cycle time under the pointwise limit and |a_t| <= A_t alone.

    The classic two-pass integration on the grid: forward v^2 <= v_prev^2 + 2 A ds, backward the
    same, both capped by the pointwise limit of Eq. 15 (not eroded) and by the programmed feed
    of `block` (in mm, the block the plan is of; None: the machine's maximum feed alone), from
    rest to rest. No schedule that respects the limits can be faster; a jerk limit only makes
    it slower.

    Over each grid interval the time is the least with |a| <= A between the passes' speeds v0,
    v1 at its ends and under the higher of their caps c: accelerate, cruise at c if the peak
    sqrt((v0^2 + v1^2 + 2 A ds) / 2) would pass it, decelerate. (Taking v^2 linear in s over
    the interval instead, 2 ds / (v0 + v1), is right only where A binds throughout: where the
    cap binds, a slow programmed F, it overstates the first and last intervals several times.)
    """
    grid, lim = plan.grid, plan.limits
    if grid.length_mm == 0.0:
        return 0.0
    ds = np.diff(grid.s_mm)
    programmed: np.ndarray | float = np.inf
    if block is not None and block.feed_mm_s.size:
        programmed = feed_at(grid.u, block.feed_u, block.feed_mm_s)
    cap = speed_limit(grid.kappa_1_mm, lim, programmed)
    # an interval's cap; between two stops (cap 0 at both ends) the grid sets none
    inside = np.maximum(cap[:-1], cap[1:])
    inside[inside == 0.0] = np.inf
    cap[0] = cap[-1] = 0.0
    v2 = cap**2
    acc = lim.acc_mm_s2
    for i in range(1, v2.size):
        v2[i] = min(v2[i], v2[i - 1] + 2.0 * acc * ds[i - 1])
    for i in range(v2.size - 2, -1, -1):
        v2[i] = min(v2[i], v2[i + 1] + 2.0 * acc * ds[i])
    v0, v1 = np.sqrt(v2[:-1]), np.sqrt(v2[1:])
    peak = np.minimum(np.sqrt(0.5 * (v2[:-1] + v2[1:]) + acc * ds), inside)
    cruise_mm = np.maximum(ds - (2.0 * peak**2 - v2[:-1] - v2[1:]) / (2.0 * acc), 0.0)
    cruise_s = np.divide(cruise_mm, peak, out=np.zeros_like(ds), where=peak > 0.0)
    return float(np.sum((2.0 * peak - v0 - v1) / acc + cruise_s))


def curve_blocks(path: Path, dialect: str = "auto") -> list[CurveBlock]:
    """The NURBS curves of an input file, in file order, in mm (`CurveBlock.in_mm`)."""
    return [item.in_mm() for item in read_program(path, dialect) if isinstance(item, CurveBlock)]
