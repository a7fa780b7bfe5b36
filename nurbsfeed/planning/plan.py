"""What planning hands on (design §2): one curve's `Plan` (its time law and whole periods, what
the stepping and the pipeline read) with its planner's diagnostics (what `nurbsfeed plan` lists
about it), the kinds of its key points, the programmed feed along the curve, and the grid's
node spacing, which every planner plans on."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.grid import Grid, polygon_length
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.timelaw import TimeLaw

if TYPE_CHECKING:
    from nurbsfeed.planning.schedule import Schedule

GRID_STEPS = 2.0  # grid nodes at most this many full-speed steps apart
MAX_GRID_NODES = 200_000  # per curve: spacing grows for very long curves at tiny periods
KIND_END, KIND_PEAK, KIND_CORNER, KIND_FEED, KIND_HOLD, KIND_CUSP, KIND_SHOULDER = range(7)
KIND_NAMES = {KIND_END: "end", KIND_PEAK: "peak", KIND_CORNER: "corner", KIND_FEED: "feed",
              KIND_HOLD: "hold", KIND_CUSP: "cusp", KIND_SHOULDER: "shoulder"}


@dataclass(frozen=True, eq=False)
class PlanDiagnostics:
    """What a planner found on its way that only `nurbsfeed plan` and the tests read, never the
    stepping: the curvature threshold kappa_0 (Eq. 16) and how many of the grid's curvature
    peaks reach it."""

    kappa0_1_mm: float
    n_peaks_above_threshold: int


@dataclass(frozen=True, eq=False)
class SCurveDiagnostics(PlanDiagnostics):
    """The S-curve planner's (planning.scurve_plan; arrays read-only). Per key point (K,): its
    nominal speed (Eq. 15; 0 at ends and corners) and its planned speed after the scan (Eq. 22).
    Per segment between key points (K-1,): its peak speed and holds. The limit-fix rounds, and
    the acceleration and jerk of its S-curves: the profile's tangential limits under the paper
    model, a share of the lowest limit they add to under the path model."""

    key_nominal_mm_s: np.ndarray
    key_v_mm_s: np.ndarray
    seg_peak_mm_s: np.ndarray
    seg_hold_start_mm: np.ndarray
    seg_hold_end_mm: np.ndarray
    fix_rounds: int
    acc_mm_s2: float
    jerk_mm_s3: float


@dataclass(frozen=True, eq=False)
class PathDiagnostics(PlanDiagnostics):
    """The path planner's (`planner: optimal`, planning.path_plan): the passes over the
    stretches' sets that found its schedule and the peak speed of each stretch between rests
    (P,; read-only)."""

    passes: int
    stretch_peak_mm_s: np.ndarray


@dataclass(frozen=True, eq=False)
class Plan:
    """What the stepping and the pipeline need of one curve's plan (arrays read-only); what
    only `nurbsfeed plan` and the tests read is in `diagnostics`.

    Key points (K,): grid node index and kind; the S-curve planner's key points, the path
    planner's rests. `law` is in plan time; stretch p between rests, from key piece_key[p] to
    key piece_key[p + 1], runs law(t / piece_scale[p]) in piece_periods[p] whole periods.
    """

    curve: NurbsCurve
    limits: Limits
    grid: Grid
    key_node: np.ndarray
    key_kind: np.ndarray
    law: TimeLaw
    # lambda >= 1 applied to the whole law (1 = none): what the S-curve planner's rounds left
    # above a limit, the largest v / limit there (rare, e.g. 1.23 on one random curve in
    # 2000), or what the path schedule's own check asked; times, under either planner, what
    # the pipeline's check from the points asked (planner.plan_curve's extra_slowdown)
    uniform_slowdown: float
    piece_key: np.ndarray  # (P+1,) keys where the motion is at rest: ends, corners, cusps
    piece_periods: np.ndarray  # (P,) whole periods of each stretch between rests
    piece_scale: np.ndarray  # (P,) lambda >= 1 of each stretch
    # "scurve": the paper's key points and S-curves, SCurveDiagnostics; "optimal":
    # planning.path_plan's schedule, whose keys are the rests alone, PathDiagnostics
    planner: str
    diagnostics: SCurveDiagnostics | PathDiagnostics
    # the path planner's spline (None under the S-curve planner): where a chain planned in
    # windows hands the motion on, the state there and the cells after it (planning.window)
    schedule: Schedule | None = None

    @cached_property
    def n_periods(self) -> int:
        return int(self.piece_periods.sum())

    @property
    def time_scale(self) -> float:
        """Overall lambda: executed duration / planned duration (1 for a zero-length curve)."""
        if self.law.duration_s == 0.0:
            return 1.0
        return self.cycle_time_s / self.law.duration_s

    @property
    def length_mm(self) -> float:
        return self.grid.length_mm

    @property
    def cycle_time_s(self) -> float:
        return self.n_periods * self.limits.period_s

    @property
    def key_s_mm(self) -> np.ndarray:
        return self.grid.s_mm[self.key_node]

    @property
    def key_u(self) -> np.ndarray:
        return self.grid.u[self.key_node]


def feed_at(u: np.ndarray, feed_u: np.ndarray, feed_mm_s: np.ndarray) -> np.ndarray:
    """Programmed feed cap (step function of u) at each u: (M,) -> (M,); inf if none."""
    # the feed in force after the i-th break, inf before the first: index i + 1 of this table
    if feed_u.size == 1 and feed_u[0] <= u[0]:  # one feed over the whole curve
        return np.full(u.size, feed_mm_s[0])
    table = np.concatenate(((np.inf,), feed_mm_s))
    return table[np.searchsorted(feed_u, u, side="right")]


def too_long(cycle_s: float, max_curve_time_s: float, least: bool = False) -> str:
    what = "cycle of at least" if least else "planned cycle"
    return (f"{what} {cycle_s:.6g} s exceeds max_curve_time_s = {max_curve_time_s:g} s "
            "(raise it in the profile or with --max-curve-time-s)")


def grid_spacing(curve: NurbsCurve, lim: Limits) -> float:
    """The grid's node spacing: GRID_STEPS full-speed steps, wider on curves so long that
    more than MAX_GRID_NODES nodes would take it."""
    return max(GRID_STEPS * lim.feed_mm_s * lim.period_s,
               polygon_length(curve.points) / MAX_GRID_NODES)
