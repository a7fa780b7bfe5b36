"""The dense grid a curve is planned on: parameters, arc length, curvature, pointwise limits.

The grid has nodes at every knot and enough nodes inside each span that consecutive nodes are
at most `spacing_mm` apart; refined curvature maxima are nodes too. The planner checks its speed
profile at these nodes ("limits everywhere"), so the spacing is tied to the step length v_m T.

Building it, in order (`_grid_nodes`, one compiled call; then `simpson_lengths`):
1. Samples: per span, a node count from a 16-chord length estimate, evenly spaced in u; at a
   knot, the higher of kappa's two one-sided values.
2. Curvature maxima: local maxima of kappa on the samples that stand out from their valleys,
   each refined inside the bracket of its two neighbours (sampling, then Brent's method span by
   span, with kappa from both sides at a knot; only roughly where kappa stays well below
   kappa_floor, where the limit is flat).
3. Corners: knots of multiplicity >= degree where the unit tangent jumps.
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

from nurbsfeed.geometry.arclength import simpson_lengths
from nurbsfeed.geometry.kernel import curvature, find_span, point_d1, point_d2
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.jit import jit

KAPPA_STEP_REL = 0.1  # refine where kappa changes by more than 10 % between nodes
REFINE_ROUNDS = 6  # ... down to 1/64 of the base spacing
ZOOM_SAMPLES = 11  # the bracket (two grid steps) shrinks by 5 by sampling ...
# ... then to this by Brent's method: about the square root of the double's resolution, since
# kappa is flat to second order at a smooth maximum (kappa is then within ~1e-16 of its peak
# value); a closer bracket only chases the rounding of kappa.
PEAK_BRACKET_REL = 1e-8
BRENT_ITERATIONS = 100
KNOT_PROBE_REL = 1e-6  # of the bracket: where kappa's slope beside a knot is probed
GOLDEN_SMALL = (3.0 - math.sqrt(5.0)) / 2.0  # the golden section's smaller part, 0.382
EPS_U = 3e-16  # Brent's relative resolution in u (a little above the double's)
# Simpson's tolerance per node interval, relative to the interval's length at the mean |C'|.
# The accepted values carry the Richardson term, so they are far more accurate than this:
# on the butterfly and the benchmark curves every node's length is within 1e-10 mm of a
# 1e-13 reference (tests/test_geometry.py); 1e-10 cost 60 % more evaluations for nothing.
ARC_REL_TOL = 1e-9
MIN_NODES_PER_SPAN = 8
CHORD_PROBES = 16  # chords per span for the node count
PEAK_PROMINENCE_REL = 1e-7
CORNER_COS_TOL = 1e-8  # a tangent turning by more than ~1.4e-4 rad at a knot is a corner
CORNER_PROBE_REL = 1e-9  # of the parameter range: how far beside the knot the tangents are taken


@dataclass(frozen=True, eq=False)
class Grid:
    """Nodes along one curve; every array is (M,) and read-only."""

    u: np.ndarray
    s_mm: np.ndarray  # cumulative arc length, s[0] = 0
    kappa_1_mm: np.ndarray  # curvature; at a point where C' = 0, the limit from inside
    peak_index: np.ndarray  # (P,) nodes that are local curvature maxima (refined, see step 2)
    corner_index: np.ndarray  # (Q,) nodes where the tangent jumps (C0 knots): speed 0

    @property
    def length_mm(self) -> float:
        return float(self.s_mm[-1])


@jit
def _samples(knots, coef, degree, breaks, spacing_mm):
    """Step 1: nodes evenly spaced in u per span, at most spacing_mm apart (the span's length
    estimated by CHORD_PROBES chords, plus 5 %), at least MIN_NODES_PER_SPAN; the last break
    closes the list. Returns u, kappa, |C'| at the nodes: three (M,) arrays. At an interior
    knot kappa is the higher of its limits from the two sides (it jumps where the curve is
    only C1), so that no node understates the curvature around it."""
    n_ctrl = coef.shape[0]
    n_spans = breaks.size - 1
    counts = np.empty(n_spans, dtype=np.int64)
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
    u_nodes = np.empty(counts.sum() + 1)
    q = 0
    for i in range(n_spans):
        step = (breaks[i + 1] - breaks[i]) / counts[i]
        for j in range(counts[i]):
            u_nodes[q] = breaks[i] + j * step
            q += 1
    u_nodes[q] = breaks[n_spans]
    kappa = np.empty(u_nodes.size)
    speed = np.empty(u_nodes.size)
    span = degree
    for q in range(u_nodes.size):
        before = span
        span = find_span(knots, degree, n_ctrl, u_nodes[q], span)
        c = point_d2(knots, coef, degree, span, u_nodes[q])
        kappa[q], speed[q] = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
        if span != before and q > 0:  # a knot: kappa may jump there, take the higher side
            c = point_d2(knots, coef, degree, before, u_nodes[q])
            left, _ = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            if left > kappa[q] or kappa[q] != kappa[q]:
                kappa[q] = left
    return u_nodes, kappa, speed


@jit
def _fill_singular(kappa):
    """Where C' = 0 (repeated control points) kappa is NaN (or overflows): use the next finite
    value along the curve (the last one past the final finite node), the limit of kappa from
    inside the curve (SPEC §3a). None finite: 0. In place."""
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
def _prominent_maxima(kappa):
    """Step 2a: interior local maxima (a plateau counts once, at its first node) that stand out
    from the lowest kappa on both sides, up to the neighbouring maxima, by a relative
    PEAK_PROMINENCE_REL, so that the rounding noise of a constant-curvature arc (1e-15) does not
    make every node a peak. Knots stay maxima where kappa has a kink."""
    cand = np.empty(kappa.size, dtype=np.int64)
    n = 0
    for q in range(1, kappa.size - 1):
        if kappa[q] > kappa[q - 1] and kappa[q] >= kappa[q + 1]:
            cand[n] = q
            n += 1
    keep = np.empty(n, dtype=np.int64)
    kept = 0
    left_valley = kappa[0:cand[0]].min() if n > 0 else 0.0
    for k in range(n):
        stop = cand[k + 1] if k + 1 < n else kappa.size
        right_valley = kappa[cand[k]:stop].min()
        if kappa[cand[k]] > max(left_valley, right_valley) * (1.0 + PEAK_PROMINENCE_REL):
            keep[kept] = cand[k]
            kept += 1
        left_valley = right_valley
    return keep[:kept]


@jit
def _kappa_on_span(knots, coef, degree, span, u):
    """kappa at u from span `span`'s polynomial (at a knot: its limit from that span's side);
    -1 where C' = 0, so that such a point is never a maximum."""
    c = point_d2(knots, coef, degree, span, u)
    kappa, _ = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
    return kappa if kappa == kappa else -1.0


