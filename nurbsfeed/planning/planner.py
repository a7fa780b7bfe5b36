"""Plan one curve: the entry point (`plan_curve`), and where each limit is enforced.

The profile key `planner` chooses the planner, `jerk_model` what the machine's limits mean.

- `planner: scurve` (planning.scurve_plan; the paper model's, and the fallback): key points,
  S-curve segments, the limits checked at the grid's nodes, and under the path model the law
  sampled twice a period (planning.path_check) with the limit lowered where it breaks one;
  what is left, a uniform slowdown.
- `planner: envelope` (planning.envelope_plan and planning.envelope; the default profile's):
  the greatest b = v^2 that the path model's caps, slopes and curvatures allow, found by
  passes over the nodes (planning.envelope_passes, the bounds from planning.envelope_rows),
  its law sampled twice a period and lowered cell by cell where it breaks a limit. The S-curve
  plan stands in where the envelope gives way, and is compared (the faster kept) where the
  curve stops inside or the envelope's plan is slowed by more than 5 %.
- `planner: optimal` (planning.optimal): linear programs over b, starting from the S-curve
  plan.

Every plan then goes to `pipeline.verified_plan`, which steps it and reads its points as
positions; the motion guard (`safety`) refuses what is still above a limit.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.errors import CurveError
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.envelope_plan import FALLBACK_SLOWDOWN, plan_envelope
from nurbsfeed.planning.grid import Grid, build_grid
from nurbsfeed.planning.limits import Limits, curvature_threshold, speed_limit
from nurbsfeed.planning.optimal import optimal_schedule
from nurbsfeed.planning.path_check import least_cycle_s, path_limit
from nurbsfeed.planning.path_model import scurve_limits
from nurbsfeed.planning.plan import Plan, feed_at, grid_spacing, too_long
from nurbsfeed.planning.scurve_plan import scurve_plan


def plan_curve(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray = np.empty(0),
               feed_mm_s: np.ndarray = np.empty(0), max_curve_time_s: float = math.inf,
               extra_slowdown: float = 1.0) -> Plan:
    if lim.planner == "path":
        plan = _path_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)
        if plan is not None:
            return plan
        return scurve_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)
    return _plan_curve(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)


def _path_plan(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
               max_curve_time_s: float, extra_slowdown: float) -> Plan | None:
    from nurbsfeed.planning.path_plan import plan_path

    feed_breaks = feed_u[1:] if feed_u.size else feed_u
    kappa0 = curvature_threshold(lim)
    grid = build_grid(curve, grid_spacing(curve, lim), feed_breaks, kappa0)
    fcap = feed_at(grid.u, feed_u, feed_mm_s)
    least = least_cycle_s(curve, grid, lim, fcap)
    if not least <= max_curve_time_s:
        raise CurveError(too_long(least, max_curve_time_s, least=True))
    limit, _ = path_limit(curve, grid, lim, speed_limit(grid.kappa_1_mm, lim, fcap))
    made = plan_path(curve, grid, lim, limit, lambda u: feed_at(u, feed_u, feed_mm_s),
                     feed_breaks, extra_slowdown)
    if made is None:
        return None
    n_peaks = int(np.count_nonzero(grid.kappa_1_mm[grid.peak_index] >= kappa0))
    acc, jerk = scurve_limits(lim, np.ptp(curve.points, axis=0) > 0.0)
    plan = _schedule_plan(curve, lim, grid, kappa0, n_peaks, made.kinds, made, acc, jerk)
    if not plan.cycle_time_s <= max_curve_time_s:
        raise CurveError(too_long(plan.cycle_time_s, max_curve_time_s))
    return plan


def _plan_curve(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                max_curve_time_s: float, extra_slowdown: float) -> Plan:
    """Plan the feed along one curve under `lim` (feed cap already in lim.feed_mm_s).
    extra_slowdown: a uniform slowdown the law takes on top of its own (the pipeline's check
    from the points asks for it, `pipeline.verified_plan`).

    `planner: envelope` plans on the grid alone (planning.envelope_plan); the S-curve plan is
    made only where the envelope gives way, where the curve stops inside (a corner, cusp or
    reversal) or where the envelope slows its law uniformly by more than
    envelope_plan.FALLBACK_SLOWDOWN; the faster of the two stands. `planner: optimal` starts
    from the S-curve plan.

    CurveError (without a place) when the planned cycle exceeds max_curve_time_s or is not a
    finite number of periods: checked on the law's duration before it is rounded to whole
    periods, then on the cycle itself."""
    if lim.planner == "envelope":
        plan = _envelope_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)
        if (plan is not None and plan.grid.stop_index.size == 0
                and plan.uniform_slowdown <= FALLBACK_SLOWDOWN * extra_slowdown):
            return plan
        base = scurve_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)
        return plan if plan is not None and plan.cycle_time_s < base.cycle_time_s else base
    plan = scurve_plan(curve, lim, feed_u, feed_mm_s, max_curve_time_s, extra_slowdown)
    if lim.planner == "optimal":
        return _optimal_plan(plan, feed_u, feed_mm_s)
    return plan


def _envelope_plan(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                   max_curve_time_s: float, extra_slowdown: float) -> Plan | None:
    """The envelope planner's plan on one grid (`envelope_plan.plan_envelope`); None where it
    cannot plan."""
    feed_breaks = feed_u[1:] if feed_u.size else feed_u
    kappa0 = curvature_threshold(lim)
    grid = build_grid(curve, grid_spacing(curve, lim), feed_breaks, kappa0)
    fcap = feed_at(grid.u, feed_u, feed_mm_s)
    least = least_cycle_s(curve, grid, lim, fcap)
    if not least <= max_curve_time_s:
        raise CurveError(too_long(least, max_curve_time_s, least=True))
    limit, _ = path_limit(curve, grid, lim, speed_limit(grid.kappa_1_mm, lim, fcap))
    made = plan_envelope(curve, grid, lim, limit, lambda u: feed_at(u, feed_u, feed_mm_s),
                         extra_slowdown)
    if made is None:
        return None
    schedule, kinds = made
    n_peaks = int(np.count_nonzero(grid.kappa_1_mm[grid.peak_index] >= kappa0))
    acc, jerk = scurve_limits(lim, np.ptp(curve.points, axis=0) > 0.0)
    plan = _schedule_plan(curve, lim, grid, kappa0, n_peaks, kinds, schedule, acc, jerk)
    if not plan.cycle_time_s <= max_curve_time_s:
        raise CurveError(too_long(plan.cycle_time_s, max_curve_time_s))
    return plan


def _optimal_plan(base: Plan, feed_u: np.ndarray, feed_mm_s: np.ndarray) -> Plan:
    """`planning.optimal`'s schedule as a plan, if it is faster than the S-curve plan `base`
    (whose law is its first iterate and whose rests it keeps); else base."""
    grid, law = base.grid, base.law
    rest_nodes = base.key_node[base.piece_key]
    # the base law's speed at the nodes, as it runs (each stretch slowed by its lambda)
    v_nodes = law.speed_at(grid.s_mm)
    v_nodes /= float(base.piece_scale.max(initial=1.0))
    schedule = optimal_schedule(base.curve, grid, base.limits, rest_nodes, v_nodes,
                                lambda u: feed_at(u, feed_u, feed_mm_s))
    if schedule is None or not schedule.law.duration_s < base.cycle_time_s:
        return base
    kinds = base.key_kind[np.searchsorted(base.key_node, schedule.rest_nodes)]
    return _schedule_plan(base.curve, base.limits, grid, base.kappa0_1_mm,
                          base.n_peaks_above_threshold, kinds, schedule,
                          base.scurve_acc_mm_s2, base.scurve_jerk_mm_s3)


def _schedule_plan(curve: NurbsCurve, lim: Limits, grid: Grid, kappa0: float, n_peaks: int,
                   kinds: np.ndarray, schedule, acc: float, jerk: float) -> Plan:
    """A schedule of planning.optimal or planning.envelope (`optimal.Schedule`) as a plan: its
    rests (of kinds (R,)) are the keys, one stretch between each two, whole periods each."""
    rest_nodes = schedule.rest_nodes
    zeros = np.zeros(rest_nodes.size)
    key_t = schedule.law.key_t_s
    periods = np.rint(np.diff(key_t) / lim.period_s).astype(np.int64)
    peaks = np.array([float(schedule.law.v0_mm_s[(schedule.law.t0_s >= key_t[k])
                                                  & (schedule.law.t0_s < key_t[k + 1])]
                            .max(initial=0.0)) for k in range(rest_nodes.size - 1)])
    arrays = (rest_nodes, np.asarray(kinds, dtype=np.int64), zeros, zeros.copy(), peaks,
              np.zeros(peaks.size), np.zeros(peaks.size), np.arange(rest_nodes.size), periods,
              np.ones(periods.size))
    for arr in arrays:
        arr.setflags(write=False)
    return Plan(curve, lim, grid, kappa0, n_peaks, *arrays[:7], schedule.law, schedule.slowdown,
                *arrays[7:], schedule.rounds, acc, jerk, lim.planner)
