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
   (`_boundary_maxima`).
3. Stops, where the feed must come to rest (kappa is infinite there):
   a. corners at knots of multiplicity >= degree, where the unit tangent jumps (`_corners`);
   b. zeros of C' (a control point repeated, a cusp, a path that turns back on itself), found
      as local minima of |C'| on the samples refined by Gauss-Newton, and at every knot from
      both sides (`_stops`). A zero is classified by the one-sided tangents, taken as chords
      from it:
        - they differ (a corner) or are opposite (a cusp, a reversal): a stop;
        - they agree, but kappa grows without bound towards the zero: a stop (v^2 kappa would
          be unbounded at any speed above 0);
        - they agree and kappa has finite one-sided limits: removable, the curve is smooth
          there; its kappa is the limit (the next finite value, `_fill_singular`).
      The ends of the curve are at rest anyway; a zero of C' there only blanks kappa.
   c. near cusps, where |C'| refines to a minimum close to 0 but not 0: kappa peaks there in a
      needle that neither neighbouring sample need show. One across which the path turns back
      (`_near_cusp_turn`) is a hairpin, and a stop like a cusp: the stepping's arc position
      runs a fraction of a micrometre off the law's between rests, enough to meet a tip of
      nanometres before the law has slowed down for it. Any other is refined there and becomes
      a peak (`_near_cusp_peaks`).
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
from nurbsfeed.jit import jit

KAPPA_STEP_REL = 0.1  # refine where kappa changes by more than 10 % between nodes
REFINE_ROUNDS = 6  # ... down to 1/64 of the base spacing
TURN_REFINE_ROUNDS = 24  # where the tangent turns more than kappa explains: down to 1/2^24
TURN_EXPLAINED = 2.0  # a turn up to this times max(kappa) x chord needs no node between
TURN_SLACK_RAD = 1e-3
REFINE_GROWTH_MAX = 8  # the refinement stops before the grid grows beyond this factor
ZOOM_SAMPLES = 11  # the bracket (two grid steps) shrinks by 5 by sampling ...
# ... then to this by Brent's method: about the square root of the double's resolution, since
# kappa is flat to second order at a smooth maximum (kappa is then within ~1e-16 of its peak
# value); a closer bracket only chases the rounding of kappa.
PEAK_BRACKET_REL = 1e-8
BRENT_ITERATIONS = 100
KNOT_PROBE_REL = 1e-6  # of the bracket: where kappa's slope beside a knot is probed
# kappa at that probe above its value at the knot by more than this (relative) falls into the
# knot; less is rounding (a circular arc's kappa is constant to ~1e-15)
BOUNDARY_FALL_REL = 1e-10
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
# |C'| at or below this fraction of the mean |C'| is zero: the curve stops there (step 3). A true
# zero of a polynomial C' refines to ~1e-12 of the mean or below; one that does not is a near
# cusp whose curvature the limits already handle.
ZERO_SPEED_REL = 1e-7
ZERO_CANDIDATE_REL = 0.05  # a local minimum of |C'| on the samples below this of the mean
ZERO_ITERATIONS = 60  # Gauss-Newton steps towards a minimum of |C'|^2 (linear at a double zero)
TANGENT_PROBE_REL = 1e-4  # of the span's width: where the chords beside a zero end ...
TANGENT_CHORD_REL = 1e-9  # ... grown tenfold until they are this long (of the polygon's length)
NEEDLE_WIDTHS = 8.0  # a near cusp's peak is sought within this many |C'|/|C''| of it
KAPPA_BOUNDED_REL = 0.25  # kappa beside a zero changing by more than this over 16x: unbounded


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
    # the valleys' minima by loops: ndarray.min would compile numba's own reduction
    left_valley = 0.0
    if n > 0:
        left_valley = kappa[0]
        for q in range(1, cand[0]):
            left_valley = min(left_valley, kappa[q])
    for k in range(n):
        stop = cand[k + 1] if k + 1 < n else kappa.size
        right_valley = kappa[cand[k]]
        for q in range(cand[k] + 1, stop):
            right_valley = min(right_valley, kappa[q])
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
            elif fu <= fv or v == x or v == w:  # noqa: SIM109 (numba's subset)
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


