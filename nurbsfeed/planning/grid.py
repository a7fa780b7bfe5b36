"""The dense grid a curve is planned on: parameters, arc length, curvature, pointwise limits.

The grid has nodes at every knot and enough nodes inside each span that consecutive nodes are
at most `spacing_mm` apart; refined curvature maxima are nodes too. The planner checks its speed
profile at these nodes ("limits everywhere"), so the spacing is tied to the step length v_m T.

Building it, in order (`_grid_nodes`, compiled steps; then `simpson_lengths`):
1. Samples: per span, a node count from a 16-chord length estimate, evenly spaced in u; at a
   knot, the higher of kappa's two one-sided values.
2. Curvature maxima: local maxima of kappa on the samples that stand out from their valleys,
   each refined inside the bracket of its two neighbours (sampling, then Brent's method span by
   span, with kappa from both sides at a knot; only roughly where kappa stays well below
   kappa_floor, where the limit is flat). A maximum inside the last interval before a knot or
   an end, beside which the samples keep rising (an end, or a knot where kappa jumps down),
   is no local maximum of the samples: each side of each boundary is probed for it
   (`geometry.peaks.boundary_maxima`).
3. Stops, where the feed must come to rest (kappa is infinite there):
   a. corners at knots of multiplicity >= degree, where the unit tangent jumps
      (`geometry.stops.find_corners`);
   b. zeros of C' (a control point repeated, a cusp, a path that turns back on itself), found
      as local minima of |C'| on the samples refined by Gauss-Newton, and at every knot from
      both sides (`geometry.stops.find_stops`). A zero is classified by the one-sided tangents,
      taken as chords from it:
        - they differ (a corner) or are opposite (a cusp, a reversal): a stop;
        - they agree, but kappa grows without bound towards the zero: a stop (v^2 kappa would
          be unbounded at any speed above 0);
        - they agree and kappa has finite one-sided limits: removable, the curve is smooth
          there; its kappa is the limit (the next finite value, `_fill_singular`).
      The ends of the curve are at rest anyway; a zero of C' there only blanks kappa.
   c. near cusps, where |C'| refines to a minimum close to 0 but not 0: kappa peaks there in a
      needle that neither neighbouring sample need show. One across which the path turns back
      (`geometry.stops._near_cusp_turn`) is a hairpin, and a stop like a cusp: the stepping's
      arc position runs a fraction of a micrometre off the law's between rests, enough to meet
      a tip of nanometres before the law has slowed down for it. Any other is refined there and
      becomes a peak (`geometry.peaks.near_cusp_peaks`).
4. The maxima, corners and caller's parameters are merged in as nodes; then every interval
   across which kappa jumps is halved, a few times over.
5. Arc length by adaptive Simpson between consecutive nodes (geometry.arclength).
Everything is evaluated one parameter at a time from the span polynomials (geometry.kernel), in
numba's subset: the cost is the evaluations, not thousands of small array operations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbsfeed.errors import CurveError
from nurbsfeed.geometry.arclength import simpson_lengths
from nurbsfeed.geometry.kernel import curvature, find_span, point_d1, point_d2
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.geometry.peaks import (
    boundary_maxima,
    holds_any,
    near_cusp_peaks,
    prominent_maxima,
    refine_peak,
)
from nurbsfeed.geometry.stops import find_corners, find_stops
from nurbsfeed.jit import jit

KAPPA_STEP_REL = 0.1  # refine where kappa changes by more than 10 % between nodes
REFINE_ROUNDS = 6  # ... down to 1/64 of the base spacing
TURN_REFINE_ROUNDS = 24  # where the tangent turns more than kappa explains: down to 1/2^24
TURN_EXPLAINED = 2.0  # a turn up to this times max(kappa) x chord needs no node between
TURN_SLACK_RAD = 1e-3
REFINE_GROWTH_MAX = 8  # the refinement stops before the grid grows beyond this factor
# Simpson's tolerance per node interval, relative to the interval's length at the mean |C'|.
# The accepted values carry the Richardson term, so they are far more accurate than this:
# on the butterfly and the benchmark curves every node's length is within 1e-10 mm of a
# 1e-13 reference (tests/test_geometry.py); 1e-10 cost 60 % more evaluations for nothing.
ARC_REL_TOL = 1e-9
MIN_NODES_PER_SPAN = 8
CHORD_PROBES = 16  # chords per span for the node count
# |C'| at or below this fraction of the mean |C'| is zero: the curve stops there (step 3). A true
# zero of a polynomial C' refines to ~1e-12 of the mean or below; one that does not is a near
# cusp whose curvature the limits already handle.
ZERO_SPEED_REL = 1e-7
TANGENT_CHORD_REL = 1e-9  # ... grown tenfold until they are this long (of the polygon's length)


@dataclass(frozen=True, eq=False)
class Grid:
    """Nodes along one curve; every array is (M,) and read-only."""

    u: np.ndarray
    s_mm: np.ndarray  # cumulative arc length, s[0] = 0
    kappa_1_mm: np.ndarray  # curvature; at a point where C' = 0, the limit from inside
    peak_index: np.ndarray  # (P,) nodes that are local curvature maxima (refined, see step 2)
    stop_index: np.ndarray  # (Q,) nodes where the motion rests: corners, cusps, reversals (step 3)
    stop_cos: np.ndarray  # (Q,) cosine of the tangent's turn at each stop (-1: turns back)

    @property
    def length_mm(self) -> float:
        return float(self.s_mm[-1])


def polygon_length(points):
    """Length of the control polygon (N, 3): the curve is no longer. The legs are summed in
    order (np.cumsum; np.sum pairs them): the grid's tolerances derive from the last bits."""
    leg = np.diff(points, axis=0)
    lengths = np.sqrt(leg[:, 0] ** 2 + leg[:, 1] ** 2 + leg[:, 2] ** 2)
    return float(np.cumsum(lengths)[-1]) if lengths.size else 0.0


