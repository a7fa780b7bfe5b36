"""What every analysis needs: the curves of an input, and the time-optimal bound."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nurbsfeed.planning.limits import speed_limit
from nurbsfeed.planning.planner import Plan
from nurbsfeed.program import CurveBlock
from nurbsfeed.readers import read_program


def time_optimal_bound_s(plan: Plan) -> float:
    """Lower bound on the cycle time under the pointwise limit and |a_t| <= A_t alone.

    The classic two-pass integration on the grid: forward v^2 <= v_prev^2 + 2 A ds, backward the
    same, both capped by the pointwise limit of Eq. 15 (not eroded), from rest to rest. No
    schedule that respects the limits can be faster; a jerk limit only makes it slower.
    """
    grid, lim = plan.grid, plan.limits
    if grid.length_mm == 0.0:
        return 0.0
    ds = np.diff(grid.s_mm)
    cap = speed_limit(grid.kappa_1_mm, lim, np.inf)
    cap[0] = cap[-1] = 0.0
    v2 = np.minimum(cap, lim.feed_mm_s) ** 2
    two_a = 2.0 * lim.acc_mm_s2
    for i in range(1, v2.size):
        v2[i] = min(v2[i], v2[i - 1] + two_a * ds[i - 1])
    for i in range(v2.size - 2, -1, -1):
        v2[i] = min(v2[i], v2[i + 1] + two_a * ds[i])
    v = np.sqrt(v2)
    # between two nodes at rest (a stop beside a stop) v^2 cannot grow on the grid: the
    # fastest way over ds from rest to rest is to accelerate half of it, 2 sqrt(ds / A)
    both = v[:-1] + v[1:]
    return float(np.sum(np.where(both > 0.0, 2.0 * ds / np.where(both > 0.0, both, 1.0),
                                 2.0 * np.sqrt(ds / lim.acc_mm_s2))))


def curve_blocks(path: Path, dialect: str = "auto") -> list[CurveBlock]:
    """The NURBS curves of an input file, in file order, in mm (`CurveBlock.in_mm`)."""
    return [item.in_mm() for item in read_program(path, dialect) if isinstance(item, CurveBlock)]