def _corners(knots, coef, degree, breaks, floor_mm):
    """Step 3a: interior knots of multiplicity >= degree where the unit tangent jumps (not
    where the curve has no length on one side: that is an end). Not compiled (its kernels
    are): it looks at each knot once."""
    n_ctrl = coef.shape[0]
    eps = CORNER_PROBE_REL * (breaks[breaks.size - 1] - breaks[0])
    out = np.empty(max(breaks.size - 2, 0))
    n = 0
    for b in range(1, breaks.size - 1):
        knot = breaks[b]
        if np.count_nonzero(knots == knot) < degree:
            continue
        _, _, _, h_before = _chord_from(knots, coef, degree, knot, -1.0,
                                        knot - breaks[b - 1], breaks[0], floor_mm)
        _, _, _, h_after = _chord_from(knots, coef, degree, knot, 1.0,
                                       breaks[b + 1] - knot, breaks[breaks.size - 1], floor_mm)
        if h_before == 0.0 or h_after == 0.0:
            continue
        span = find_span(knots, degree, n_ctrl, knot - eps, degree)
        _, _, _, lx, ly, lz = point_d1(knots, coef, degree, span, knot - eps)
        span = find_span(knots, degree, n_ctrl, knot + eps, span)
        _, _, _, rx, ry, rz = point_d1(knots, coef, degree, span, knot + eps)
        norm_l = math.sqrt(lx * lx + ly * ly + lz * lz)
        norm_r = math.sqrt(rx * rx + ry * ry + rz * rz)
        if norm_l == 0.0 or norm_r == 0.0:  # C' = 0 beside the knot: `_stops` decides
            continue
        cos = (lx / norm_l) * (rx / norm_r) + (ly / norm_l) * (ry / norm_r) + (
            lz / norm_l) * (rz / norm_r)
        if cos < 1.0 - CORNER_COS_TOL:
            out[n] = knot
            n += 1
    return out[:n]


@jit
def _speed_on_span(knots, coef, degree, span, u):
    """|C'(u)| from span `span`'s polynomial (at a knot: its limit from that span's side)."""
    _, _, _, dx, dy, dz = point_d1(knots, coef, degree, span, u)
    return math.sqrt(dx * dx + dy * dy + dz * dz)


@jit
def _kappa_or_nan(knots, coef, degree, u, zero_speed):
    """kappa at u; NaN where |C'| <= zero_speed (there it is rounding noise over ~0)."""
    span = find_span(knots, degree, coef.shape[0], u, degree)
    c = point_d2(knots, coef, degree, span, u)
    kappa, speed = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
    return kappa if speed > zero_speed else math.nan


@jit
def _turn_back(knots, coef, degree, tx, ty, tz, low, high):
    """Where C'.t changes sign in [low, high] (positive at low, negative at high), by
    bisection to the resolution of u."""
    n_ctrl = coef.shape[0]
    span = find_span(knots, degree, n_ctrl, low, degree)
    for _ in range(ZERO_ITERATIONS):
        mid = 0.5 * (low + high)
        if mid <= low or mid >= high:
            break
        span = find_span(knots, degree, n_ctrl, mid, span)
        _, _, _, dx, dy, dz = point_d1(knots, coef, degree, span, mid)
        if dx * tx + dy * ty + dz * tz > 0.0:
            low = mid
        else:
            high = mid
    return 0.5 * (low + high)