@jit
def _samples(knots, coef, degree, breaks, spacing_mm):
    """Step 1: nodes evenly spaced in u per span, at most spacing_mm apart (the span's length
    estimated by CHORD_PROBES chords, plus 5 %), at least MIN_NODES_PER_SPAN; the last break
    closes the list. Returns u, kappa, |C'| at the nodes (M,), C and the unit tangent there
    (M, 3; the tangent from the span after a knot, 0 where C' = 0), and the mean of |C'| over
    the nodes (summed in order). At an interior
    knot kappa is the higher of its limits from the two sides (it jumps where the curve is
    only C1), so that no node understates the curvature around it; a side where |C'| is below
    ZERO_SPEED_REL of the other's does not count (its kappa is rounding noise)."""
    n_ctrl = coef.shape[0]
    n_spans = breaks.size - 1
    counts = np.empty(n_spans, dtype=np.int64)
    n_nodes = 1  # the last break
    span = degree
    for i in range(n_spans):
        width = breaks[i + 1] - breaks[i]
        chord = 0.0
        span = find_span(knots, degree, n_ctrl, breaks[i], span)
        px, py, pz, _, _, _ = point_d1(knots, coef, degree, span, breaks[i])
        for j in range(1, CHORD_PROBES + 1):
            u = breaks[i] + width * (j / CHORD_PROBES)
            span = find_span(knots, degree, n_ctrl, u, span)
            qx, qy, qz, _, _, _ = point_d1(knots, coef, degree, span, u)
            chord += math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
            px, py, pz = qx, qy, qz
        counts[i] = max(MIN_NODES_PER_SPAN, math.ceil(1.05 * chord / spacing_mm))
        n_nodes += counts[i]
    u_nodes = np.empty(n_nodes)
    q = 0
    for i in range(n_spans):
        step = (breaks[i + 1] - breaks[i]) / counts[i]
        for j in range(counts[i]):
            u_nodes[q] = breaks[i] + j * step
            q += 1
    u_nodes[q] = breaks[n_spans]
    kappa = np.empty(u_nodes.size)
    speed = np.empty(u_nodes.size)
    pts = np.empty((u_nodes.size, 3))
    tan = np.zeros((u_nodes.size, 3))
    span = degree
    for q in range(u_nodes.size):
        before = span
        span = find_span(knots, degree, n_ctrl, u_nodes[q], span)
        c = point_d2(knots, coef, degree, span, u_nodes[q])
        kappa[q], speed[q] = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
        _unit_tangent(c, pts, tan, q)
        if span != before and q > 0:  # a knot: kappa may jump there, take the higher side
            c = point_d2(knots, coef, degree, before, u_nodes[q])
            left, left_speed = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            # ... where the side before moves: after a span of no length (coincident control
            # points) its kappa is rounding noise (7e13 at a knot where the curve starts
            # moving, filled back over the still span: 2.8e-11 mm/s, 65 hours planned)
            moves = left_speed > ZERO_SPEED_REL * speed[q] if speed[q] == speed[q] else True
            if moves and (left > kappa[q] or kappa[q] != kappa[q]):
                kappa[q] = left
    total_speed = 0.0
    for q in range(speed.size):
        total_speed += speed[q]
    return u_nodes, kappa, speed, pts, tan, total_speed / speed.size


