"""What planning hands on (design §2): one curve's `Plan` (its time law, whole periods and
what `nurbsfeed plan` lists about it), the kinds of its key points, the programmed feed along
the curve, and the grid's node spacing, which every planner plans on."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.grid import Grid, polygon_length
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.timelaw import TimeLaw

GRID_STEPS = 2.0  # grid nodes at most this many full-speed steps apart
MAX_GRID_NODES = 200_000  # per curve: spacing grows for very long curves at tiny periods
KIND_END, KIND_PEAK, KIND_CORNER, KIND_FEED, KIND_HOLD, KIND_CUSP, KIND_SHOULDER = range(7)
KIND_NAMES = {KIND_END: "end", KIND_PEAK: "peak", KIND_CORNER: "corner", KIND_FEED: "feed",
              KIND_HOLD: "hold", KIND_CUSP: "cusp", KIND_SHOULDER: "shoulder"}


@dataclass(frozen=True, eq=False)
class Plan:
    """Everything the interpolator and `plan` need about one curve (arrays read-only).

    Key points (K,): grid node index, kind, nominal speed (Eq. 15 / 0 at ends and corners) and
    planned speed after the scan. Segments (K-1,): peak speed, holds. `law` is in plan time;
    stretch p between rests runs law(t / piece_scale[p]) in piece_periods[p] whole periods.
    """

    curve: NurbsCurve
    limits: Limits
    grid: Grid
    kappa0_1_mm: float
    n_peaks_above_threshold: int
    key_node: np.ndarray
    key_kind: np.ndarray
    key_nominal_mm_s: np.ndarray
    key_v_mm_s: np.ndarray
    seg_peak_mm_s: np.ndarray
    seg_hold_start_mm: np.ndarray
    seg_hold_end_mm: np.ndarray
    law: TimeLaw
    # lambda applied to the whole law where the limit-fix rounds left nodes above their limit:
    # the largest v / limit there (1 = none; rare, e.g. 1.23 on one random curve in 2000)
    uniform_slowdown: float
    piece_key: np.ndarray  # (P+1,) keys where the motion is at rest: ends, corners, cusps
    piece_periods: np.ndarray  # (P,) whole periods of each stretch between rests
    piece_scale: np.ndarray  # (P,) lambda >= 1 of each stretch
    fix_rounds: int
    # the S-curve's own acceleration and jerk: the profile's tangential limits under the paper
    # model, a share of the lowest limit they add to under the path model
    scurve_acc_mm_s2: float
    scurve_jerk_mm_s3: float
    # "scurve": the paper's key points and S-curves; "optimal": planning.path_plan's schedule,
    # whose keys are the rests alone (the key and segment fields above are zeros there)
    planner: str = "scurve"

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