@jit
def _refine_zero(knots, coef, degree, u, low, high):
    """Step 3a: Gauss-Newton towards a minimum of |C'|^2 in [low, high] from u, (u, |C'(u)|).

    The step is the zero of C' linearised at u, -(C'.C'') / |C''|^2, kept inside the bracket:
    quadratic convergence at a simple zero of C' (a cusp, a reversal), linear (halving) at a
    double one, and at a minimum that is not a zero it stops where |C'| is smallest."""
    n_ctrl = coef.shape[0]
    span = find_span(knots, degree, n_ctrl, u, degree)
    for _ in range(ZERO_ITERATIONS):
        span = find_span(knots, degree, n_ctrl, u, span)
        c = point_d2(knots, coef, degree, span, u)
        grad = c[3] * c[6] + c[4] * c[7] + c[5] * c[8]
        curv = c[6] * c[6] + c[7] * c[7] + c[8] * c[8]
        if curv == 0.0:
            break
        nxt = min(max(u - grad / curv, low), high)
        if nxt == u:
            break
        u = nxt
    span = find_span(knots, degree, n_ctrl, u, span)
    return u, _speed_on_span(knots, coef, degree, span, u)


@jit
def _chord_from(knots, coef, degree, u0, side, width, u_limit, floor_mm):
    """Step 3b: the unit chord between C(u0) and C(u0 + side h), in the direction of travel,
    with h = TANGENT_PROBE_REL * width grown tenfold until the chord is at least floor_mm long
    (never past u_limit, and never past a knot without a chord to it: past a span of no length,
    a tenfold step could leap to a point the curve comes back to, such as the start of a
    closed curve, and call the curve an end there). At a zero of C' this is the one-sided
    tangent: the curve leaves the point along it. Returns the unit vector and h; h = 0 if no
    chord is long enough."""
    n_ctrl = coef.shape[0]
    span = find_span(knots, degree, n_ctrl, u0, degree)
    px, py, pz, _, _, _ = point_d1(knots, coef, degree, span, u0)
    h = TANGENT_PROBE_REL * width
    reached = u0
    while True:
        u = u0 + side * h
        if side * (u - u_limit) > 0.0:
            u = u_limit
        nearest = u  # the first knot past the last probe, if this step would leap it
        for k in knots:
            if side * (k - reached) > 0.0 and side * (nearest - k) > 0.0:
                nearest = k
        if nearest != u:
            u = nearest
            h = abs(u - u0)
        reached = u
        span = find_span(knots, degree, n_ctrl, u, span)
        qx, qy, qz, _, _, _ = point_d1(knots, coef, degree, span, u)
        dx = side * (qx - px)
        dy = side * (qy - py)
        dz = side * (qz - pz)
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if length >= floor_mm and length > 0.0:  # floor_mm is 0 if the polygon has no length
            return dx / length, dy / length, dz / length, abs(u - u0)
        if u == u_limit:
            return 0.0, 0.0, 0.0, 0.0
        h *= 10.0


@jit
def _zero_is_smooth(knots, coef, degree, u0, width_before, width_after, floor_mm, kappa_floor):
    """Step 3c: whether the curve passes a zero of C' at u0 smoothly (the zero is removable),
    and the cosine of the turn there (1: none, -1: the path turns back on itself). A zero with
    no length on one side (the curve's first or last span(s) have none) is an end, not a stop.

    Smooth means: the one-sided tangents (`_chord_from`) agree to CORNER_COS_TOL, and kappa
    has finite one-sided limits: kappa at h and 16 h beside u0 on each side differs by at most
    KAPPA_BOUNDED_REL (or stays below kappa_floor, where it does not limit the feed). Near a
    repeated control point kappa often grows like s^-1/2 towards the zero: v^2 kappa would be
    unbounded at any speed but 0, so such a zero is a stop however straight the path looks.
    """
    u_min = knots[degree]
    u_max = knots[knots.size - degree - 1]
    bx, by, bz, h_before = _chord_from(knots, coef, degree, u0, -1.0, width_before, u_min,
                                       floor_mm)
    ax, ay, az, h_after = _chord_from(knots, coef, degree, u0, 1.0, width_after, u_max,
                                      floor_mm)
    if h_before == 0.0 or h_after == 0.0:  # no length on one side: an end of the curve
        return True, 1.0
    cos = bx * ax + by * ay + bz * az
    if cos < 1.0 - CORNER_COS_TOL:
        return False, cos
    zero_speed = 0.0
    for side, h in ((-1.0, h_before), (1.0, h_after)):
        near = _kappa_or_nan(knots, coef, degree, u0 + side * h, zero_speed)
        far_u = min(max(u0 + side * 16.0 * h, u_min), u_max)
        far = _kappa_or_nan(knots, coef, degree, far_u, zero_speed)
        if not (math.isfinite(near) and math.isfinite(far)):
            return False, cos
        high = max(near, far)
        if high > kappa_floor and abs(near - far) > KAPPA_BOUNDED_REL * high:
            return False, cos
    return True, cos


