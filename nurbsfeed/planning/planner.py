"""Plan one curve: key points, nominal speeds, bidirectional scan, S-curve segments, limits
everywhere, whole periods (SPEC §2).

1. Grid: nodes <= 2 v_m T apart with arc length and curvature (planning.grid).
2. Key points: both ends (speed 0), every curvature maximum with kappa >= kappa_0 (nominal speed
   from Eq. 15), every sharp corner (speed 0), every change of programmed feed.
3. Bidirectional scan (Eq. 22): backward from the end, each key speed is lowered until the next
   one is reachable by deceleration within the segment; forward from the start likewise by
   acceleration. v_i = min(nominal, backward, forward).
4. Segments: accelerate to the highest peak that fits, cruise, decelerate (planning.scurve).
5. Limits everywhere (beyond the paper): the planned speed is compared with the pointwise limit
   at every grid node. Between two key points the limit rises from one curvature peak and falls
   to the next, so a violation lies on a shoulder where the S-curve accelerates sooner (or
   decelerates later) than the limit allows, or in the cruise. A shoulder violation adds a key
   point that holds the key speed up to the violation ("hold"), a cruise violation lowers the
   segment's cap; then the scan runs again. What is left after MAX_FIX_ROUNDS is removed by
   slowing the whole law uniformly (time scale lambda >= 1 keeps every limit).
6. Whole periods: the time law is stretched by lambda >= 1 so that its duration is a whole
   number of periods (v/lambda, a/lambda^2, j/lambda^3: limits still hold). Where the motion
   rests inside the curve (a corner), each stretch between rests gets its own lambda, so that an
   interpolation point falls exactly on the corner.

Speeds at grid nodes are checked against an eroded limit (the minimum over each node and its two
neighbours, at most two full-speed steps away), which covers interpolation points that fall
between nodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.grid import Grid, build_grid
from nurbsfeed.planning.limits import Limits, curvature_threshold, speed_limit
from nurbsfeed.planning.scurve import scan_speeds, segment_profiles
from nurbsfeed.planning.timelaw import TimeLaw

MAX_FIX_ROUNDS = 40
SPEED_CHECK_REL_TOL = 1e-9  # a node "violates" when v > limit * (1 + this)
GRID_STEPS = 2.0  # grid nodes at most this many full-speed steps apart
MAX_GRID_NODES = 200_000  # per curve: spacing grows for very long curves at tiny periods
PERIOD_ROUNDING_REL = 1e-9
HOLD_ROOM = 0.05  # holds leave at least this fraction of a segment for its transitions  # a duration within this of a whole period count is not stretched

KIND_END, KIND_PEAK, KIND_CORNER, KIND_FEED, KIND_HOLD = range(5)
KIND_NAMES = {KIND_END: "end", KIND_PEAK: "peak", KIND_CORNER: "corner", KIND_FEED: "feed",
              KIND_HOLD: "hold"}


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
    residual_scale: float  # part of lambda that fixed what the key points could not (1 = none)
    piece_key: np.ndarray  # (P+1,) keys where the motion is at rest: ends, corners, cusps
    piece_periods: np.ndarray  # (P,) whole periods of each stretch between rests
    piece_scale: np.ndarray  # (P,) lambda >= 1 of each stretch
    fix_rounds: int

    @property
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
    if feed_u.size == 0:
        return np.full(np.shape(u), np.inf)
    i = np.searchsorted(feed_u, u, side="right") - 1
    return np.where(i >= 0, feed_mm_s[np.clip(i, 0, None)], np.inf)


def _eroded(v: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """min(v[i-1], v[i], v[i+1]) per node, except that a stop node (corner or cusp, limit 0)
    does not spread to its neighbours: beside a corner the curvature is finite."""
    w = v.copy()
    for n in stops:  # borrow the neighbours' limits for the stop node while eroding
        w[n] = min(v[max(n - 1, 0)], v[min(n + 1, v.size - 1)])
    out = w.copy()
    out[1:] = np.minimum(out[1:], w[:-1])
    out[:-1] = np.minimum(out[:-1], w[1:])
    out[stops] = 0.0
    return out


def _segments_of_nodes(key_node: np.ndarray, n_nodes: int) -> np.ndarray:
    """For each grid node, the segment it lies in (key nodes belong to the segment they start)."""
    seg = np.searchsorted(key_node, np.arange(n_nodes), side="right") - 1
    return np.clip(seg, 0, len(key_node) - 2)


def plan_curve(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray = np.empty(0),
               feed_mm_s: np.ndarray = np.empty(0)) -> Plan:
    """Plan the feed along one curve under `lim` (feed cap already in lim.feed_mm_s)."""
    rough_length = float(np.sum(np.linalg.norm(np.diff(curve.points, axis=0), axis=1)))
    spacing = max(GRID_STEPS * lim.feed_mm_s * lim.period_s, rough_length / MAX_GRID_NODES)
    feed_breaks = feed_u[1:] if feed_u.size else feed_u
    kappa0 = curvature_threshold(lim)
    grid = build_grid(curve, spacing, feed_breaks, kappa0)
    fcap = feed_at(grid.u, feed_u, feed_mm_s)
    # corners (tangent jumps) and cusps (kappa infinite inside the curve) are passed at rest
    last = grid.u.size - 1
    stops = np.union1d(grid.corner_index, np.flatnonzero(np.isinf(grid.kappa_1_mm)))
    stops = stops[(stops > 0) & (stops < last)]
    limit = _eroded(speed_limit(grid.kappa_1_mm, lim, fcap), stops)

    # ---- key points -----------------------------------------------------------------------
    peaks = grid.peak_index[grid.kappa_1_mm[grid.peak_index] >= kappa0]
    feed_nodes = np.searchsorted(grid.u, feed_breaks)
    nodes = {0: KIND_END, last: KIND_END}
    for kind, idx in ((KIND_FEED, feed_nodes), (KIND_PEAK, peaks), (KIND_CORNER, stops)):
        for n in idx:
            if 0 < n < last:
                nodes[int(n)] = kind
    key_node = np.array(sorted(nodes))
    key_kind = np.array([nodes[n] for n in key_node])
    nominal = limit[key_node].copy()
    nominal[(key_kind == KIND_END) | (key_kind == KIND_CORNER)] = 0.0
    for n in feed_nodes:  # the lower of the two feeds holds at the change
        k = np.searchsorted(key_node, n)
        nominal[k] = min(nominal[k], fcap[max(n - 1, 0)], fcap[n])

    hold_start = np.zeros(len(key_node) - 1)
    hold_end = np.zeros(len(key_node) - 1)
    seg_of_node = _segments_of_nodes(key_node, grid.u.size)
    cap = np.full(len(key_node) - 1, lim.feed_mm_s)
    np.minimum.at(cap, seg_of_node, fcap)
    a, j = lim.acc_mm_s2, lim.jerk_mm_s3

    rounds = 0
    while True:
        key_s = grid.s_mm[key_node]
        length = np.diff(key_s)
        free = np.maximum(length - hold_start - hold_end, 0.0)
        v = scan_speeds(nominal, free, cap, a, j)
        peak, d_up, d_down = segment_profiles(v, free, cap, a, j)
        law = TimeLaw.from_segments(key_s, v, peak, hold_start, hold_end, a, j)
        v_nodes = law.speed_at_arc(grid.s_mm)
        bad = v_nodes > limit * (1.0 + SPEED_CHECK_REL_TOL)
        bad[key_node] = False  # passed at the key speed <= nominal by construction
        if not np.any(bad) or rounds == MAX_FIX_ROUNDS:
            break
        rounds += 1
        accel_end = key_s[:-1] + hold_start + d_up
        decel_start = key_s[1:] - hold_end - d_down
        changed = False
        for seg in np.unique(seg_of_node[bad]):
            nodes_bad = np.flatnonzero(bad & (seg_of_node == seg))
            s_bad = grid.s_mm[nodes_bad]
            up = s_bad < accel_end[seg]
            down = s_bad > decel_start[seg]
            mid = ~(up | down)
            new_start, new_end = hold_start[seg], hold_end[seg]
            if np.any(up) and v[seg] > 0.0:
                new_start = max(new_start, s_bad[up].min() - key_s[seg])
            if np.any(down) and v[seg + 1] > 0.0:
                new_end = max(new_end, key_s[seg + 1] - s_bad[down].max())
            if np.any(mid) or (np.any(up) and v[seg] == 0.0) or (np.any(down)
                                                                  and v[seg + 1] == 0.0):
                lowest = float(limit[nodes_bad].min())
                if 0.0 < lowest < cap[seg]:
                    cap[seg] = lowest
                    changed = True
            # A hold shortens what is left for the transitions; the next scan lowers the key
            # speeds until they fit. Holds that would meet leave no room: lower the cap instead.
            if new_start + new_end < length[seg] * (1.0 - HOLD_ROOM):
                changed |= (new_start, new_end) != (hold_start[seg], hold_end[seg])
                hold_start[seg], hold_end[seg] = new_start, new_end
            else:
                lowest = float(limit[nodes_bad].min())
                if 0.0 < lowest < cap[seg]:
                    cap[seg] = lowest
                    changed = True
        if not changed:
            break

    # Whatever the key points could not fix is fixed by slowing the whole law uniformly.
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(limit > 0, v_nodes / limit, 0.0)
    ratio[key_node] = 0.0
    residual = max(1.0, float(np.max(ratio)))
    # The motion stops at every interior key of speed 0 (corners, cusps): each stretch between
    # stops is stretched to a whole number of periods on its own and stepped on its own, so that
    # an interpolation point lands exactly on every corner.
    piece_key = np.array([0] + [k for k in range(1, len(v) - 1) if v[k] == 0.0] + [len(v) - 1])
    piece_duration = np.diff(law.key_t_s[piece_key])
    exact = piece_duration * residual / lim.period_s
    piece_periods = np.where(piece_duration > 0.0,
                             np.maximum(1, np.ceil(exact * (1.0 - PERIOD_ROUNDING_REL))),
                             0).astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        piece_scale = np.where(piece_duration > 0.0,
                               piece_periods * lim.period_s / piece_duration, 1.0)
    for arr in (key_node, key_kind, nominal, v, peak, hold_start, hold_end, piece_key,
                piece_periods, piece_scale):
        arr.setflags(write=False)
    return Plan(curve, lim, grid, kappa0, int(peaks.size), key_node, key_kind, nominal, v, peak,
                hold_start, hold_end, law, residual, piece_key, piece_periods, piece_scale,
                rounds)
