"""The dense grid a curve is planned on: parameters, arc length, curvature, pointwise limits.

The grid has nodes at every knot and enough nodes inside each span that consecutive nodes are
at most `spacing_mm` apart; refined curvature maxima are nodes too. The planner checks its speed
profile at these nodes ("limits everywhere"), so the spacing is tied to the step length v_m T.

Building it, in order (`_grid_nodes`, one compiled call; then `simpson_lengths`):
1. Samples: per span, a node count from a 16-chord length estimate, evenly spaced in u.
2. Curvature maxima: local maxima of kappa on the samples that stand out from their valleys,
   each refined inside the bracket of its two neighbours (zoom sampling, then golden section;
   only roughly where kappa stays well below kappa_floor, where the limit is flat).
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
ZOOM_SAMPLES = 11
ZOOM_ROUNDS = 3  # the bracket (two grid steps) shrinks by 5^3 by zoom sampling ...
PEAK_BRACKET_REL = 2e-9  # ... then to this by golden-section search
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
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
    closes the list. Returns u, kappa, |C'| at the nodes: three (M,) arrays."""
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
        span = find_span(knots, degree, n_ctrl, u_nodes[q], span)
        c = point_d2(knots, coef, degree, span, u_nodes[q])
        kappa[q], speed[q] = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
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
def _refine_peak(knots, coef, degree, low, high, kappa_floor):
    """Step 2b: the maximum of kappa in [low, high] (u, kappa).

    Zoom sampling first: ZOOM_SAMPLES points, keep the best and its neighbours as the next
    bracket, ZOOM_ROUNDS times (the bracket shrinks by ZOOM_SAMPLES/2 per round). Unlike a
    parabolic or Newton step it needs no smoothness, so a maximum on a knot (a kink in kappa) is
    found as well as a smooth one, and of several maxima it keeps the highest. The bracket, now
    holding one maximum, is then closed by golden-section search (smoothness-free as well) to
    PEAK_BRACKET_REL of its first width. A peak still below half of kappa_floor after the zoom
    is left there: below kappa_floor its position does not matter.
    """
    n_ctrl = coef.shape[0]
    last = ZOOM_SAMPLES - 1
    step = 1.0 / last
    best_u = low
    best_k = -1.0
    span = degree
    target = (high - low) * PEAK_BRACKET_REL
    for _ in range(ZOOM_ROUNDS):
        best_i = 0
        best_k = -1.0
        width = high - low
        for i in range(ZOOM_SAMPLES):
            u = low + width * (i * step if i < last else 1.0)
            span = find_span(knots, degree, n_ctrl, u, span)
            c = point_d2(knots, coef, degree, span, u)
            kappa, _ = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            if kappa > best_k:  # the first maximum; NaN (C' = 0) never wins
                best_k = kappa
                best_i = i
        best_u = low + width * (best_i * step if best_i < last else 1.0)
        i_low = max(best_i - 1, 0)
        i_high = min(best_i + 1, last)
        low, high = (low + width * (i_low * step if i_low < last else 1.0),
                     low + width * (i_high * step if i_high < last else 1.0))
    if best_k < 0.5 * kappa_floor:
        return best_u, best_k
    # golden section: inner points x1 < x2 with kappa k1, k2; each round evaluates one new point
    x1 = high - GOLDEN * (high - low)
    x2 = low + GOLDEN * (high - low)
    k1 = -1.0
    k2 = -1.0
    fresh = 0  # which inner point to evaluate next: 1 (x1), 2 (x2), 0 both at the start
    while True:
        for which in range(1, 3):
            if fresh != 0 and fresh != which:
                continue
            u = x1 if which == 1 else x2
            span = find_span(knots, degree, n_ctrl, u, span)
            c = point_d2(knots, coef, degree, span, u)
            kappa, _ = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            kappa = kappa if kappa == kappa else -1.0
            if kappa > best_k:
                best_u, best_k = u, kappa
            if which == 1:
                k1 = kappa
            else:
                k2 = kappa
        if high - low <= target:
            return best_u, best_k
        if k1 >= k2:  # the maximum is in [low, x2]
            high, x2, k2 = x2, x1, k1
            x1 = high - GOLDEN * (high - low)
            fresh = 1
        else:
            low, x1, k1 = x1, x2, k2
            x2 = low + GOLDEN * (high - low)
            fresh = 2


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