@jit
def _near_cusp_turn(knots, coef, degree, u0):
    """Step 3d: the cosine of the turn across a near cusp at u0 (a minimum of |C'| that is not
    0): between the chords that arrive at C(u0) from NEEDLE_WIDTHS widths |C'|/|C''| before it
    and leave it to as far after it (within the curve). Where C' ~ d + (u - u0) b, the tangent
    turns by 2 atan(NEEDLE_WIDTHS) ~ 166 degrees over them: a turn back (cos < 0) is a hairpin
    whose tip can be far tighter than any sample spacing, and the stepping's arc position, a
    fraction of a micrometre off the law's between rests (rk2c runs ahead by the arc minus the
    chord of every step), would meet the tip while the law is still slowing down: ahead of a
    hairpin of radius 1e-12 mm planned at 2e-9 mm/s the velocity reversed at 0.06 mm/s. Passed
    at rest, the stepping lands exactly on it."""
    n_ctrl = coef.shape[0]
    u_min = knots[degree]
    u_max = knots[knots.size - degree - 1]
    span = find_span(knots, degree, n_ctrl, u0, degree)
    c = point_d2(knots, coef, degree, span, u0)
    speed = math.sqrt(c[3] * c[3] + c[4] * c[4] + c[5] * c[5])
    acc = math.sqrt(c[6] * c[6] + c[7] * c[7] + c[8] * c[8])
    if acc == 0.0:
        return 1.0
    width = NEEDLE_WIDTHS * speed / acc
    lo = max(u0 - width, u_min)
    hi = min(u0 + width, u_max)
    if lo >= u0 or hi <= u0:
        return 1.0
    ax, ay, az, _, _, _ = point_d1(knots, coef, degree, find_span(knots, degree, n_ctrl, lo,
                                                                    span), lo)
    bx, by, bz, _, _, _ = point_d1(knots, coef, degree, find_span(knots, degree, n_ctrl, hi,
                                                                    span), hi)
    ix, iy, iz = c[0] - ax, c[1] - ay, c[2] - az
    ox, oy, oz = bx - c[0], by - c[1], bz - c[2]
    norm = math.sqrt((ix * ix + iy * iy + iz * iz) * (ox * ox + oy * oy + oz * oz))
    if norm == 0.0:
        return 1.0
    return (ix * ox + iy * oy + iz * oz) / norm


