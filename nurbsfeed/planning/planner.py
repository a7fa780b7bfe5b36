"""Plan one curve: the entry point (`plan_curve`), and where each limit is enforced.

The profile key `planner` chooses the planner, `jerk_model` what the machine's limits mean.

- `planner: scurve` (planning.scurve_plan; the paper model's): key points, S-curve segments, the
  limits checked at the grid's nodes, and under the path model the law sampled twice a period
  (planning.path_check) with the limit lowered where it breaks one; what is left, a uniform
  slowdown.
- `planner: optimal` (the default profile's, path model): planning.path_plan. The schedule b =
  v^2 is a spline over the cells of planning.cells; every limit of the path model (the caps,
  the accelerations, the jerks along and across the path and per axis) is a row over a cell's
  state (planning.reach_rows), and each stretch between rests runs the fastest motion its
  controllable sets allow (planning.reach_sets, reach_pass, reach_schedule: TOPP-RA's
  reachability analysis one order up); planning.schedule_law samples it at the periods. Where
  it cannot plan (a law longer than path_plan.MAX_LAW_PERIODS) the S-curve plan stands in. Its
  unit is a chain of curves merged into one: at rest at both ends, or (`chain_schedule`)
  moving at either in a given state, for a chain planned in windows.

Every plan then goes to `verified.verified_plan`, which steps it and reads its points as
positions; the motion guard (`safety`) refuses what is still above a limit.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.errors import CurveError
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.basis import AT_REST, ChainEnds
from nurbsfeed.planning.grid import Grid, build_grid
from nurbsfeed.planning.limits import Limits, curvature_threshold, speed_limit
from nurbsfeed.planning.path_check import axis_capped, least_cycle_s, path_limit
from nurbsfeed.planning.path_plan import PathSchedule, plan_path
from nurbsfeed.planning.plan import PathDiagnostics, Plan, feed_at, grid_spacing, too_long
from nurbsfeed.planning.scurve_plan import scurve_plan


def plan_curve(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray = np.empty(0),
               feed_mm_s: np.ndarray = np.empty(0), max_curve_time_s: float = math.inf,
               extra_slowdown: float = 1.0) -> Plan:
    """Plan the feed along one curve under `lim` (feed cap already in lim.feed_mm_s).
    extra_slowdown: a uniform slowdown the law takes on top of its own (the pipeline's check
    from the points asks for it, `verified.verified_plan`).

    CurveError (without a place) when the planned cycle exceeds max_curve_time_s or is not a
    finite number of periods: checked on a lower bound of the cycle before planning, then on
    the cycle itself."""
    if lim.planner == "optimal":
        plan = _path_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)
        if plan is not None:
            return plan
    return scurve_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)


def _path_plan(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
               max_curve_time_s: float, extra_slowdown: float) -> Plan | None:
    """planning.path_plan's plan on the planning grid; None where it cannot plan."""
    made = _path_schedule(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)
    if made is None:
        return None
    grid, kappa0, schedule = made
    n_peaks = int(np.count_nonzero(grid.kappa_1_mm[grid.peak_index] >= kappa0))
    plan = _schedule_plan(curve, lim, grid, kappa0, n_peaks, schedule)
    if not plan.cycle_time_s <= max_curve_time_s:
        raise CurveError(too_long(plan.cycle_time_s, max_curve_time_s))
    return plan


def plan_window(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                ends: ChainEnds, seed: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
                max_curve_time_s: float = math.inf) -> Plan | None:
    """The path planner's plan of a window of a chain that starts moving (`chain_schedule`),
    ending at rest; None where it cannot be planned so (there is no other planner to take it:
    the caller plans otherwise)."""
    made = _path_schedule(curve, lim, feed_u, feed_mm_s, max_curve_time_s, 1.0, ends, seed)
    if made is None:
        return None
    grid, kappa0, schedule = made
    n_peaks = int(np.count_nonzero(grid.kappa_1_mm[grid.peak_index] >= kappa0))
    plan = _schedule_plan(curve, lim, grid, kappa0, n_peaks, schedule)
    return plan if plan.cycle_time_s <= max_curve_time_s else None


def chain_schedule(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                   ends: ChainEnds, seed: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                   ) -> PathSchedule | None:
    """The path planner's schedule of a chain (merged into `curve`) that starts or ends moving
    in the state `ends` gives (the unit a chain planned in windows is made of, design §3b); None
    where it cannot be planned so (path_plan.plan_path). Its law starts at its first point and
    ends at its last: a moving end is reached within a share of a period. seed: the plan the
    state comes from (path_plan.plan_path)."""
    made = _path_schedule(curve, lim, feed_u, feed_mm_s, math.inf, 1.0, ends, seed)
    return None if made is None else made[2]


def _path_schedule(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                   max_curve_time_s: float, extra_slowdown: float, ends: ChainEnds = AT_REST,
                   seed: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                   ) -> tuple[Grid, float, PathSchedule] | None:
    """The planning grid, kappa_0 and planning.path_plan's schedule on the grid."""
    feed_breaks = feed_u[1:] if feed_u.size else feed_u
    kappa0 = curvature_threshold(lim)
    grid = build_grid(curve, grid_spacing(curve, lim), feed_breaks, kappa0)
    fcap = feed_at(grid.u, feed_u, feed_mm_s)
    least = least_cycle_s(curve, grid, lim, fcap)
    if not least <= max_curve_time_s:
        raise CurveError(too_long(least, max_curve_time_s, least=True))
    caps = speed_limit(grid.kappa_1_mm, lim, fcap)
    limit, _ = path_limit(curve, grid, lim, caps)
    made = plan_path(curve, grid, lim, limit, axis_capped(curve, grid, lim, caps),
                     lambda u: feed_at(u, feed_u, feed_mm_s), feed_breaks, extra_slowdown, ends,
                     seed)
    return None if made is None else (grid, kappa0, made)


def _schedule_plan(curve: NurbsCurve, lim: Limits, grid: Grid, kappa0: float, n_peaks: int,
                   schedule: PathSchedule) -> Plan:
    """A path schedule as a plan: its rests are the keys, one stretch between each two, whole
    periods each."""
    law = schedule.law
    key_t = law.key_t_s
    rest_nodes = schedule.rest_nodes
    kinds = np.asarray(schedule.kinds, dtype=np.int64)
    piece_key = np.arange(rest_nodes.size)
    periods = np.rint(np.diff(key_t) / lim.period_s).astype(np.int64)
    scale = np.ones(periods.size)
    peaks = np.array([float(law.v0_mm_s[(law.t0_s >= key_t[k]) & (law.t0_s < key_t[k + 1])]
                            .max(initial=0.0)) for k in range(rest_nodes.size - 1)])
    for arr in (rest_nodes, kinds, piece_key, periods, scale, peaks):
        arr.setflags(write=False)
    diagnostics = PathDiagnostics(kappa0_1_mm=kappa0, n_peaks_above_threshold=n_peaks,
                                  passes=schedule.passes, stretch_peak_mm_s=peaks)
    return Plan(curve=curve, limits=lim, grid=grid, key_node=rest_nodes, key_kind=kinds,
                law=law, uniform_slowdown=schedule.slowdown, piece_key=piece_key,
                piece_periods=periods, piece_scale=scale, planner=lim.planner,
                diagnostics=diagnostics, schedule=schedule.schedule)
