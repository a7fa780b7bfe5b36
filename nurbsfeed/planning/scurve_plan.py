"""The S-curve planner (`planner: scurve`: the paper model's, and the path planner's
fallback): key points, nominal speeds, bidirectional scan, S-curve segments, limits
everywhere, whole periods (design §2).

1. Grid: nodes <= 2 v_m T apart with arc length and curvature (planning.grid).
2. Key points: both ends (speed 0), every curvature maximum with kappa >= kappa_0 (nominal speed
   from Eq. 15), every stop of the grid (a corner, cusp or reversal: speed 0), every change of
   programmed feed.
3. Bidirectional scan (Eq. 22): backward from the end, each key speed is lowered until the next
   one is reachable by deceleration within the segment; forward from the start likewise by
   acceleration. v_i = min(nominal, backward, forward).
4. Segments: accelerate to the highest peak that fits, cruise, decelerate (planning.scurve).
5. Limits everywhere (beyond the paper): the planned speed is compared with the pointwise limit
   at every grid node. Between two key points the limit rises from one curvature peak and falls
   to the next, so a violation lies on a shoulder where the S-curve accelerates sooner (or
   decelerates later) than the limit allows, or in the cruise. A shoulder violation adds a key
   point that holds the key speed up to the violation ("hold"), a cruise violation lowers the
   segment's cap; then the scan runs again. A segment's peak that lies between two nodes, with
   no node in its cruise, is seen by none: the grid gains nodes there and planning starts again
   (PEAK_NODE_ROUNDS). What is left after MAX_FIX_ROUNDS is removed by slowing the whole law
   uniformly (time scale lambda >= 1 keeps every limit), a peak still hidden included, by its
   limit evaluated on the curve.
6. Whole periods: the time law is stretched by lambda >= 1 so that its duration is a whole
   number of periods (v/lambda, a/lambda^2, j/lambda^3: limits still hold). Where the motion
   rests inside the curve (a corner), each stretch between rests gets its own lambda, so that an
   interpolation point falls exactly on the corner.

Speeds at grid nodes are checked against an eroded limit (the minimum over each node and its two
neighbours, at most two full-speed steps away), which covers interpolation points that fall
between nodes.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from nurbsfeed.errors import CurveError
from nurbsfeed.geometry.nurbs import NurbsCurve, curvature_from_derivatives
from nurbsfeed.geometry.peaks import first_at_or_above
from nurbsfeed.jit import jit
from nurbsfeed.planning.grid import Grid, build_grid
from nurbsfeed.planning.key_points import key_points
from nurbsfeed.planning.limits import Limits, curvature_threshold, speed_limit
from nurbsfeed.planning.path_check import least_cycle_s, path_excess, path_limit
from nurbsfeed.planning.path_model import scurve_limits
from nurbsfeed.planning.plan import (
    GRID_STEPS,
    Plan,
    SCurveDiagnostics,
    feed_at,
    grid_spacing,
    too_long,
)
from nurbsfeed.planning.scurve import scan_speeds, segment_profiles
from nurbsfeed.planning.timelaw import TimeLaw, chain_segments, speed_at_arc

MAX_FIX_ROUNDS = 40
SPEED_CHECK_REL_TOL = 1e-9  # a node "violates" when v > limit * (1 + this)
PERIOD_ROUNDING_REL = 1e-9  # a duration within this of a whole period count is not stretched
MAX_STRETCH_PERIODS = 1e15  # whole periods of one stretch: far below int64's range
HOLD_ROOM = 0.05  # holds leave at least this fraction of a segment for its transitions
PEAK_NODE_ROUNDS = 3  # times the grid gains nodes where a segment's peak hid between two
SHOULDER_ROUNDS = 8  # times key points are added where a hold cannot (or should not) help
HOLD_MAX_PERIODS = 16  # a hold longer than this (in time) becomes a shoulder key point


def _node_excess(key_node: np.ndarray, limit: np.ndarray, v_nodes: np.ndarray) -> float:
    """The largest v / limit over the nodes that are not keys (0 if none is checked)."""
    checked = limit > 0.0
    checked[key_node] = False
    return float((v_nodes[checked] / limit[checked]).max()) if checked.any() else 0.0


def _whole_periods(v_key, key_t, key_node, limit, v_nodes, period_s, slowdown):
    """Step 6: the uniform slowdown (whatever the key points could not fix: the largest v / limit
    over the nodes that are not keys, at least the slowdown given), the keys where the motion
    rests (P+1,), and per stretch between them (P,) its whole number of periods and its lambda.
    A stretch that would last more than MAX_STRETCH_PERIODS periods, or not a finite number,
    gets -1 (the caller refuses the curve): rounded into int64 it could wrap to a small count.
    (numpy, not a kernel: a few operations per curve, cheaper than loading one more kernel.)"""
    slowdown = max(slowdown, _node_excess(key_node, limit, v_nodes))
    piece_key = np.concatenate(([0], np.flatnonzero(v_key[1:-1] == 0.0) + 1, [v_key.size - 1]))
    piece_periods = np.zeros(piece_key.size - 1, dtype=np.int64)
    piece_scale = np.ones(piece_key.size - 1)
    for p in range(piece_key.size - 1):
        duration = float(key_t[piece_key[p + 1]] - key_t[piece_key[p]])
        exact = duration * slowdown / period_s
        if not exact <= MAX_STRETCH_PERIODS:
            piece_periods[p] = -1
        elif duration > 0.0:
            piece_periods[p] = max(1, math.ceil(exact * (1.0 - PERIOD_ROUNDING_REL)))
            piece_scale[p] = float(piece_periods[p]) * period_s / duration
    return slowdown, piece_key, piece_periods, piece_scale


@jit
def _limit_rounds(s_mm, limit, key_node, nominal, cap, hold_start, hold_end, acc, jerk,
                  max_hold_s, cap_to_cruise, confine):
    """Steps 3-5: scan, segments, time law, then fix rounds until the law keeps the eroded
    limit at every node (or MAX_FIX_ROUNDS, or a round that changes nothing).

    cap, hold_start, hold_end (K-1,) are updated in place. A node between key points k and k+1
    (key nodes excluded: they are passed at a key speed <= nominal by construction) that is too
    fast lies before the end of the acceleration ("up"), after the start of the deceleration
    ("down") or in the cruise. Up: hold the start speed until the first such node; down: hold
    the end speed from the last one; cruise, or an end at rest, or holds that would leave less
    than HOLD_ROOM of the segment: cap the segment at the lowest limit of its fast nodes (with
    cap_to_cruise, the path model's: of those a hold cannot help; confine: see the loop).
    Returns key speeds (K,), peak speeds (K-1,), the law's pieces (timelaw.chain_segments), the
    law's speed at every node where it could exceed the limit (M,; 0 at the others and at key
    nodes), the number of fix rounds and, per segment (K-1,), where `plan_curve` should add a
    key point (a shoulder; -1: none): the node where the law was too fast farthest from the key
    it leaves (nearest to the key it comes to; confined, beside a rest, the end of the first run
    of such nodes), when that key is at rest (a hold of speed 0 cannot help, so the segment's
    cap was lowered) or when the hold would last longer than max_hold_s (a key speed held over a
    long stretch of a steep limit: a near cusp); and, per segment, the stretch [from, to] of arc
    length where its peak speed hides between two nodes ((K-1, 2); NaN: none).
    """
    # loops rather than index arrays and array expressions, here and below: numba compiles
    # each of those into code of its own, a second of the first run for this kernel alone
    n_seg = key_node.size - 1
    key_s = np.empty(n_seg + 1)
    for k in range(n_seg + 1):
        key_s[k] = s_mm[key_node[k]]
    length = np.empty(n_seg)
    free = np.empty(n_seg)
    for seg in range(n_seg):
        length[seg] = key_s[seg + 1] - key_s[seg]
    # a segment's profile (hence v at its nodes) depends on its end speeds, peak and holds only:
    # what they were when its nodes were last checked (NaN: never)
    seen = np.empty((n_seg, 5))
    v_nodes = np.zeros(s_mm.size)
    checked = np.empty(s_mm.size, dtype=np.int64)
    checked_s = np.empty(s_mm.size)
    checked_limit = np.empty(s_mm.size)
    shoulder_at = np.empty(n_seg, dtype=np.int64)
    for seg in range(n_seg):  # loops, not np.full: numba compiles its own per type
        shoulder_at[seg] = -1
        for k in range(5):
            seen[seg, k] = np.nan
    rounds = 0
    while True:
        for seg in range(n_seg):
            gap = length[seg] - hold_start[seg] - hold_end[seg]
            free[seg] = 0.0 if gap < 0.0 else gap  # np.maximum's: NaN and -0.0 stay
        v = scan_speeds(nominal, free, cap, acc, jerk)
        peak, d_up, d_down = segment_profiles(v, free, cap, acc, jerk)
        t0, s0, v0, a0, jk, key_t, duration = chain_segments(key_s, v, peak, hold_start,
                                                             hold_end, acc, jerk)
        # Nodes are checked again only in segments whose profile changed; speed_at_arc solves
        # only where the speed bound of the law's piece exceeds the node's limit (in low
        # curvature, at most nodes it does not). The others get v_nodes = 0.
        n_checked = 0
        for seg in range(n_seg):
            profile = (v[seg], v[seg + 1], peak[seg], hold_start[seg], hold_end[seg])
            if (seen[seg, 0] == profile[0] and seen[seg, 1] == profile[1]
                    and seen[seg, 2] == profile[2] and seen[seg, 3] == profile[3]
                    and seen[seg, 4] == profile[4]):
                continue
            for k in range(5):
                seen[seg, k] = profile[k]
            for node in range(key_node[seg] + 1, key_node[seg + 1]):
                checked[n_checked] = node
                checked_s[n_checked] = s_mm[node]
                checked_limit[n_checked] = limit[node]
                n_checked += 1
        if t0.size and n_checked:
            checked_v = np.empty(n_checked)
            speed_at_arc(t0, s0, v0, a0, jk, duration, checked_s[:n_checked],
                         checked_limit[:n_checked], checked_v)
            # element by element: an assignment through an index array compiles numba's
            # shape-mismatch message (str, repr, concatenation), a second of the first run
            for i in range(n_checked):
                v_nodes[checked[i]] = checked_v[i]
        if rounds == MAX_FIX_ROUNDS:
            break
        changed = False
        any_bad = False
        for seg in range(n_seg):
            accel_end = key_s[seg] + hold_start[seg] + d_up[seg]
            decel_start = key_s[seg + 1] - hold_end[seg] - d_down[seg]
            first_up = np.inf
            last_down = -np.inf
            last_up_node = -1
            first_down_node = -1
            # the last node of the first run of too-fast nodes (consecutive), the first of the last
            first_run_end = -1
            last_run_start = -1
            previous_bad = -2
            lowest = np.inf
            lowest_up = np.inf
            lowest_mid = np.inf
            lowest_down = np.inf
            up = False
            down = False
            mid = False
            for node in range(key_node[seg] + 1, key_node[seg + 1]):
                if v_nodes[node] <= limit[node] * (1.0 + SPEED_CHECK_REL_TOL):
                    continue
                if first_run_end < 0 or node == first_run_end + 1:
                    first_run_end = node
                if node != previous_bad + 1:
                    last_run_start = node
                previous_bad = node
                s = s_mm[node]
                lowest = min(lowest, limit[node])
                if s < accel_end:
                    up = True
                    first_up = min(first_up, s)
                    last_up_node = node
                    lowest_up = min(lowest_up, limit[node])
                elif s > decel_start:
                    down = True
                    last_down = max(last_down, s)
                    if first_down_node < 0:
                        first_down_node = node
                    lowest_down = min(lowest_down, limit[node])
                else:
                    mid = True
                    lowest_mid = min(lowest_mid, limit[node])
            if not (up or down or mid):
                continue
            any_bad = True
            new_start = hold_start[seg]
            new_end = hold_end[seg]
            # confined (CRAWL_REL), a hold longer than max_hold_s is a cap at the lowest limit
            # it broke (a near cusp's 0.3 mm/s held 5 mm to a dip took 17 s), and beside a rest
            # the shoulder ends the run there: the cap is that run's lowest limit, and a far
            # run (a dip the S-curve from rest passes too fast) took it along (0.2 mm/s, 9 mm)
            long_up = up and v[seg] > 0.0 and first_up - key_s[seg] > v[seg] * max_hold_s
            long_down = (down and v[seg + 1] > 0.0
                         and key_s[seg + 1] - last_down > v[seg + 1] * max_hold_s)
            if up and v[seg] > 0.0 and not (confine and long_up):
                new_start = max(new_start, first_up - key_s[seg])
            if down and v[seg + 1] > 0.0 and not (confine and long_down):
                new_end = max(new_end, key_s[seg + 1] - last_down)
            # Under the path model the cap falls to the lowest limit of the nodes a hold cannot
            # help (those of the cruise, and beside a key at rest), not to that of nodes a hold
            # does help: a curve that cruised past one node too fast and then braked into a
            # needle peak capped its whole 28 mm segment at the peak's 1.3 mm/s (23 s for
            # 1.8 s). The paper model keeps the lowest of all: its plan is not checked between
            # the nodes afterwards (the path model's is, by path_excess), and cruising at the
            # exact limit of a node let a curvature bump between two nodes, 0.5 % above both,
            # pass 0.09 % above the normal-jerk limit.
            capped_up = up and (v[seg] == 0.0 or (confine and long_up))
            capped_down = down and (v[seg + 1] == 0.0 or (confine and long_down))
            lower_cap = mid or capped_up or capped_down
            cap_to = lowest_mid if cap_to_cruise else lowest
            if capped_up:
                cap_to = min(cap_to, lowest_up)
            if capped_down:
                cap_to = min(cap_to, lowest_down)
            if up and (v[seg] == 0.0 or long_up):
                shoulder_at[seg] = first_run_end if confine and v[seg] == 0.0 else last_up_node
            elif down and (v[seg + 1] == 0.0 or long_down):
                shoulder_at[seg] = (last_run_start if confine and v[seg + 1] == 0.0
                                    else first_down_node)
            # A hold shortens what is left for the transitions; the next scan lowers the key
            # speeds until they fit. Holds that would meet leave no room: lower the cap instead.
            if new_start + new_end < length[seg] * (1.0 - HOLD_ROOM):
                if new_start != hold_start[seg] or new_end != hold_end[seg]:
                    changed = True
                hold_start[seg] = new_start
                hold_end[seg] = new_end
            else:
                lower_cap = True
                cap_to = lowest
            if lower_cap and 0.0 < cap_to < cap[seg]:
                cap[seg] = cap_to
                changed = True
        if not any_bad:
            break
        rounds += 1
        if not changed:
            break
    hidden_peak_s = np.empty((n_seg, 2))
    for seg in range(n_seg):
        hidden_peak_s[seg, 0], hidden_peak_s[seg, 1] = _hidden_peak(
            seg, s_mm, limit, key_node, key_s, v, peak, hold_start, hold_end, d_up, d_down)
    return (v, peak, t0, s0, v0, a0, jk, key_t, duration, v_nodes, rounds, shoulder_at,
            hidden_peak_s)


@jit
def _hidden_peak(seg, s_mm, limit, key_node, key_s, v, peak, hold_start, hold_end, d_up, d_down):
    """The stretch [accel_end, decel_start] over which segment seg holds its peak speed, where
    that peak hides between two nodes and may break the limit there ((NaN, NaN): it does not).

    Between two adjacent nodes the limit is at least the lower of theirs (every curvature
    maximum is a node), and away from its peak the law's speed is monotone between nodes; so
    only a peak above that lower limit, with no node inside its cruise, can break the limit
    where no node looks (a circle's shoulders one grid interval apart ran 5 % over
    sqrt(A_n / kappa))."""
    if not peak[seg] > max(v[seg], v[seg + 1]) * (1.0 + SPEED_CHECK_REL_TOL):
        return math.nan, math.nan
    accel_end = key_s[seg] + hold_start[seg] + d_up[seg]
    decel_start = max(key_s[seg + 1] - hold_end[seg] - d_down[seg], accel_end)
    after = first_at_or_above(s_mm, accel_end)  # the first node at or after it
    if after < s_mm.size and s_mm[after] <= decel_start:
        return math.nan, math.nan  # a node in the cruise: checked
    if (after <= key_node[seg] or after > key_node[seg + 1]
            or peak[seg] <= min(limit[after - 1], limit[after]) * (1.0 + SPEED_CHECK_REL_TOL)):
        return math.nan, math.nan
    return accel_end, decel_start


class _OnGrid(NamedTuple):
    """What `_plan_on_grid` plans on one grid: the eroded limit (M,), the key points and their
    segments (as in `Plan` and `SCurveDiagnostics`), the law's pieces (timelaw.chain_segments),
    key times and duration, the law's speed at the nodes, the fix rounds and the segments'
    hidden peaks."""

    limit: np.ndarray
    key_node: np.ndarray
    key_kind: np.ndarray
    nominal: np.ndarray
    n_peaks: int
    v: np.ndarray
    peak: np.ndarray
    hold_start: np.ndarray
    hold_end: np.ndarray
    pieces: list[np.ndarray]
    key_t: np.ndarray
    duration: float
    v_nodes: np.ndarray
    rounds: int
    hidden_peak_s: np.ndarray

    def law(self) -> TimeLaw:
        t0, s0, v0, a0, jk = self.pieces
        return TimeLaw.from_pieces(t0, s0, v0, a0, jk, self.key_t, self.duration)


def _plan_on_grid(grid: Grid, raw_limit, fcap, feed_nodes, kappa0: float, lim: Limits,
                  acc: float, jerk: float, fixed_keys: np.ndarray, *, confine: bool = False
                  ) -> _OnGrid:
    """Steps 2-5 on one grid, with shoulder key points added where holds cannot help.

    Beside a rest where the limit rises steeply (a curve that starts with a hook, a weight near
    0 beside an end) the S-curve from rest outruns the limit and no hold can help; the segment's
    cap would fall to that limit all along it. A key point at the last such node (a shoulder)
    confines the low cap to the short segment from the rest to it. Likewise beside a near cusp,
    where holding its tiny key speed up to the limit's rise would crawl for seconds: from a
    shoulder the speed rises with the limit."""
    shoulders = fixed_keys
    for _ in range(SHOULDER_ROUNDS + 1):
        limit, key_node, key_kind, nominal, cap, n_peaks = key_points(
            grid.kappa_1_mm, raw_limit, fcap, grid.stop_index, grid.stop_cos, grid.peak_index,
            feed_nodes, kappa0, lim.feed_mm_s, shoulders)
        hold_start = np.zeros(len(key_node) - 1)
        hold_end = np.zeros(len(key_node) - 1)
        # a writable copy of the arc lengths: the grid's search kernel (first_at_or_above) is
        # compiled for writable arrays, and a read-only one would compile it a second time
        v, peak, *pieces, key_t, duration, v_nodes, rounds, shoulder_at, hidden_peak_s = \
            _limit_rounds(grid.s_mm.copy(), limit, key_node, nominal, cap, hold_start, hold_end,
                          acc, jerk, HOLD_MAX_PERIODS * lim.period_s, lim.jerk_model == "path",
                          confine)
        if not (shoulder_at >= 0).any():  # (the common case: setdiff1d costs ~50 us)
            break
        new = np.setdiff1d(shoulder_at[shoulder_at >= 0], key_node)
        if new.size == 0 or shoulders.size >= SHOULDER_ROUNDS * max(1, key_node.size):
            break
        shoulders = np.union1d(shoulders, new)
    return _OnGrid(limit, key_node, key_kind, nominal, n_peaks, v, peak, hold_start, hold_end,
                   pieces, key_t, duration, v_nodes, rounds, hidden_peak_s)


def _hidden_slowdown(curve: NurbsCurve, grid: Grid, lim: Limits, feed_u, feed_mm_s, peak,
                     hidden_peak_s) -> float:
    """The slowdown that keeps peaks still hidden between nodes after PEAK_NODE_ROUNDS within
    the limit (at least 1): between two nodes the limit has no minimum inside (curvature maxima
    are nodes), so over a peak's stretch it is lowest at one of the stretch's ends, evaluated
    here on the curve itself."""
    hidden = np.flatnonzero(np.isfinite(hidden_peak_s[:, 0]))
    if hidden.size == 0:
        return 1.0
    u = np.interp(hidden_peak_s[hidden].ravel(), grid.s_mm, grid.u)
    _, c1, c2 = curve.derivatives(u)
    kappa = np.nan_to_num(curvature_from_derivatives(c1, c2), nan=np.inf)
    here = speed_limit(kappa, lim, feed_at(u, feed_u, feed_mm_s)).reshape(-1, 2).min(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(here > 0.0, peak[hidden] / here, 1.0)
    return max(1.0, float(ratio.max()))


# a path-model plan over this many times its lower bound (path_check.least_cycle_s) may crawl
# where holds and shoulders met a near cusp: planned again confined, the shorter plan is kept
CRAWL_REL = 4.0


def _uncrawled(on: _OnGrid, least: float, *args) -> _OnGrid:
    """`on`, or the confined plan of `_plan_on_grid(*args)` where on crawls and it is shorter."""
    confined = _plan_on_grid(*args, confine=True) if on.duration > CRAWL_REL * least else on
    return confined if confined.duration < on.duration else on


PATH_FIX_ROUNDS = 3  # plans again with the limit lowered where the law broke a path limit ...
PATH_FIX_REL = 0.02  # ... while it does so by more than this


def _cycle_left(on: _OnGrid, law: TimeLaw, excess: float, hidden_slowdown: float) -> float:
    """The law's duration after the uniform slowdown it would still need: the path limits'
    excess, the nodes the fix rounds left too fast, the hidden peaks."""
    return law.duration_s * max(excess, _node_excess(on.key_node, on.limit, on.v_nodes),
                                hidden_slowdown)


def scurve_plan(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray, feed_mm_s: np.ndarray,
                 max_curve_time_s: float, extra_slowdown: float) -> Plan:
    """The paper's key points and S-curves (the module's steps), limits everywhere."""
    spacing = grid_spacing(curve, lim)
    feed_breaks = feed_u[1:] if feed_u.size else feed_u
    kappa0 = curvature_threshold(lim)
    extra_u = feed_breaks
    path = lim.jerk_model == "path"
    acc, jerk = scurve_limits(lim, np.ptp(curve.points, axis=0) > 0.0)
    for refine in range(PEAK_NODE_ROUNDS + 1):
        grid = build_grid(curve, spacing, extra_u, kappa0)
        fcap = feed_at(grid.u, feed_u, feed_mm_s)
        feed_nodes = np.searchsorted(grid.u, feed_breaks)
        paper_limit = speed_limit(grid.kappa_1_mm, lim, fcap)
        raw_limit, fixed_keys = paper_limit, np.empty(0, dtype=np.int64)
        if path:
            raw_limit, fixed_keys = path_limit(curve, grid, lim, paper_limit)
        on = _plan_on_grid(grid, raw_limit, fcap, feed_nodes, kappa0, lim, acc, jerk, fixed_keys)
        hidden = np.flatnonzero(np.isfinite(on.hidden_peak_s[:, 0]))
        if hidden.size == 0 or refine == PEAK_NODE_ROUNDS:
            break
        # a segment whose peak hid between two nodes (grid spacing follows the feed, not the
        # plan): plan again with a node in the middle of each of its intervals (one node where
        # the peak was only moves it: the holds the next rounds set shift it again) that is
        # longer than GRID_STEPS steps at that peak (the eroded limit covers shorter ones)
        mids = []
        for seg in hidden:
            first, last = on.key_node[seg], on.key_node[seg + 1]
            wide = np.diff(grid.s_mm[first:last + 1]) > GRID_STEPS * on.peak[seg] * lim.period_s
            mids.append(0.5 * (grid.u[first:last] + grid.u[first + 1:last + 1])[wide])
        more = np.concatenate(mids)
        if more.size == 0:
            break
        extra_u = np.union1d(extra_u, more)
    excess = 1.0
    if path:
        least = least_cycle_s(curve, grid, lim, fcap)
        if not least <= max_curve_time_s:
            raise CurveError(too_long(least, max_curve_time_s, least=True))
        on = _uncrawled(on, least, grid, raw_limit, fcap, feed_nodes, kappa0, lim, acc, jerk,
                        fixed_keys)
    law = on.law()
    hidden_slowdown = _hidden_slowdown(curve, grid, lim, feed_u, feed_mm_s, on.peak,
                                       on.hidden_peak_s)
    if path:
        # where the S-curves' own acceleration and jerk break a path limit, lower the limit
        # there and plan again (PATH_FIX_ROUNDS at most, keeping the plan whose cycle after the
        # uniform slowdown that is left is the shortest): one needle of a 0.14 um hook beside
        # an end once slowed a whole 58 mm curve 6.3 times
        excess, caps = path_excess(curve, grid, law, lim)
        best = (_cycle_left(on, law, excess, hidden_slowdown), on, law, excess, hidden_slowdown)
        path_caps = caps
        for _ in range(PATH_FIX_ROUNDS):
            if excess <= 1.0 + PATH_FIX_REL:
                break
            raw_limit, fixed_keys = path_limit(curve, grid, lim, paper_limit, path_caps)
            args = (grid, raw_limit, fcap, feed_nodes, kappa0, lim, acc, jerk, fixed_keys)
            on = _uncrawled(_plan_on_grid(*args), least, *args)
            law = on.law()
            excess, caps = path_excess(curve, grid, law, lim)
            hidden_slowdown = _hidden_slowdown(curve, grid, lim, feed_u, feed_mm_s, on.peak,
                                               on.hidden_peak_s)
            cycle = _cycle_left(on, law, excess, hidden_slowdown)
            if cycle < best[0]:
                best = (cycle, on, law, excess, hidden_slowdown)
            path_caps = np.minimum(path_caps, caps)
        _, on, law, excess, hidden_slowdown = best
    if not law.duration_s <= max_curve_time_s:
        raise CurveError(too_long(law.duration_s, max_curve_time_s))
    slowdown = max(excess, hidden_slowdown) * extra_slowdown
    slowdown, piece_key, piece_periods, piece_scale = _whole_periods(
        on.v, law.key_t_s, on.key_node, on.limit, on.v_nodes, lim.period_s, slowdown)
    if np.any(piece_periods < 0):
        raise CurveError(too_long(law.duration_s * slowdown, max_curve_time_s))
    cycle_s = float(piece_periods.sum()) * lim.period_s
    if not cycle_s <= max_curve_time_s:
        raise CurveError(too_long(cycle_s, max_curve_time_s))
    for arr in (on.key_node, on.key_kind, on.nominal, on.v, on.peak, on.hold_start, on.hold_end,
                piece_key, piece_periods, piece_scale):
        arr.setflags(write=False)
    diagnostics = SCurveDiagnostics(
        kappa0_1_mm=kappa0, n_peaks_above_threshold=int(on.n_peaks),
        key_nominal_mm_s=on.nominal, key_v_mm_s=on.v, seg_peak_mm_s=on.peak,
        seg_hold_start_mm=on.hold_start, seg_hold_end_mm=on.hold_end, fix_rounds=on.rounds,
        acc_mm_s2=acc, jerk_mm_s3=jerk)
    return Plan(curve=curve, limits=lim, grid=grid, key_node=on.key_node, key_kind=on.key_kind,
                law=law, uniform_slowdown=slowdown, piece_key=piece_key,
                piece_periods=piece_periods, piece_scale=piece_scale, planner="scurve",
                diagnostics=diagnostics)