@jit
def _brent_max(knots, coef, degree, span, a, b, x, kappa_x, tol):
    """Step 2c: the maximum of kappa on [a, b] from span `span`'s polynomial alone (u, kappa),
    from x inside, whose kappa_x is above kappa at a and b, by Brent's method (parabolic
    steps, golden-section steps where they do not shrink the bracket) to about tol in u.
    Inside one span kappa is smooth, so the parabolic steps converge fast."""
    fx = -kappa_x  # minimise -kappa
    w, fw, v, fv = x, fx, x, fx
    d = 0.0
    e = 0.0
    for _ in range(BRENT_ITERATIONS):
        xm = 0.5 * (a + b)
        tol1 = tol + EPS_U * abs(x)
        tol2 = 2.0 * tol1
        if abs(x - xm) <= tol2 - 0.5 * (b - a):
            break
        golden = True
        if abs(e) > tol1:  # try a parabola through x, w, v
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            p = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            e_old = e
            e = d
            if abs(p) < abs(0.5 * q * e_old) and q * (a - x) < p < q * (b - x):
                d = p / q
                golden = False
                if (x + d) - a < tol2 or b - (x + d) < tol2:
                    d = tol1 if xm >= x else -tol1
        if golden:
            e = (a - x) if x >= xm else (b - x)
            d = GOLDEN_SMALL * e
        u = x + (d if abs(d) >= tol1 else (tol1 if d > 0.0 else -tol1))
        c = point_d2(knots, coef, degree, span, u)  # _kappa_on_span, inline: ~10 % faster
        kappa, _ = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
        fu = -kappa if kappa == kappa else 1.0
        if fu <= fx:
            if u >= x:
                a = x
            else:
                b = x
            v, fv, w, fw, x, fx = w, fw, x, fx, u, fu
        else:
            if u < x:
                a = u
            else:
                b = u
            if fu <= fw or w == x:
                v, fv, w, fw = w, fw, u, fu
            elif fu <= fv or v == x or v == w:
                v, fv = u, fu
    return x, -fx


