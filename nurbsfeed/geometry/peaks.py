"""Curvature maxima of a NURBS curve, for the planning grid (planning.grid, steps 2 and 3c):
prominent maxima of the samples, each refined inside its bracket by sampling and Brent's
method span by span (kappa from both sides at a knot), maxima hidden beside a span boundary,
and the needle of a near cusp. Compiled kernels, written once in numba's subset; kappa is
evaluated one parameter at a time from the span polynomials (geometry.kernel)."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry.kernel import curvature, find_span, point_d2
from nurbsfeed.jit import jit

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
PEAK_PROMINENCE_REL = 1e-7
NEEDLE_WIDTHS = 8.0  # a near cusp's peak is sought within this many |C'|/|C''| of it


@jit
def prominent_maxima(kappa):
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
def refined_maxima(knots, coef, degree, node_u, node_kappa, held_u, stop_u, kappa_floor,
                   at_least):
    """Step 2b: the curvature maxima of the nodes node_u, node_kappa (M,), refined (P,): each
    prominent maximum (`prominent_maxima`) with kappa at least at_least whose bracket, its
    neighbouring nodes, holds no value of held_u nor of stop_u (both sorted; kappa grows
    without bound into a cusp, so its "maximum" is the bracket's end: the motion rests at a
    stop anyway), as the maximum of kappa in its bracket, or the node itself where that is no
    higher.

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
    at = prominent_maxima(node_kappa)
    peak_u = np.empty(at.size)
    n_peaks = 0
    for q in at:
        low = node_u[q - 1]
        high = node_u[q + 1]
        if (node_kappa[q] < at_least or holds_any(held_u, low, high)
                or holds_any(stop_u, low, high)):
            continue
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
        if best_k >= 0.5 * kappa_floor:
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
                        u, kappa = _brent_max(knots, coef, degree, span, piece_low,
                                              piece_high, start_u, start_k, tol)
                        if kappa > best_k:
                            best_u, best_k = u, kappa
                if piece_high >= b:
                    break
                piece_low = piece_high
                span = find_span(knots, degree, n_ctrl, piece_low, span)
        peak_u[n_peaks] = best_u if best_k > node_kappa[q] else node_u[q]
        n_peaks += 1
    return peak_u[:n_peaks]


@jit
def boundary_maxima(knots, coef, degree, breaks, u, peak_u, stop_u):
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
    `prominent_maxima`. An interval that holds a peak of step 2 (sorted peak_u: a knot inside
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
            if holds_any(peak_u, low, high) or holds_any(stop_u, low, high):
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
def first_above(sorted_x, x):
    """The first index q with sorted_x[q] > x (sorted_x.size if none): np.searchsorted's right
    side (see `first_at_or_above`)."""
    lo = 0
    hi = sorted_x.size
    while lo < hi:
        mid = (lo + hi) // 2
        if sorted_x[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@jit
def holds_any(sorted_u, low, high):
    """Whether sorted_u (K,) has a value in [low, high]."""
    q = first_at_or_above(sorted_u, low)
    return q < sorted_u.size and sorted_u[q] <= high


def near_cusp_peaks(knots, coef, degree, u, kappa, near_u, kappa_floor):
    """Step 2c: the curvature peaks of near cusps (R,) that the samples do not show.

    Where |C'| dips close to 0 without reaching it (the path turns back in a hairpin of a
    radius far below the sample spacing), kappa ~ 1/|C'|^2 peaks in a needle whose width in u
    is ~|C'|/|C''| there: neither neighbouring sample holds it, and sampling their bracket
    (`refined_maxima`) can step over it. Seen on a degree-4 curve: samples 3,777 and 6,087 1/mm
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
        # the bracket as three nodes, the near cusp a maximum between two lower ones
        none = np.empty(0)
        out[n] = refined_maxima(knots, coef, degree, np.array([low, u0, high]),
                                np.array([-np.inf, k0, -np.inf]), none, none, kappa_floor,
                                -np.inf)[0]
        n += 1
    return out[:n]