def _stops(knots, coef, degree, breaks, u, speed, pts, tangent, zero_speed, mean_speed, floor_mm,
           kappa_floor):
    """Step 3: the interior points where C' vanishes and the motion must come to rest.

    Candidates are the samples where |C'| has a local minimum below ZERO_CANDIDATE_REL of its
    mean (refined by `_refine_zero` inside the bracket of their neighbours; a zero whose
    neighbouring samples are faster than that is a cusp or reversal, found by the next rule, or
    removable), the intervals across which the tangent turns by
    more than 90 degrees, and every interior knot, where |C'| is taken from both sides (a
    repeated control point makes it vanish on one side only). A candidate whose
    |C'| is at most zero_speed is a zero of C'; each is classified by `_zero_is_smooth`: a
    corner (the tangent jumps), a cusp or a reversal (it turns back), or a zero beside which
    kappa is unbounded is a stop (u, and the cosine of the turn); a removable zero is not (its
    kappa is the one-sided limit, see `_fill_singular`). A candidate whose |C'| refines to a
    minimum above zero_speed is a near cusp: where the path turns back across it
    (`_near_cusp_turn`) it is a stop too, a hairpin passed at rest; the others are returned as
    (R,) parameters, where kappa may peak in a needle far narrower than the samples
    (`_near_cusp_peaks`). Returns (Q,) parameters (sorted) and cosines, and the (R,) near
    cusps.

    The search over the samples (`_stop_candidates`) is compiled; the refinement and the
    classification of the few candidates it finds are not (their kernels are, the first time a
    curve has such a candidate), nor is the sorting: numba compiles a quicksort and a binary
    search of its own for each array type, seconds of the first run for a few values.
    """
    found_u, minima, turns = _stop_candidates(knots, coef, degree, breaks, u, speed, pts,
                                              tangent, zero_speed, mean_speed, floor_mm)
    found, near = list(found_u), []
    near_speed = ZERO_CANDIDATE_REL * mean_speed
    for q in minima:
        # from the sample and from the middle of each interval beside it: the zero may lie
        # just before a knot whose sample is taken on the span after it
        best_speed = np.inf
        at = u[q]
        for start in (u[q], 0.5 * (u[q - 1] + u[q]), 0.5 * (u[q] + u[q + 1])):
            here, here_speed = _refine_zero(knots, coef, degree, start, u[q - 1], u[q + 1])
            if here_speed < best_speed:
                at, best_speed = here, here_speed
        if best_speed <= zero_speed:
            found.append(at)
        elif best_speed <= near_speed:
            near.append(at)
    for q in turns:
        at, at_speed = _refine_zero(knots, coef, degree, 0.5 * (u[q] + u[q + 1]), u[q],
                                    u[q + 1])
        if at_speed > zero_speed:
            # Gauss-Newton from the middle can leave for the bracket's end and stay there (C''
            # jumps at a knot of multiplicity 2); the tangent's component along the first
            # sample's changes sign inside, and bisecting it brackets the turn
            start = _turn_back(knots, coef, degree, tangent[q, 0], tangent[q, 1],
                               tangent[q, 2], u[q], u[q + 1])
            at, at_speed = _refine_zero(knots, coef, degree, start, u[q], u[q + 1])
        if at_speed <= zero_speed:
            found.append(at)
        elif at_speed <= near_speed:  # not a corner's flip of the tangent
            near.append(at)
    zeros, near = np.sort(np.array(found, dtype=float)), np.sort(np.array(near, dtype=float))
    n = zeros.size
    n_near = near.size
    resolution = EPS_U * 16.0 * (breaks[breaks.size - 1] - breaks[0])
    stop_u = np.empty(n + n_near)
    stop_cos = np.empty(n + n_near)
    m = 0
    bends = np.empty(n_near)
    n_bends = 0
    for i in range(n_near):
        u0 = near[i]
        if (i > 0 and u0 - near[i - 1] <= resolution) or u0 <= breaks[0] or (
                u0 >= breaks[breaks.size - 1]):
            continue
        cos = _near_cusp_turn(knots, coef, degree, u0)
        if cos < 0.0:
            stop_u[m] = u0
            stop_cos[m] = cos
            m += 1
        else:
            bends[n_bends] = u0
            n_bends += 1
    for i in range(n):
        u0 = zeros[i]
        if (i > 0 and u0 - zeros[i - 1] <= resolution) or u0 <= breaks[0] or (
                u0 >= breaks[breaks.size - 1]):
            continue
        b = int(np.searchsorted(breaks, u0, side="right"))  # breaks[b - 1] <= u0 < breaks[b]
        width_after = breaks[b] - breaks[b - 1]
        width_before = width_after
        if u0 == breaks[b - 1] and b >= 2:  # on a knot: the span before it
            width_before = breaks[b - 1] - breaks[b - 2]
        smooth, cos = _zero_is_smooth(knots, coef, degree, u0, width_before, width_after,
                                      floor_mm, kappa_floor)
        if not smooth:
            stop_u[m] = u0
            stop_cos[m] = cos
            m += 1
    order = np.argsort(stop_u[:m], kind="stable")
    return stop_u[:m][order], stop_cos[:m][order], bends[:n_bends]