@jit
def _refine_peak(knots, coef, degree, low, high, kappa_floor):
    """Step 2b: the maximum of kappa in [low, high] (u, kappa).

    kappa is smooth inside a span; at a knot it may have a kink, or a jump where the curve is
    only C1 there. First, ZOOM_SAMPLES evenly spaced samples, and every knot inside with the
    higher of its two one-sided values: the best of them and its neighbouring samples bracket
    the maximum (of several, the highest at that resolution). A peak below half of kappa_floor
    stops there: below kappa_floor its position does not matter. Then the bracket is cut at
    the knots inside it, which are candidates from both sides; a piece whose inside holds a
    point above both its ends (the best sample, or a probe just inside a knot end where kappa
    rises into the piece) is searched by `_brent_max` on its own span's polynomial, and on any
    other piece the maximum is at an end.
    """
    n_ctrl = coef.shape[0]
    last = ZOOM_SAMPLES - 1
    width = high - low
    step = width / last
    best_i = 0
    best_k = -1.0
    span = degree
    for i in range(ZOOM_SAMPLES):
        u = low + width * (i / last) if i < last else high
        span = find_span(knots, degree, n_ctrl, u, span)
        c = point_d2(knots, coef, degree, span, u)
        kappa, _ = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
        if kappa > best_k:  # the first maximum; NaN (C' = 0) never wins
            best_k = kappa
            best_i = i
    best_u = low + width * (best_i / last) if best_i < last else high
    a = low + width * (max(best_i - 1, 0) / last)
    b = low + width * ((best_i + 1) / last) if best_i + 1 < last else high
    span = find_span(knots, degree, n_ctrl, low, degree)
    while knots[span + 1] < high:  # the knots inside, from both sides
        knot = knots[span + 1]
        kappa = _kappa_on_span(knots, coef, degree, span, knot)
        span = find_span(knots, degree, n_ctrl, knot, span)
        kappa = max(kappa, _kappa_on_span(knots, coef, degree, span, knot))
        if kappa > best_k:
            best_u, best_k = knot, kappa
            a, b = max(low, knot - step), min(high, knot + step)
    if best_k < 0.5 * kappa_floor:
        return best_u, best_k
    tol = PEAK_BRACKET_REL * width
    inside_u = best_u
    inside_k = best_k
    piece_low = a
    span = find_span(knots, degree, n_ctrl, a, degree)
    while True:
        piece_high = min(b, knots[span + 1])
        k_low = _kappa_on_span(knots, coef, degree, span, piece_low)
        k_high = _kappa_on_span(knots, coef, degree, span, piece_high)
        for u, kappa in ((piece_low, k_low), (piece_high, k_high)):
            if kappa > best_k:
                best_u, best_k = u, kappa
        if piece_high - piece_low > 4.0 * tol:
            start_u, start_k = piece_low, -1.0
            if piece_low < inside_u < piece_high:
                start_u, start_k = inside_u, inside_k
            for end, into in ((piece_low, 1.0), (piece_high, -1.0)):
                if a < end < b:  # a knot
                    u = end + into * KNOT_PROBE_REL * width
                    kappa = _kappa_on_span(knots, coef, degree, span, u)
                    if kappa > start_k:
                        start_u, start_k = u, kappa
            if start_k > max(k_low, k_high):
                u, kappa = _brent_max(knots, coef, degree, span, piece_low, piece_high,
                                      start_u, start_k, tol)
                if kappa > best_k:
                    best_u, best_k = u, kappa
        if piece_high >= b:
            return best_u, best_k
        piece_low = piece_high
        span = find_span(knots, degree, n_ctrl, piece_low, span)


@jit
def _corners(knots, coef, degree, breaks):
    """Step 3: interior knots of multiplicity >= degree where the unit tangent jumps."""
    n_ctrl = coef.shape[0]
    eps = CORNER_PROBE_REL * (breaks[breaks.size - 1] - breaks[0])
    out = np.empty(max(breaks.size - 2, 0))
    n = 0
    for b in range(1, breaks.size - 1):
        knot = breaks[b]
        mult = 0
        for k in knots:
            mult += k == knot
        if mult < degree:
            continue
        span = find_span(knots, degree, n_ctrl, knot - eps, degree)
        _, _, _, lx, ly, lz = point_d1(knots, coef, degree, span, knot - eps)
        span = find_span(knots, degree, n_ctrl, knot + eps, span)
        _, _, _, rx, ry, rz = point_d1(knots, coef, degree, span, knot + eps)
        norm_l = max(math.sqrt(lx * lx + ly * ly + lz * lz), 1e-300)
        norm_r = max(math.sqrt(rx * rx + ry * ry + rz * rz), 1e-300)
        cos = (lx * rx + ly * ry + lz * rz) / (norm_l * norm_r)
        if cos < 1.0 - CORNER_COS_TOL:
            out[n] = knot
            n += 1
    return out[:n]


@jit
def _merge(knots, coef, degree, u, kappa, speed, extra):
    """Step 4a: the sorted union of the nodes and the extra parameters, with kappa and |C'|
    (a parameter that is already a node keeps the node's values)."""
    n_ctrl = coef.shape[0]
    extra = np.sort(extra)
    size = u.size + extra.size
    u_out = np.empty(size)
    k_out = np.empty(size)
    s_out = np.empty(size)
    i = 0
    j = 0
    n = 0
    span = degree
    while i < u.size or j < extra.size:
        if j >= extra.size or (i < u.size and u[i] <= extra[j]):
            if i < u.size and j < extra.size and u[i] == extra[j]:
                j += 1
                continue
            u_out[n] = u[i]
            k_out[n] = kappa[i]
            s_out[n] = speed[i]
            i += 1
        else:
            if n > 0 and u_out[n - 1] == extra[j]:
                j += 1
                continue
            u_out[n] = extra[j]
            span = find_span(knots, degree, n_ctrl, extra[j], span)
            c = point_d2(knots, coef, degree, span, extra[j])
            k_out[n], s_out[n] = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            j += 1
        n += 1
    return u_out[:n], k_out[:n], s_out[:n]


