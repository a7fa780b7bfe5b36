"""The path planner's plan of one curve (`planner: optimal`, design §2d): the planning grid,
its rests, the cells, the schedule, the law.

    grid (planning.grid) -> rests -> cells (planning.cells) -> schedule (planning.reach_schedule:
    the fastest motion b = v^2 inside each stretch's controllable sets) -> law at the periods
    (planning.schedule_law)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.basis import AT_REST, ChainEnds
from nurbsfeed.planning.cells import build_layout
from nurbsfeed.planning.grid import Grid
from nurbsfeed.planning.limits import Limits, curvature_threshold
from nurbsfeed.planning.nodes import cut_cells, schedule_nodes
from nurbsfeed.planning.plan import KIND_CORNER, KIND_CUSP, KIND_END
from nurbsfeed.planning.reach_schedule import plan_schedule
from nurbsfeed.planning.schedule import Schedule, cell_times
from nurbsfeed.planning.schedule_law import schedule_law
from nurbsfeed.planning.timelaw import TimeLaw

# past this many periods a curve keeps the S-curve plan, whose pieces do not grow with its
# duration (the law holds a piece a period)
MAX_LAW_PERIODS = 1_000_000
MIN_STRETCH_NODES = 3  # nodes from one rest to the next (the next counted) a stretch needs
# past this many cells too: a stretch's sets take 1.3 kB a cell, and the passes hold two
MAX_CELLS = 40_000
# a schedule that dwells in cells far longer than the estimate sized them, or breaks a limit
# between a cell's points, is planned again on cells cut (nodes.cut_cells), this many times at
# most
RECUTS = 2
# ... and a chain with a moving end this many: it cannot take back what its points break by a
# slowdown
RECUTS_MOVING = 5
# a chain that ends moving keeps the state it was given there, so its schedule may not be
# slowed: past this slowdown it is not planned; below it (the passes' rounding: their states
# sit 1e-7 inside the sets' boundaries) the stretch at the moving end is not slowed (schedule_law)
OPEN_SLOWDOWN_REL = 1e-6
# A chain that starts moving starts as the last window's points moved, which lie off that
# window's law by its stepping's drift (micrometres, interpolate.landing): where that window
# was braking at its limits, no schedule from the state it hands on may keep them exactly; a
# chain that ends in a state another plan rides its limits in may find, on cells of its own,
# no way into it, or one that breaks a limit beside it by a hair. Either is planned again with
# every limit within `end_slack_mm` (the distance it may take to brake) of its moving ends
# loosened, rather than not planned: by the least of END_SLACKS_REL that leaves a way. The
# planner rides its limits and uses all of a slack, so the slack stays inside what `check`
# allows as rounding (a braking window loosened by 0.5 % rode 502.9 mm/s^2 against 500, which
# `check` refuses; by 0.02 %, 500.6): a chain no rung plans is not planned, and its window
# takes the windows' fallback (written whole, to rest). The drift a rung absorbs is
# micrometres.
END_SLACKS_REL = (2e-4, 1e-3)


@dataclass(frozen=True, eq=False)
class PathSchedule:
    """What planning.planner makes a Plan of: the law (whole periods per stretch, every
    slowdown applied), the slowdown the schedule's own check asked for (>= 1), the passes
    over the sets that found it, the grid nodes (R,) the motion rests at and their kinds (R,)
    (a moving end of the chain among them: the end of its stretch), and the schedule
    itself."""

    law: TimeLaw
    slowdown: float
    passes: int
    rest_nodes: np.ndarray
    kinds: np.ndarray
    schedule: Schedule


def end_slack_mm(lim: Limits) -> float:
    """How far from a moving end its limits may be loosened: the distance braking from the
    feed takes at most, v (v / A + A / J)."""
    v = lim.feed_mm_s
    return v * (v / lim.acc_mm_s2 + lim.acc_mm_s2 / lim.jerk_mm_s3)


def rest_nodes(grid: Grid, limit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The grid nodes (R,) where every plan rests, ascending, and their kinds (R,): the ends,
    the grid's stops (a corner or, where the tangent turns back, a cusp), nodes of infinite
    curvature and nodes whose pointwise limit limit (M,) is 0."""
    last = grid.u.size - 1
    kind = np.full(grid.u.size, -1, dtype=np.int64)
    kind[~(limit > 0.0)] = KIND_CORNER
    kind[np.isinf(grid.kappa_1_mm)] = KIND_CORNER
    stops = np.asarray(grid.stop_index, dtype=np.int64)
    kind[stops] = np.where(np.asarray(grid.stop_cos) < 0.0, KIND_CUSP, KIND_CORNER)
    kind[[0, last]] = KIND_END
    nodes = np.flatnonzero(kind >= 0)
    return nodes, kind[nodes]