@jit
def _fill_singular(kappa):
    """Where C' = 0 (repeated control points) kappa is NaN (or overflows): use the next finite
    value along the curve (the last one past the final finite node), the limit of kappa from
    inside the curve (design §3a). None finite: 0. In place."""
    last_good = -1
    for q in range(kappa.size - 1, -1, -1):
        if math.isfinite(kappa[q]):
            last_good = q
            break
    if last_good < 0:
        kappa[:] = 0.0
        return
    following = kappa[last_good]
    for q in range(kappa.size - 1, -1, -1):
        if math.isfinite(kappa[q]):
            following = kappa[q]
        else:
            kappa[q] = following


@jit
def _merge(knots, coef, degree, u, kappa, speed, pts, tan, extra, zero_speed):
    """Step 4a: the sorted union of the nodes and the sorted extra parameters, with kappa,
    |C'|, C and the unit tangent (a parameter that is already a node keeps the node's values;
    kappa NaN where |C'| is 0)."""
    n_ctrl = coef.shape[0]
    size = u.size + extra.size
    u_out = np.empty(size)
    k_out = np.empty(size)
    s_out = np.empty(size)
    p_out = np.empty((size, 3))
    t_out = np.empty((size, 3))
    i = 0
    j = 0
    n = np.int64(0)  # not a literal 0: _unit_tangent(..., n) would compile for Literal[int](0) too
    span = degree
    while i < u.size or j < extra.size:
        if j >= extra.size or (i < u.size and u[i] <= extra[j]):
            if i < u.size and j < extra.size and u[i] == extra[j]:
                j += 1
                continue
            u_out[n] = u[i]
            k_out[n] = kappa[i]
            s_out[n] = speed[i]
            for d in range(3):
                p_out[n, d] = pts[i, d]
                t_out[n, d] = tan[i, d]
            i += 1
        else:
            if n > 0 and u_out[n - 1] == extra[j]:
                j += 1
                continue
            u_out[n] = extra[j]
            span = find_span(knots, degree, n_ctrl, extra[j], span)
            c = point_d2(knots, coef, degree, span, extra[j])
            k_out[n], s_out[n] = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            if s_out[n] <= zero_speed:
                k_out[n] = math.nan
            _unit_tangent(c, p_out, t_out, n)
            j += 1
        n += 1
    return u_out[:n], k_out[:n], s_out[:n], p_out[:n], t_out[:n]


@jit
def _tangent_chord_cos(tan, pts, moving, q, chord):
    """The cosine between the unit tangent at node `moving` and the chord from node q to q + 1."""
    return ((tan[moving, 0] * (pts[q + 1, 0] - pts[q, 0])
             + tan[moving, 1] * (pts[q + 1, 1] - pts[q, 1])
             + tan[moving, 2] * (pts[q + 1, 2] - pts[q, 2])) / chord)


@jit
def _hidden_bump(knots, coef, degree, low, high_u, high_kappa, kappa_floor, zero_speed):
    """Whether kappa at the middle of [low, high_u] is above kappa_floor and more than
    KAPPA_STEP_REL above the higher of its ends: a maximum the ends do not show (fuzz seed 45:
    kappa 14.7 and 14.6 at the ends of the first interval after a knot, 23.1 between them)."""
    mid = 0.5 * (low + high_u)
    span = find_span(knots, degree, coef.shape[0], mid, degree)
    c = point_d2(knots, coef, degree, span, mid)
    k_mid, s_mid = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
    return (s_mid > zero_speed and math.isfinite(k_mid) and k_mid > kappa_floor
            and k_mid > (1.0 + KAPPA_STEP_REL) * high_kappa)