@jit
def _stop_candidates(knots, coef, degree, breaks, u, speed, pts, tangent, zero_speed,
                     mean_speed, floor_mm):
    """Step 3's search over the samples (see `_stops`): the zeros of C' it finds without
    refining (N,: first samples of runs at rest, and knots), the samples (I,) at a local
    minimum of |C'| that needs refining, and the intervals (J,) across which the path turns
    back. The refinements are `_stops`' (rare: most curves have none, and their kernels then
    never compile)."""
    n_ctrl = coef.shape[0]
    last = u.size - 1
    found = np.empty(u.size + breaks.size)
    n = 0
    minima = np.empty(u.size, dtype=np.int64)
    n_minima = 0
    turns = np.empty(u.size, dtype=np.int64)
    n_turns = 0
    for q in range(1, last):
        if (speed[q] > speed[q - 1] or speed[q] > speed[q + 1]
                or speed[q] > ZERO_CANDIDATE_REL * mean_speed):
            continue
        if speed[q] <= zero_speed:
            if speed[q - 1] > zero_speed:  # the first sample of a run at rest
                found[n] = u[q]
                n += 1
            continue
        minima[n_minima] = q
        n_minima += 1
    # a cusp or reversal between two samples need not show as a minimum of |C'| on them (|C'|
    # may fall on through it); the tangent turning back by more than 90 degrees does, and so
    # does a chord going back along the first sample's tangent (by more than floor_mm, beyond
    # rounding): C'.t must change sign inside. A reversal just before a corner knot,
    # whose sample takes the tangent after the knot, leaves both tangents pointing back while
    # the curve between them went forward
    for q in range(last):
        turn = (tangent[q, 0] * tangent[q + 1, 0] + tangent[q, 1] * tangent[q + 1, 1]
                + tangent[q, 2] * tangent[q + 1, 2])
        cx = pts[q + 1, 0] - pts[q, 0]
        cy = pts[q + 1, 1] - pts[q, 1]
        cz = pts[q + 1, 2] - pts[q, 2]
        ahead = tangent[q, 0] * cx + tangent[q, 1] * cy + tangent[q, 2] * cz
        if speed[q] <= zero_speed or speed[q + 1] <= zero_speed or (
                turn >= 0.0 and ahead >= -floor_mm):
            continue
        turns[n_turns] = q
        n_turns += 1
    span = degree
    for b in range(1, breaks.size - 1):
        knot = breaks[b]
        span = find_span(knots, degree, n_ctrl, knot, span)  # the span starting at the knot
        before = find_span(knots, degree, n_ctrl, breaks[b - 1], span - 1)
        if (_speed_on_span(knots, coef, degree, before, knot) <= zero_speed
                or _speed_on_span(knots, coef, degree, span, knot) <= zero_speed):
            found[n] = knot
            n += 1
    return found[:n], minima[:n_minima], turns[:n_turns]


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