@jit
def _refine_where_kappa_jumps(knots, coef, degree, u, kappa, speed, kappa_floor):
    """Step 4b: halve every interval across which kappa (above kappa_floor) changes by more than
    KAPPA_STEP_REL, up to REFINE_ROUNDS times. The planner bounds the limit between two nodes by
    the lower of their limits; near a sharp curvature peak that bound is only tight when the
    nodes are close, so the grid is made dense exactly there. A midpoint where C' = 0 takes the
    kappa of the interval's start."""
    n_ctrl = coef.shape[0]
    for _ in range(REFINE_ROUNDS):
        split = np.zeros(u.size, dtype=np.bool_)
        n_split = 0
        for q in range(u.size - 1):
            high = max(kappa[q], kappa[q + 1])
            if high > kappa_floor and abs(kappa[q + 1] - kappa[q]) > KAPPA_STEP_REL * high:
                split[q] = True
                n_split += 1
        if n_split == 0:
            break
        size = u.size + n_split
        u_new = np.empty(size)
        k_new = np.empty(size)
        s_new = np.empty(size)
        n = 0
        span = degree
        for q in range(u.size):
            u_new[n] = u[q]
            k_new[n] = kappa[q]
            s_new[n] = speed[q]
            n += 1
            if split[q]:
                mid = 0.5 * (u[q] + u[q + 1])
                span = find_span(knots, degree, n_ctrl, mid, span)
                c = point_d2(knots, coef, degree, span, mid)
                k_mid, s_mid = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
                u_new[n] = mid
                k_new[n] = k_mid if math.isfinite(k_mid) else kappa[q]
                s_new[n] = s_mid
                n += 1
        u, kappa, speed = u_new, k_new, s_new
    return u, kappa, speed


@jit
def _grid_nodes(knots, coef, degree, breaks, spacing_mm, extra_u, kappa_floor):
    """Steps 1-4: nodes u, kappa, |C'| (M,), refined peak parameters (P,), corners (Q,), and
    the mean |C'| over the samples (the arc length tolerance's scale)."""
    u, kappa, speed = _samples(knots, coef, degree, breaks, spacing_mm)
    mean_speed = speed.mean()
    _fill_singular(kappa)
    idx = _prominent_maxima(kappa)
    peak_u = np.empty(idx.size)
    for k in range(idx.size):
        refined_u, refined_kappa = _refine_peak(knots, coef, degree, u[idx[k] - 1],
                                                u[idx[k] + 1], kappa_floor)
        peak_u[k] = refined_u if refined_kappa > kappa[idx[k]] else u[idx[k]]
    corner_u = _corners(knots, coef, degree, breaks)
    extra = np.concatenate((peak_u, corner_u, extra_u))
    u, kappa, speed = _merge(knots, coef, degree, u, kappa, speed, extra)
    _fill_singular(kappa)
    u, kappa, speed = _refine_where_kappa_jumps(knots, coef, degree, u, kappa, speed,
                                                kappa_floor)
    return u, kappa, speed, peak_u, corner_u, mean_speed


def build_grid(curve: NurbsCurve, spacing_mm: float, extra_u: np.ndarray = np.empty(0),
               kappa_floor: float = np.inf) -> Grid:
    """Sample, find and refine curvature maxima, integrate arc length: the planning grid.

    extra_u: parameters that must be nodes (where the programmed feed changes); kappa_floor:
    below it the limit does not depend on curvature (kappa_0), so neither jumps of kappa nor its
    maxima below it need refining.
    """
    knots, coef, degree = curve.knots, curve.span_polynomials, curve.degree
    u, kappa, speed, peak_u, corner_u, mean_speed = _grid_nodes(
        knots, coef, degree, curve.span_breaks, float(spacing_mm),
        np.ascontiguousarray(extra_u, dtype=float), float(kappa_floor))
    corner_index = np.searchsorted(u, corner_u)
    kappa[corner_index] = np.inf
    peak_index = np.searchsorted(u, np.sort(peak_u))
    s = simpson_lengths(knots, coef, degree, u, speed, ARC_REL_TOL * (mean_speed + 1e-300))
    for a in (u, s, kappa, peak_index, corner_index):
        a.setflags(write=False)
    return Grid(u, s, kappa, peak_index, corner_index)