@jit
def _refine_where_kappa_jumps_or_turns(knots, coef, degree, u, kappa, speed, pts, tan,
                                       kappa_floor, zero_speed, floor_mm):
    """Step 4b: halve every interval across which kappa (above kappa_floor) changes by more than
    KAPPA_STEP_REL, up to REFINE_ROUNDS times, and every interval across which the tangent turns
    by more than its end nodes' kappa explains, up to TURN_REFINE_ROUNDS times.

    The planner bounds the limit between two nodes by the lower of their limits; near a sharp
    curvature peak that bound is only tight when the nodes are close, so the grid is made dense
    exactly there. A spike of kappa narrower than the node spacing (a near cusp: |C'| dips
    between two nodes) shows in neither node's kappa, but in the turn of the tangent between
    them: more than TURN_EXPLAINED times max(kappa) times the chord, plus TURN_SLACK_RAD, where
    that turn over the chord is a curvature above kappa_floor (not where C' = 0 at a node, or
    the chord is shorter than floor_mm). A midpoint where C' = 0 (|C'| at most zero_speed) takes
    the kappa of the interval's start. The grid grows at most REFINE_GROWTH_MAX-fold: what a
    refinement stopped there misses, the motion guard (nurbsfeed/safety.py) refuses."""
    n_ctrl = coef.shape[0]
    most = REFINE_GROWTH_MAX * u.size
    # only intervals made in the last round are looked at: the others' ends are unchanged
    fresh = np.empty(u.size, dtype=np.bool_)
    for q in range(u.size):  # not np.ones or np.zeros: numba compiles its own per type
        fresh[q] = True
    for rounds in range(TURN_REFINE_ROUNDS):
        split = np.empty(u.size, dtype=np.bool_)
        for q in range(u.size):
            split[q] = False
        n_split = 0
        for q in range(u.size - 1):
            if not fresh[q]:
                continue
            high = max(kappa[q], kappa[q + 1])
            if (rounds < REFINE_ROUNDS and high > kappa_floor
                    and abs(kappa[q + 1] - kappa[q]) > KAPPA_STEP_REL * high):
                split[q] = True
                n_split += 1
                continue
            if rounds < REFINE_ROUNDS and _hidden_bump(knots, coef, degree, u[q], u[q + 1], high,
                                                       kappa_floor, zero_speed):
                split[q] = True
                n_split += 1
                continue
            still_q = speed[q] <= zero_speed
            still_next = speed[q + 1] <= zero_speed
            if still_q and still_next:
                continue  # C' = 0 at both ends of the interval: no tangent
            chord = math.sqrt((pts[q + 1, 0] - pts[q, 0]) ** 2 + (pts[q + 1, 1] - pts[q, 1]) ** 2
                              + (pts[q + 1, 2] - pts[q, 2]) ** 2)
            if chord <= floor_mm:
                continue  # no length: nothing between the nodes to plan for
            if still_q or still_next:
                # C' = 0 at one end (a stop, a curve end): the tangent at the other against the
                # chord (a hook of 0.14 um between the last node and a still end once hid a
                # kappa of 5e6 from the grid)
                moving = q + 1 if still_q else q
                cos = _tangent_chord_cos(tan, pts, moving, q, chord)
            else:
                cos = (tan[q, 0] * tan[q + 1, 0] + tan[q, 1] * tan[q + 1, 1]
                       + tan[q, 2] * tan[q + 1, 2])
            explained = TURN_EXPLAINED * high * chord + TURN_SLACK_RAD
            # 1 - cos x >= x^2/2 - x^4/24: below that the turn is explained, without an acos
            if 1.0 - cos <= explained * explained * (0.5 - explained * explained / 24.0):
                continue
            turn = math.acos(min(1.0, max(-1.0, cos)))
            if turn > explained and turn > kappa_floor * chord:
                split[q] = True
                n_split += 1
        if n_split == 0 or u.size + n_split > most:
            break
        size = u.size + n_split
        u_new = np.empty(size)
        k_new = np.empty(size)
        s_new = np.empty(size)
        p_new = np.empty((size, 3))
        t_new = np.empty((size, 3))
        f_new = np.empty(size, dtype=np.bool_)
        n = np.int64(0)  # not a literal 0 (see _merge)
        span = degree
        for q in range(u.size):
            u_new[n] = u[q]
            k_new[n] = kappa[q]
            s_new[n] = speed[q]
            for i in range(3):  # element by element: a row copy costs numba a slice
                p_new[n, i] = pts[q, i]
                t_new[n, i] = tan[q, i]
            f_new[n] = split[q]
            n += 1
            if split[q]:
                mid = 0.5 * (u[q] + u[q + 1])
                span = find_span(knots, degree, n_ctrl, mid, span)
                c = point_d2(knots, coef, degree, span, mid)
                k_mid, s_mid = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
                u_new[n] = mid
                k_new[n] = k_mid if math.isfinite(k_mid) and s_mid > zero_speed else kappa[q]
                s_new[n] = s_mid
                _unit_tangent(c, p_new, t_new, n)
                f_new[n] = True
                n += 1
        u, kappa, speed, pts, tan, fresh = u_new, k_new, s_new, p_new, t_new, f_new
    return u, kappa, speed, pts, tan


