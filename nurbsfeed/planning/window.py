"""Where a chain planned in windows hands the motion on (design §3b): the state of a window's
plan at one of its periods, and the cells its plan had from there on.

A window is planned to rest at its end, which is past where it is written up to: the next
window starts from the last point written, moving as the plan moved there. Its plan takes that
state, b and b' = 2 a of the law at that period (the schedule's, over the square of the time
scale its stretch runs at), and `seed`: the last plan's nodes and coefficients over the same
path, from there up to `SEED_BEFORE_END` short of where that plan's approach to its own rest
could begin. A time-optimal plan rides its limits, so from its state a plan on cells of its own
may find no way to brake in time; on the same cells, linearised at the same schedule, the last
plan is one its sets allow (planning.path_plan).
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.planning.basis import ChainEnds, EndState, point_weights
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.plan import Plan

Seed = tuple[np.ndarray, np.ndarray, np.ndarray]


def approach_mm(lim: Limits) -> float:
    """How far before a rest the plan may start to slow for it: from the feed at the
    acceleration limit, with the jerk's ramps, v (v / A + A / J), twice over."""
    v, acc, jerk = lim.feed_mm_s, lim.acc_mm_s2, lim.jerk_mm_s3
    return 2.0 * v * (v / acc + acc / jerk)


def hand_on(plan: Plan, k: int) -> tuple[ChainEnds, Seed | None] | None:
    """The state of `plan` at its point k (the start of the next window) and the seed of its
    cells after it, on an arc measured from there; ChainEnds() with no seed where the motion
    rests there; None where it cannot be handed on (an S-curve plan, the point inside a rest
    cell, nothing of the plan left to seed the next one with)."""
    schedule = plan.schedule
    if schedule is None:
        return None
    t = k * plan.limits.period_s
    piece, local, v, _, _ = plan.law.sample(np.array([t]))
    s = float(plan.law.s0_mm[piece[0]] + local[0])
    speed = float(v[0])
    if not speed > 0.0:
        return ChainEnds(), None
    layout = schedule.layout
    node = layout.cell_node
    q = int(np.searchsorted(layout.s_mm[node], s, side="right")) - 1
    if q < 0 or s > layout.s_mm[node[q] + 1] or layout.rest[node[q] + 1]:
        return None  # in a rest cell: the motion is about to rest, or has just left one
    h = float(layout.cells[q, 4])
    w = np.empty((3, 3))
    cell = layout.cells[q]
    point_weights(cell[1], cell[2], cell[3], h, (s - layout.s_mm[node[q]]) / h, w)
    i0 = int(layout.cells[q, 0])
    c = np.asarray(schedule.c)
    b, d, _ = w @ c[i0:i0 + 3]
    if not b > 0.0:
        return None
    scale2 = b / speed**2  # the stretch's time scale, squared: the law's b is b / scale2
    state = EndState(speed, d / (2.0 * scale2))
    # the seed: the inner knots of this stretch after the point, up to the approach to the
    # plan's own end
    stretch = int(np.searchsorted(layout.first, i0, side="right")) - 1
    last_knot = layout.s_mm[node[layout.cells[:, 0] < layout.last[stretch] - 1][-1] + 1]
    end = min(float(last_knot), float(layout.s_mm[-1]) - approach_mm(plan.limits))
    knots = layout.s_mm[node[q + 1:]] if q + 1 < node.size else np.empty(0)
    knots = knots[knots <= end]
    if knots.size < 2:
        return ChainEnds(start=state), None
    inside = (layout.xi > layout.s_mm[node[q] + 1]) & (layout.xi < knots[-1])
    if not inside.any():
        return ChainEnds(start=state), None
    seed = (np.concatenate([[0.0], knots - s]), layout.xi[inside] - s, c[inside] / scale2)
    if not math.isfinite(float(seed[2].sum())):
        return None
    return ChainEnds(start=state), seed