@jit
def _boundary_maxima(knots, coef, degree, breaks, u, peak_u, stop_u):
    """Step 2d: curvature maxima inside a sample interval that ends at a span boundary (a knot
    or an end of the curve), which no sample shows as a local maximum (P,).

    Step 2 brackets a maximum by the samples beside a local maximum of the samples; a maximum
    strictly inside the last interval before a boundary escapes it when kappa keeps rising on
    the samples past it: at an end (no sample beyond), or at a knot where kappa jumps down and
    the knot's sample takes the higher side. Found by fuzzing: kappa 37 between an end (20)
    and the node before it (18); 21.7 between a knot (16.8, 7.5 beyond) and the node before
    it (16.4).
    The grid's refinement (step 4) splits on differences of kappa at the ends of an interval
    and cannot see such a bump, and the planner's eroded limit assumes none: the speed there
    was 20 % above the limit. Per side of each boundary, from that span's polynomial: where
    kappa falls into the boundary (a probe just inside is higher, beyond rounding) and that
    probe is above the sample beside it, the interval holds a maximum: sampled, then Brent's
    method. It counts where it stands out from both ends of the interval, as in
    `_prominent_maxima`. An interval that holds a peak of step 2 (sorted peak_u: a knot inside
    its bracket is searched from both sides) or a stop (sorted stop_u) is skipped."""
    n_ctrl = coef.shape[0]
    found = np.empty(2 * breaks.size)
    n = 0
    last = ZOOM_SAMPLES - 1
    for b in range(breaks.size):
        at = first_at_or_above(u, breaks[b])  # the samples hold every break exactly
        for side in (-1, 1):
            beside = at + side
            if beside < 0 or beside >= u.size:
                continue
            low, high = min(u[at], u[beside]), max(u[at], u[beside])
            if _holds_any(peak_u, low, high) or _holds_any(stop_u, low, high):
                continue
            span = find_span(knots, degree, n_ctrl, 0.5 * (low + high), degree)
            k_end = _kappa_on_span(knots, coef, degree, span, u[at])
            if k_end < 0.0:
                continue  # C' = 0 there: a stop or an end at rest, handled by step 3
            probe_u = u[at] + side * KNOT_PROBE_REL * (high - low)
            k_probe = _kappa_on_span(knots, coef, degree, span, probe_u)
            if k_probe <= k_end * (1.0 + BOUNDARY_FALL_REL):
                continue
            k_beside = _kappa_on_span(knots, coef, degree, span, u[beside])
            if k_probe <= k_beside:
                continue
            # the interval's points in order: its ends, ZOOM_SAMPLES - 2 inside, and the probe
            pts_u = np.empty(ZOOM_SAMPLES + 1)
            pts_k = np.empty(ZOOM_SAMPLES + 1)
            # evenly spaced points are in order already: the probe goes in after those below
            # it (sorting them would compile numba's quicksort)
            i_probe = 0
            for i in range(ZOOM_SAMPLES):
                pts_u[i] = low + (high - low) * (i / last) if i < last else high
                if pts_u[i] <= probe_u:
                    i_probe = i + 1
            for i in range(ZOOM_SAMPLES, i_probe, -1):
                pts_u[i] = pts_u[i - 1]
            pts_u[i_probe] = probe_u
            best = 1
            for i in range(pts_u.size):
                if pts_u[i] == probe_u:
                    pts_k[i] = k_probe
                elif pts_u[i] == u[at]:
                    pts_k[i] = k_end
                elif pts_u[i] == u[beside]:
                    pts_k[i] = k_beside
                else:
                    pts_k[i] = _kappa_on_span(knots, coef, degree, span, pts_u[i])
                if 0 < i < pts_u.size - 1 and pts_k[i] > pts_k[best]:
                    best = i
            top_u, top_k = _brent_max(knots, coef, degree, span, pts_u[best - 1],
                                      pts_u[best + 1], pts_u[best], pts_k[best],
                                      PEAK_BRACKET_REL * (high - low))
            if top_k > max(k_end, k_beside) * (1.0 + PEAK_PROMINENCE_REL):
                found[n] = top_u
                n += 1
    return found[:n]