@jit
def _unit_tangent(c, pts, tan, q):
    """C and the unit tangent from point_d2's c into pts[q], tan[q] (tangent 0 where C' = 0)."""
    pts[q, 0] = c[0]
    pts[q, 1] = c[1]
    pts[q, 2] = c[2]
    norm = math.sqrt(c[3] * c[3] + c[4] * c[4] + c[5] * c[5])
    inv = 1.0 / norm if norm > 0.0 else 0.0
    tan[q, 0] = c[3] * inv
    tan[q, 1] = c[4] * inv
    tan[q, 2] = c[5] * inv


def _grid_nodes(knots, coef, degree, breaks, spacing_mm, extra_u, kappa_floor, floor_mm):
    """Steps 1-4: nodes u, kappa, |C'| (M,), refined peak parameters (P,), stops (Q,) with
    the cosine of their turn (Q,), and the mean |C'| over the samples (the arc length
    tolerance's scale).

    The steps are compiled; this driver is not: it runs each once (and the peak refinement once
    per peak), and its sorting, concatenating and masking of a few values is numpy's, which in
    compiled code would cost seconds of the first run compiling numba's own quicksort and array
    functions."""
    u, kappa, speed, pts, tan, mean_speed = _samples(knots, coef, degree, breaks, spacing_mm)
    zero_speed = ZERO_SPEED_REL * mean_speed
    kappa[speed <= zero_speed] = math.nan
    _fill_singular(kappa)
    idx = prominent_maxima(kappa)
    peak_u = np.empty(idx.size)
    for k in range(idx.size):
        refined_u, refined_kappa = refine_peak(knots, coef, degree, u[idx[k] - 1],
                                                u[idx[k] + 1], kappa_floor)
        peak_u[k] = refined_u if refined_kappa > kappa[idx[k]] else u[idx[k]]
    corner_u = find_corners(knots, coef, degree, breaks, floor_mm)
    zero_u, zero_cos, near_u = find_stops(knots, coef, degree, breaks, u, speed, pts, tan,
                                      zero_speed, mean_speed, floor_mm, kappa_floor)
    stop_u = np.concatenate((corner_u, zero_u))
    stop_cos = np.concatenate((np.zeros(corner_u.size), zero_cos))
    order = np.argsort(stop_u, kind="stable")
    stop_u = stop_u[order]
    stop_cos = stop_cos[order]
    # kappa grows without bound into a cusp, so its "maximum" is the refinement's bracket end:
    # a peak whose bracket holds a stop adds nothing, the motion rests there anyway
    keep = np.ones(idx.size, dtype=np.bool_)
    for k in range(idx.size):
        keep[k] = not holds_any(stop_u, u[idx[k] - 1], u[idx[k] + 1])
    peak_u = peak_u[keep]
    needles = near_cusp_peaks(knots, coef, degree, u, kappa, near_u, kappa_floor)
    peak_u = np.sort(np.concatenate((peak_u, needles)))
    beside_u = boundary_maxima(knots, coef, degree, breaks, u, peak_u, stop_u)
    if beside_u.size:
        peak_u = np.sort(np.concatenate((peak_u, beside_u)))
    extra = np.sort(np.concatenate((peak_u, stop_u, extra_u)))
    u, kappa, speed, pts, tan = _merge(knots, coef, degree, u, kappa, speed, pts, tan, extra,
                                       zero_speed)
    _fill_singular(kappa)
    u, kappa, speed, pts, tan = _refine_where_kappa_jumps_or_turns(
        knots, coef, degree, u, kappa, speed, pts, tan, kappa_floor, zero_speed, floor_mm)
    # a spike of kappa narrower than the samples shows only in the refined grid: its maxima
    # at or above kappa_floor that no peak's bracket holds are peaks too (refined likewise)
    idx = prominent_maxima(kappa)
    more = []
    for k in range(idx.size):
        low, high = u[idx[k] - 1], u[idx[k] + 1]
        if kappa[idx[k]] < kappa_floor:
            continue
        if holds_any(peak_u, low, high) or holds_any(stop_u, low, high):
            continue
        refined_u, refined_kappa = refine_peak(knots, coef, degree, low, high, kappa_floor)
        more.append(refined_u if refined_kappa > kappa[idx[k]] else u[idx[k]])
    if more:
        added = np.sort(np.array(more))
        u, kappa, speed, pts, tan = _merge(knots, coef, degree, u, kappa, speed, pts, tan,
                                           added, zero_speed)
        _fill_singular(kappa)
        peak_u = np.sort(np.concatenate((peak_u, added)))
    return u, kappa, speed, peak_u, stop_u, stop_cos, mean_speed