def _cruise_speed(grid: Grid, lim: Limits, limit: np.ndarray,
                  feed_at_u: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """The speed the motion may cruise at at each grid node (M,): the programmed feed where the
    pointwise limit allows it, NaN elsewhere (nodes.schedule_nodes)."""
    feed = np.minimum(feed_at_u(grid.u), lim.feed_mm_s)
    return np.where(limit >= feed * (1.0 - 1e-9), feed, np.nan)


def _time(schedule: Schedule) -> float:
    """A schedule's cycle as the law will run it: slowed where its points ask."""
    return schedule.cycle_s * schedule.slowdown


def plan_path(curve: NurbsCurve, grid: Grid, lim: Limits, limit: np.ndarray, cap: np.ndarray,
              feed_at_u: Callable[[np.ndarray], np.ndarray], feed_breaks: np.ndarray,
              extra_slowdown: float = 1.0, ends: ChainEnds = AT_REST,
              seed: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
              ) -> PathSchedule | None:
    """The schedule of `curve` on `grid` under `lim` (path model); limit (M,): the pointwise
    speed limit at the grid's nodes with a = j = 0 (it says where the motion rests); cap (M,):
    the caps on the speed there (chord error, normal acceleration, feeds, axis velocities);
    feed_breaks: the parameters where the programmed feed changes; None where it cannot plan
    (a stretch of no length between two rests, over MAX_CELLS cells, a stretch without a motion
    inside its sets, a law above MAX_LAW_PERIODS periods).

    The curve is a chain (design §3b) that starts and ends at rest, or moving in the state
    `ends` gives (its speed and acceleration there): the look-ahead of a chain planned in
    windows. A moving end's state is kept as given, so such a chain is not planned (None) where
    it breaks a limit there, where the curve must rest there (a corner, a pointwise limit of
    0), where a stretch has no motion inside its sets, or where its schedule would have to be
    slowed. seed: the plan that state comes from where the two overlap, as its nodes' arc (N,)
    on this curve, its coefficients' abscissae and values (K,): its cells are this plan's there
    and its schedule the first linearisation point (and a floor, reach_schedule.SEED_KEEP),
    so that it is a motion this plan's sets allow (a time-optimal plan rides its limits: from
    its state, a plan on nodes of its own may find no way to brake in time)."""
    rests, kinds = rest_nodes(grid, limit)
    if rests.size < 2 or not np.all(np.diff(grid.s_mm[rests]) > 0.0):
        return None
    moving = np.array(ends.moving)
    ends_at = np.array([0, grid.u.size - 1])
    must_rest = (~(limit[ends_at] > 0.0) | np.isinf(grid.kappa_1_mm[ends_at])
                 | np.isin(ends_at, np.asarray(grid.stop_index, dtype=np.int64)))
    if np.any(moving & must_rest):
        return None
    nodes = schedule_nodes(curve, grid, lim, rests, cap, curvature_threshold(lim), feed_breaks,
                           MAX_CELLS, ends, np.empty(0) if seed is None else seed[0],
                           _cruise_speed(grid, lim, limit, feed_at_u))
    # a stretch needs two knots of its own between its rest cells: one too short to hold them
    # (a few millionths of the curve between two rests) is the S-curve plan's
    if (nodes is None or int(nodes[2].sum()) != rests.size
            or np.diff(np.flatnonzero(nodes[2])).min() < MIN_STRETCH_NODES):
        return None
    s_mm, u, rest, v_estimate = nodes
    layout = build_layout(curve, grid, lim, s_mm, u, rest, v_estimate, feed_at_u, ends)
    slack = (0.0, 0.0)
    schedule = plan_schedule(layout, lim, None, None if seed is None else seed[1:])
    for share in END_SLACKS_REL if moving.any() else ():
        if schedule.solved and schedule.slowdown <= 1.0 + OPEN_SLOWDOWN_REL:
            break
        slack = (share, end_slack_mm(lim))
        schedule = plan_schedule(layout, lim, None, None if seed is None else seed[1:], slack)
    if not schedule.solved:
        return None
    # the fastest schedule that breaks no limit between a cell's points is kept: cells cut for
    # the time spent in them are cut to win time, and a plan on them can lose it (beside a
    # 14 um hairpin passed at rest at F10 mm/min, the plan on the cut cells creeps into the
    # rest cell for 14 s)
    kept = None if schedule.broken_between.any() or moving.any() else (layout, schedule)
    for _ in range(RECUTS_MOVING if moving.any() else RECUTS):
        times = np.empty(layout.cells.shape[0] + 2 * layout.first.size)
        cell_times(np.array(schedule.c), layout.cells, layout.first, layout.last, layout.rest_h,
                   times)
        nodes = cut_cells(curve, grid, lim, layout, times[:layout.cells.shape[0]],
                          schedule.broken_between)
        if nodes is None or nodes[0].size > MAX_CELLS:
            break
        finer = build_layout(curve, grid, lim, *nodes, feed_at_u, ends)
        # linearised first at the last schedule (its polygon): it is nearly the answer
        cut = plan_schedule(finer, lim, np.interp(finer.xi, layout.xi, schedule.c),
                            None if seed is None else seed[1:], slack)
        if not cut.solved:
            break
        layout, schedule = finer, cut
        if not (moving.any() or schedule.broken_between.any()) and (
                kept is None or _time(schedule) < _time(kept[1])):
            kept = (layout, schedule)
    if kept is not None and (schedule.broken_between.any() or _time(kept[1]) < _time(schedule)):
        layout, schedule = kept
    if not schedule.cycle_s * schedule.slowdown * extra_slowdown < MAX_LAW_PERIODS * lim.period_s:
        return None
    if moving.any() and schedule.slowdown * extra_slowdown > 1.0 + OPEN_SLOWDOWN_REL:
        return None
    law, _ = schedule_law(schedule, lim.period_s, extra_slowdown)
    return PathSchedule(law, schedule.slowdown * extra_slowdown, schedule.passes, rests, kinds,
                        schedule)
