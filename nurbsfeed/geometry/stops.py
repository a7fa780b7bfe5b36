"""Where a NURBS curve must come to rest, for the planning grid (planning.grid, step 3): corners
at knots where the unit tangent jumps, zeros of C' (a repeated control point, a cusp, a path
that turns back) found from the samples and at every knot and classified by their one-sided
tangents, and near cusps across which the path turns back. Compiled kernels, written once in
numba's subset."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry.kernel import curvature, find_span, point_d1, point_d2
from nurbsfeed.geometry.peaks import EPS_U, NEEDLE_WIDTHS
from nurbsfeed.jit import jit

CORNER_COS_TOL = 1e-8  # a tangent turning by more than ~1.4e-4 rad at a knot is a corner
CORNER_PROBE_REL = 1e-9  # of the parameter range: how far beside the knot the tangents are taken
ZERO_CANDIDATE_REL = 0.05  # a local minimum of |C'| on the samples below this of the mean
ZERO_ITERATIONS = 60  # Gauss-Newton steps towards a minimum of |C'|^2 (linear at a double zero)
TANGENT_PROBE_REL = 1e-4  # of the span's width: where the chords beside a zero end ...
PROBE_REL = 1e-6  # of a span's width: where the way out of a zero of C' at a knot is read
KAPPA_BOUNDED_REL = 0.25  # kappa beside a zero changing by more than this over 16x: unbounded


def find_corners(knots, coef, degree, breaks, floor_mm, full):
    """Step 3a: interior knots of multiplicity >= degree (their indices into breaks, full,
    from `stop_candidates`) where the unit tangent jumps (not where the curve has no length on
    one side: that is an end). Not compiled (its kernels are): most curves have no such knot."""
    n_ctrl = coef.shape[0]
    eps = CORNER_PROBE_REL * (breaks[breaks.size - 1] - breaks[0])
    out = np.empty(full.size)
    n = 0
    for b in full:
        knot = breaks[b]
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
        if norm_l == 0.0 or norm_r == 0.0:  # C' = 0 beside the knot: `classify_stops` decides
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
def _probe_direction(knots, coef, degree, u0, side, width):
    """The unit direction of travel into (side -1) or out of (side +1) a point u0 where C'
    vanishes: the chord to C(u0 + side h), h = PROBE_REL of the span's width and up to a
    thousand times that while the chord has no length (0 if it never has)."""
    n_ctrl = coef.shape[0]
    span = find_span(knots, degree, n_ctrl, u0, degree)
    px, py, pz, _, _, _ = point_d1(knots, coef, degree, span, u0)
    h = PROBE_REL * width
    for _ in range(4):
        u = u0 + side * h
        span = find_span(knots, degree, n_ctrl, u, span)
        qx, qy, qz, _, _, _ = point_d1(knots, coef, degree, span, u)
        dx, dy, dz = side * (qx - px), side * (qy - py), side * (qz - pz)
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if length > 0.0:
            return dx / length, dy / length, dz / length
        h *= 10.0
    return 0.0, 0.0, 0.0


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


def classify_stops(knots, coef, degree, breaks, u, tangent, zero_speed, mean_speed, floor_mm,
                   kappa_floor, found_u, minima, turns, back):
    """Step 3: the interior points where C' vanishes and the motion must come to rest, from the
    candidates `stop_candidates` found on the samples u (M,) with their unit tangents (M, 3).

    Candidates are the samples where |C'| has a local minimum below ZERO_CANDIDATE_REL of its
    mean (refined by `_refine_zero` inside the bracket of their neighbours; a zero whose
    neighbouring samples are faster than that is a cusp or reversal, found by the next rule, or
    removable), the intervals across which the tangent turns by
    more than 90 degrees, and every interior knot, where |C'| is taken from both sides (a
    repeated control point makes it vanish on one side only). A candidate whose
    |C'| is at most zero_speed is a zero of C'; each is classified by `_zero_is_smooth`: a
    corner (the tangent jumps), a cusp or a reversal (it turns back), or a zero beside which
    kappa is unbounded is a stop (u, and the cosine of the turn); a removable zero is not (its
    kappa is the one-sided limit, see `sampling.fill_singular`). A candidate whose |C'| refines
    to a minimum above zero_speed is a near cusp: where the path turns back across it
    (`_near_cusp_turn`) it is a stop too, a hairpin passed at rest; the others are returned as
    (R,) parameters, where kappa may peak in a needle far narrower than the samples
    (`near_cusp_peaks`). Returns (Q,) parameters (sorted) and cosines, and the (R,) near
    cusps.

    The search over the samples (`stop_candidates`) is compiled; the refinement and the
    classification of the few candidates it finds are not (their kernels are, the first time a
    curve has such a candidate; the grid calls this only then), nor is the sorting: numba
    compiles a quicksort and a binary search of its own for each array type, seconds of the
    first run for a few values.
    """
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
    for low, high, tx, ty, tz in back:
        # C' along the way the curve goes at low changes sign inside: bisect it, then refine
        if high > low and not (tx == 0.0 and ty == 0.0 and tz == 0.0):
            start = _turn_back(knots, coef, degree, tx, ty, tz, low, high)
            at, at_speed = _refine_zero(knots, coef, degree, start, low, high)
            if at_speed <= zero_speed:
                found.append(at)
            elif at_speed <= near_speed:
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
def stop_candidates(knots, coef, degree, breaks, u, speed, pts, tangent, zero_speed,
                    mean_speed, floor_mm):
    """Step 3's search over the samples (see `classify_stops`): the zeros of C' it finds
    without refining (N,: first samples of runs at rest, and knots), the samples (I,) at a local
    minimum of |C'| that needs refining, and the intervals (J,) across which the path turns
    back; and the interior knots of multiplicity >= degree, where a corner may be (their
    indices into breaks, for `find_corners`). The refinements are `classify_stops`' (rare: most
    curves have none, and their kernels then never compile)."""
    n_ctrl = coef.shape[0]
    last = u.size - 1
    full = np.empty(breaks.size, dtype=np.int64)
    n_full = 0
    k = 0
    for b in range(1, breaks.size - 1):
        while knots[k] < breaks[b]:
            k += 1
        multiplicity = 0
        while k + multiplicity < knots.size and knots[k + multiplicity] == breaks[b]:
            multiplicity += 1
        if multiplicity >= degree:
            full[n_full] = b
            n_full += 1
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
    # a reversal between a knot and the sample beside it (C' falls through 0 in the span
    # there): the curve arrives at the knot (leaves it) against the chord from (to) that sample;
    # (low, high) and the direction C' keeps at low (positive along it), C' negative at high
    back = np.empty((2 * breaks.size, 5))
    n_back = 0
    q = 0
    for b in range(1, breaks.size - 1):
        knot = breaks[b]
        span = find_span(knots, degree, n_ctrl, knot, span)  # the span starting at the knot
        before = find_span(knots, degree, n_ctrl, breaks[b - 1], span - 1)
        if (_speed_on_span(knots, coef, degree, before, knot) <= zero_speed
                or _speed_on_span(knots, coef, degree, span, knot) <= zero_speed):
            found[n] = knot
            n += 1  # (a zero at the knot, and perhaps a reversal beside it too)
        while q + 1 < u.size and u[q + 1] < knot:
            q += 1  # u[q] < knot <= u[q + 1]
        for side in range(2):
            at = q if side == 0 else q + 1
            while side == 1 and at < last and u[at] <= knot:
                at += 1
            if (u[at] >= knot) if side == 0 else (u[at] <= knot):
                continue
            px, py, pz, dx, dy, dz = point_d1(knots, coef, degree,
                                              before if side == 0 else span, knot)
            norm = math.sqrt(dx * dx + dy * dy + dz * dz)
            if norm <= zero_speed:  # C' = 0 at the knot: the way the curve arrives or leaves
                width = knot - breaks[b - 1] if side == 0 else breaks[b + 1] - knot
                dx, dy, dz = _probe_direction(knots, coef, degree, knot, 2 * side - 1, width)
                norm = math.sqrt(dx * dx + dy * dy + dz * dz)
            sign = 1.0 if side == 0 else -1.0  # chord in the direction of travel
            cx, cy, cz = (px - pts[at, 0]) * sign, (py - pts[at, 1]) * sign, (
                pz - pts[at, 2]) * sign
            # or the sample's own tangent against that way: the curve turned back between
            # them but has not come back past the knot by the sample (a reversal 0.04 of the
            # span after a zero of C' at the knot), which no chord shows
            against = (speed[at] > zero_speed and dx * tangent[at, 0] + dy * tangent[at, 1]
                       + dz * tangent[at, 2] < 0.0)
            if norm > 0.0 and (dx * cx + dy * cy + dz * cz < -floor_mm * norm or against):
                if side == 0:  # C' at the sample before is the way it goes at low
                    tx, ty, tz = tangent[at, 0], tangent[at, 1], tangent[at, 2]
                else:
                    tx, ty, tz = dx / norm, dy / norm, dz / norm
                back[n_back, 0] = u[at] if side == 0 else knot
                back[n_back, 1] = knot if side == 0 else u[at]
                back[n_back, 2], back[n_back, 3], back[n_back, 4] = tx, ty, tz
                n_back += 1
    return found[:n], minima[:n_minima], turns[:n_turns], back[:n_back], full[:n_full]