def _zero_length_grid(curve: NurbsCurve, extra_u: np.ndarray) -> Grid:
    """The grid of a curve whose control points all coincide: it stays at one point, whatever
    its weights. Built here, not sampled: C' is then rounding noise over 0 (a weight != 1 leaves
    ~1e-16 of it), which made an arc length integrated to a tolerance relative to its own mean
    split without end, and a chord of length 0 a division by 0. The knots and the caller's
    parameters are the nodes; no length, no curvature, no peaks, no stops (rest throughout)."""
    u = np.union1d(curve.span_breaks, np.asarray(extra_u, dtype=float))
    zeros = np.zeros(u.size)
    none = np.empty(0, dtype=np.int64)
    for a in (u, zeros, none):
        a.setflags(write=False)
    return Grid(u, zeros, zeros, none, none, np.empty(0))


def build_grid(curve: NurbsCurve, spacing_mm: float, extra_u: np.ndarray = np.empty(0),
               kappa_floor: float = np.inf) -> Grid:
    """Sample, find and refine curvature maxima, integrate arc length: the planning grid.

    extra_u: parameters that must be nodes (where the programmed feed changes); kappa_floor:
    below it the limit does not depend on curvature (kappa_0), so neither jumps of kappa nor its
    maxima below it need refining.
    """
    if curve.is_degenerate:
        return _zero_length_grid(curve, extra_u)
    knots, coef, degree = curve.knots, curve.span_polynomials, curve.degree
    floor_mm = TANGENT_CHORD_REL * polygon_length(curve.points)
    u, kappa, speed, peak_u, stop_u, stop_cos, mean_speed = _grid_nodes(
        knots, coef, degree, curve.span_breaks, float(spacing_mm),
        np.ascontiguousarray(extra_u, dtype=float), float(kappa_floor), floor_mm)
    # two stops on one node (a corner knot where C' also vanishes) are one: the sharper turn
    stop_index = np.searchsorted(u, stop_u)
    if stop_index.size > 1:
        stop_index, first = np.unique(stop_index, return_index=True)
        stop_cos = np.minimum.reduceat(stop_cos, first)
    peak_index = np.searchsorted(u, np.sort(peak_u))
    s = simpson_lengths(knots, coef, degree, u, speed, ARC_REL_TOL * (mean_speed + 1e-300))
    if not math.isfinite(s[-1]):
        q = int(np.argmin(np.isfinite(s)))
        raise CurveError(f"arc length does not converge between u = {curve.input_u(u[q - 1]):.9g}"
                         f" and {curve.input_u(u[q]):.9g} (|C'| there is rounding noise?)")
    # stops with no length between them (a span whose control points are all equal) are one
    # place: the first stands, the others become plain nodes with the kappa that follows them
    same = np.flatnonzero(np.diff(s[stop_index]) <= floor_mm) + 1 if stop_index.size > 1 else ()
    if len(same):
        for n in stop_index[same][::-1]:
            kappa[n] = kappa[n + 1]
        stop_index = np.delete(stop_index, same)
        stop_cos = np.delete(stop_cos, same)
    kappa[stop_index] = np.inf
    for a in (u, s, kappa, peak_index, stop_index, stop_cos):
        a.setflags(write=False)
    return Grid(u, s, kappa, peak_index, stop_index, stop_cos)