@jit
def first_at_or_above(sorted_x, x):
    """The first index q with sorted_x[q] >= x (sorted_x.size if none): np.searchsorted's left
    side, by bisection written out, since numba's np.searchsorted compiles its own search and
    comparators per array type."""
    lo = 0
    hi = sorted_x.size
    while lo < hi:
        mid = (lo + hi) // 2
        if sorted_x[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@jit
def _holds_any(sorted_u, low, high):
    """Whether sorted_u (K,) has a value in [low, high]."""
    q = first_at_or_above(sorted_u, low)
    return q < sorted_u.size and sorted_u[q] <= high


def _near_cusp_peaks(knots, coef, degree, u, kappa, near_u, kappa_floor):
    """Step 2c: the curvature peaks of near cusps (R,) that the samples do not show.

    Where |C'| dips close to 0 without reaching it (the path turns back in a hairpin of a
    radius far below the sample spacing), kappa ~ 1/|C'|^2 peaks in a needle whose width in u
    is ~|C'|/|C''| there: neither neighbouring sample holds it, and sampling their bracket
    (`_refine_peak`) can step over it. Seen on a degree-4 curve: samples 3,777 and 6,087 1/mm
    either side of a peak of 2.4e7, which the plan then passed at 0.11 mm/s, its velocity
    reversing within one period. The peak lies beside the minimum of |C'|: each near cusp
    whose kappa reaches kappa_floor and exceeds both samples around it is refined over a few
    needle widths about it. Not compiled (its kernels are): there are a few near cusps.
    """
    n_ctrl = coef.shape[0]
    out = np.empty(near_u.size)
    n = 0
    for r in range(near_u.size):
        u0 = near_u[r]
        q = min(max(int(np.searchsorted(u, u0, side="right")) - 1, 0), u.size - 2)
        span = find_span(knots, degree, n_ctrl, u0, degree)
        c = point_d2(knots, coef, degree, span, u0)
        k0, speed0 = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
        if not k0 >= kappa_floor or not k0 > max(kappa[q], kappa[q + 1]):
            continue
        acc0 = math.sqrt(c[6] * c[6] + c[7] * c[7] + c[8] * c[8])
        low, high = u[max(q - 1, 0)], u[min(q + 2, u.size - 1)]
        if acc0 > 0.0:
            width = NEEDLE_WIDTHS * speed0 / acc0
            low, high = max(low, u0 - width), min(high, u0 + width)
        peak, peak_k = _refine_peak(knots, coef, degree, low, high, kappa_floor)
        out[n] = peak if peak_k > k0 else u0
        n += 1
    return out[:n]


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
    idx = _prominent_maxima(kappa)
    peak_u = np.empty(idx.size)
    for k in range(idx.size):
        refined_u, refined_kappa = _refine_peak(knots, coef, degree, u[idx[k] - 1],
                                                u[idx[k] + 1], kappa_floor)
        peak_u[k] = refined_u if refined_kappa > kappa[idx[k]] else u[idx[k]]
    corner_u = _corners(knots, coef, degree, breaks, floor_mm)
    zero_u, zero_cos, near_u = _stops(knots, coef, degree, breaks, u, speed, pts, tan,
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
        keep[k] = not _holds_any(stop_u, u[idx[k] - 1], u[idx[k] + 1])
    peak_u = peak_u[keep]
    needles = _near_cusp_peaks(knots, coef, degree, u, kappa, near_u, kappa_floor)
    peak_u = np.sort(np.concatenate((peak_u, needles)))
    beside_u = _boundary_maxima(knots, coef, degree, breaks, u, peak_u, stop_u)
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
    idx = _prominent_maxima(kappa)
    more = []
    for k in range(idx.size):
        low, high = u[idx[k] - 1], u[idx[k] + 1]
        if kappa[idx[k]] < kappa_floor:
            continue
        if _holds_any(peak_u, low, high) or _holds_any(stop_u, low, high):
            continue
        refined_u, refined_kappa = _refine_peak(knots, coef, degree, low, high, kappa_floor)
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
