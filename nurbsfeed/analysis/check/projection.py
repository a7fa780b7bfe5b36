"""Written points mapped back to their curve: foot parameters and distances, in order."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.kernel import eval_d1, find_span
from nurbsfeed.jit import jit

PROJECT_ITERATIONS = 100
PROJECT_U_TOL_REL = 1e-16  # bisection ends when the bracket is this narrow (of |u| + range)
PROJECT_SEED_REL = 1e-9  # first walking step (of the knot range) where |C'| = 0
# Walking steps are at most this share of the knot range: where |C'| is nearly 0 (a repeated
# control point) chord / |C'| would jump to the far end, past the foot and what follows it.
PROJECT_STEP_MAX_REL = 1e-3
# ... and cover at most this share of the distance to the point (or back_mm, if more).
PROJECT_STEP_ARC_SHARE = 0.25
# Minima within the acceptance are gathered up to this many last parameter steps ahead.
PROJECT_WINDOW_STEPS = 3.0
# A point the forward search leaves far from the curve is looked for again over the rest of the
# curve: the best of this many evenly spaced parameters, refined by golden section.
PROJECT_SCAN_SAMPLES = 4096
# A point the walk leaves beyond accept_mm is looked for again this many PROJECT_STEP_MAX_REL
# either side of the anchor (the same number of samples) before it counts as off the curve.
PROJECT_LOCAL_STEPS = 4.0
NEAREST_SAMPLES = 4097  # per level of `nearest_on_curve`'s search
# levels of it: with two, the samples near a corner of a 180 mm polyline were about r apart, and
# a point 0.8 r from the curve was measured 1.1 r off
NEAREST_LEVELS = 3
# g = C'.(C - P) is taken as positive only above this many units of rounding of |C'| |C|: C is
# computed to a few ulps of the coordinates, and near a stop the true g is smaller than that.
PROJECT_G_NOISE_EPS = 64.0
EPS = 2.220446049250313e-16
GOLDEN = 0.5 * (math.sqrt(5.0) - 1.0)


@jit
def _distance2(knots, cw, degree, n_ctrl, u, span, tx, ty, tz, basis, dbasis, left, right, p, d):
    span = find_span(knots, degree, n_ctrl, u, span)
    eval_d1(knots, cw, degree, u, span, basis, dbasis, left, right, p, d)
    return (tx - p[0]) ** 2 + (ty - p[1]) ** 2 + (tz - p[2]) ** 2, span


@jit
def _growing(p, d, tx, ty, tz):
    """Whether |C - P| grows along C' (p: C (3,), d: C' (3,)): g = C'.(C - P) above its
    rounding noise."""
    g = d[0] * (p[0] - tx) + d[1] * (p[1] - ty) + d[2] * (p[2] - tz)
    scale = abs(p[0]) + abs(p[1]) + abs(p[2]) + abs(tx) + abs(ty) + abs(tz)
    noise = PROJECT_G_NOISE_EPS * EPS * math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) * scale
    return g > noise


@jit
def _probe(knots, cw, degree, n_ctrl, u, span, tx, ty, tz, basis, dbasis, left, right, p, d):
    """Whether |C(u) - P| grows at u, and its square. Growing: g(u) = C'(u).(C(u) - P) above
    its rounding noise. Where C' = 0 the curve stops and goes on; near a stop g is lost in the
    rounding of C - P: neither is growing. Returns (growing, distance^2, span); leaves C(u) in
    p."""
    span = find_span(knots, degree, n_ctrl, u, span)
    eval_d1(knots, cw, degree, u, span, basis, dbasis, left, right, p, d)
    return _growing(p, d, tx, ty, tz), (tx - p[0]) ** 2 + (ty - p[1]) ** 2 + (tz - p[2]) ** 2, span


@jit
def _golden(knots, cw, degree, n_ctrl, a, b, u, dist2, span, tx, ty, tz, basis, dbasis, left,
            right, p, d):
    """The least |C(u) - P|^2 on [a, b] by golden section, starting from the best so far (u,
    dist2): returns (u, dist2, span)."""
    for _ in range(PROJECT_ITERATIONS):
        x1 = b - GOLDEN * (b - a)
        x2 = a + GOLDEN * (b - a)
        f1, span = _distance2(knots, cw, degree, n_ctrl, x1, span, tx, ty, tz, basis, dbasis,
                              left, right, p, d)
        f2, span = _distance2(knots, cw, degree, n_ctrl, x2, span, tx, ty, tz, basis, dbasis,
                              left, right, p, d)
        if f1 <= f2:
            b = x2
        else:
            a = x1
        if min(f1, f2) < dist2:
            dist2 = min(f1, f2)
            u = x1 if f1 <= f2 else x2
    return u, dist2, span


@jit
def _scan(knots, cw, degree, n_ctrl, a, b, u, dist2, span, tx, ty, tz, basis, dbasis, left,
          right, p, d):
    """The nearest of PROJECT_SCAN_SAMPLES even parameters on [a, b], refined by golden section,
    if it is nearer than the best so far (u, dist2): returns (u, dist2, span)."""
    width = (b - a) / (PROJECT_SCAN_SAMPLES - 1)
    best = -1
    for q in range(PROJECT_SCAN_SAMPLES):
        dq, span = _distance2(knots, cw, degree, n_ctrl, a + q * width, span, tx, ty, tz, basis,
                              dbasis, left, right, p, d)
        if dq < dist2:
            dist2 = dq
            best = q
    if best >= 0:
        # golden section is only sure of a minimum where the distance has one: a corner (a knot
        # where the curve is C0) inside the bracket can put one minimum on each leg, and the
        # section would settle on either, so each piece between knots is refined on its own
        lo = max(a, a + (best - 1) * width)
        end = min(b, a + (best + 1) * width)
        u_best = a + best * width
        while lo < end:
            span = find_span(knots, degree, n_ctrl, lo, span)
            hi = min(end, knots[span + 1]) if knots[span + 1] > lo else end
            u_best, dist2, span = _golden(knots, cw, degree, n_ctrl, lo, hi, u_best, dist2,
                                          span, tx, ty, tz, basis, dbasis, left, right, p, d)
            lo = hi
        u = u_best
    return u, dist2, span


@jit
def _project_kernel(knots, cw, degree, targets, u_first, u_last, back_mm, accept_mm, anchor_mm,
                    u_out, dist_out, other_out):
    """Foot parameters of targets (N, 3), in order: u_out (N,), distances dist_out (N,), and
    other_out (N,): the minimum within accept_mm farthest from the foot (NaN: none other).

    The search walks forward from the origin, back_mm of arc behind the last anchored point
    (rounding may put a point slightly behind the one before), by steps that double up to
    PROJECT_STEP_MAX_REL of the knot range and cover at most PROJECT_STEP_ARC_SHARE of the
    distance to P (and back_mm). Its candidates are the local minima of |C(u) - P|: the origin
    where the distance grows there; each step over which g(u) = C'(u).(C(u) - P) turns positive
    (at a step's end on a corner, with C' of the leg it arrives by), bisected; each step that
    ends farther than it began without g turning (it ends on a stop), by golden section; and the
    curve end where the distance still falls there.

    Where C' = 0 (a corner, a cusp or reversal, a zero-length span of coincident control points)
    g = 0 too, but the distance need not be least there: the curve stops and goes on. So only g
    above its rounding noise counts as growing, and a step is bisected, never refined by Newton:
    near a stop g/g' shrinks geometrically towards the stop itself and Newton would settle there.

    At a reversal the point just after the turn is as near the way out as the way back. The
    choice follows the parameter's own pace: minima within accept_mm are gathered up to
    PROJECT_WINDOW_STEPS last parameter steps ahead of the anchor, and the one nearest the anchor
    plus the last step is taken (u(t) passes a reversal at a finite rate while C' = 0). The
    parameter never runs back: the anchor never moves back, and a minimum whose chord to the
    anchor exceeds back_mm lies on the leg before a turn-back and is only the nearest so far. The
    motion rests on a corner and a point is written there: once the anchor is past a corner or
    its point within accept_mm of it, the walk starts afresh at the corner. With no minimum
    within accept_mm the walk goes on for twice the chord from the anchor plus back_mm past the
    anchor (past a corner the foot is about that far) and takes the nearest minimum. A point
    left farther than anchor_mm is looked for again on a grid over the rest of the curve (a
    dropped stretch of moves puts the next point far ahead). A point within anchor_mm becomes
    the anchor (if it is not behind it).

    Where the curve retraces itself through a cusp, a point written within rounding of the
    cusp can round onto a point of the leg in: position cannot tell the legs apart, and the foot
    can be on either (fuzz seed 36: three points kept on the leg in, 5 r of arc off). A point
    whose foot does not move the anchor on therefore walks on to the reach (as a point with no
    foot would) without changing its foot, gathering the other minima within accept_mm:
    other_out lets the caller allow for the arc between them.
    """
    n_ctrl = cw.shape[0]
    basis = np.empty(degree + 1)
    dbasis = np.empty(degree + 1)
    left = np.empty(degree + 1)
    right = np.empty(degree + 1)
    p = np.empty(3)
    d = np.empty(3)
    seed = (u_last - u_first) * PROJECT_SEED_REL
    step_max = (u_last - u_first) * PROJECT_STEP_MAX_REL
    u_tol = PROJECT_U_TOL_REL * (abs(u_first) + abs(u_last) + u_last - u_first)
    accept2 = accept_mm * accept_mm
    anchor = u_first
    anchor_at = 0  # the anchor's point (the first is the curve start)
    pace = 0.0  # the last anchored parameter step, at most step_max
    span = find_span(knots, degree, n_ctrl, u_first, degree)
    for i in range(targets.shape[0]):
        tx = targets[i, 0]
        ty = targets[i, 1]
        tz = targets[i, 2]
        span = find_span(knots, degree, n_ctrl, anchor, span)
        eval_d1(knots, cw, degree, anchor, span, basis, dbasis, left, right, p, d)
        speed = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        chord = math.sqrt((tx - p[0]) ** 2 + (ty - p[1]) ** 2 + (tz - p[2]) ** 2)
        ax = p[0]
        ay = p[1]
        az = p[2]
        origin = anchor
        step = seed
        if speed > 0.0:
            # near a stop back_mm / speed is no measure of arc: step_max bounds the way back
            origin = max(u_first, anchor - min(step_max, back_mm / speed))
            step = min(step_max, max(seed, (chord + back_mm) / speed))
        predicted = anchor + pace
        window_end = anchor + PROJECT_WINDOW_STEPS * pace
        u = u_last
        dist2 = math.inf
        chosen = False
        n_minima = 0
        other_lo = math.inf
        other_hi = -math.inf
        reach_mm = 2.0 * (chord + back_mm)
        walked_mm = 0.0
        lo = origin
        rising, d2_lo, span = _probe(knots, cw, degree, n_ctrl, lo, span, tx, ty, tz, basis,
                                     dbasis, left, right, p, d)
        wx = p[0]
        wy = p[1]
        wz = p[2]
        speed_lo = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        at_end = False
        knot_after = u_last
        corner_after = False
        while True:
            candidate = -1.0
            dc = math.inf
            if rising and n_minima == 0 and lo == origin:
                candidate = origin
                dc = d2_lo
            else:
                rising_lo = rising
                # two minima within one step would leave the first unseen; a step whose chord
                # or trapezoid arc is too long is halved ...
                arc_max = max(back_mm, PROJECT_STEP_ARC_SHARE * math.sqrt(d2_lo))
                # nor past a knot: where the curve is only C0 there (a corner) the distance
                # has a maximum at the knot, and a step across it from the rising distance
                # before to the rising distance after it would leave the minimum after unseen
                before = find_span(knots, degree, n_ctrl, lo, span)
                knot_after = knots[before + 1]
                # the motion rests on a corner, so a foot found before one stays before it
                corner_after = knot_after < u_last and knots[before + degree] == knot_after
                while True:
                    hi = min(lo + step, u_last, knot_after)
                    rising, d2_hi, span = _probe(knots, cw, degree, n_ctrl, hi, span, tx, ty,
                                                 tz, basis, dbasis, left, right, p, d)
                    speed_hi = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
                    chord_mm = math.sqrt((p[0] - wx) ** 2 + (p[1] - wy) ** 2 + (p[2] - wz) ** 2)
                    arc_mm = max(chord_mm, 0.5 * (hi - lo) * (speed_lo + speed_hi))
                    if arc_mm <= arc_max or step <= seed:
                        break
                    step *= 0.5
                speed_lo = speed_hi
                if hi > anchor:  # the reach is counted from the anchor
                    walked_mm += chord_mm
                wx = p[0]
                wy = p[1]
                wz = p[2]
                arriving = rising
                if corner_after and hi == knot_after:
                    # the step arrives at the corner along the leg before it, and the knot's
                    # own span is the leg after: where that leg turns back past the point, the
                    # distance falls along it while it grows along the leg the step came by, so
                    # a foot just before the corner is seen only by the leg before's C'
                    eval_d1(knots, cw, degree, hi, before, basis, dbasis, left, right, p, d)
                    arriving = rising or _growing(p, d, tx, ty, tz)
                if arriving and not rising_lo:
                    a = lo
                    b = hi
                    for _ in range(PROJECT_ITERATIONS):
                        mid = 0.5 * (a + b)
                        if b - a <= u_tol or not a < mid < b:
                            break
                        up, _d2, span = _probe(knots, cw, degree, n_ctrl, mid, span, tx, ty, tz,
                                               basis, dbasis, left, right, p, d)
                        if up:
                            b = mid
                        else:
                            a = mid
                    candidate = b
                    dc, span = _distance2(knots, cw, degree, n_ctrl, b, span, tx, ty, tz, basis,
                                          dbasis, left, right, p, d)
                elif not rising_lo and d2_hi > d2_lo:
                    # falling at lo, farther at hi, yet not rising there: hi is a stop (C' = 0)
                    # or g is lost in rounding, and the minimum between is found on the distance
                    candidate, dc, span = _golden(knots, cw, degree, n_ctrl, lo, hi, lo, d2_lo,
                                                  span, tx, ty, tz, basis, dbasis, left, right,
                                                  p, d)
                elif hi >= u_last and not rising:
                    candidate = u_last
                    dc = d2_hi
                lo = hi
                d2_lo = d2_hi
                at_end = hi >= u_last
                step = min(2.0 * step, step_max)
            if candidate >= 0.0 and dc <= accept2:
                other_lo = min(other_lo, candidate)
                other_hi = max(other_hi, candidate)
            if candidate >= 0.0 and not (chosen and lo > window_end and u <= anchor):
                n_minima += 1
                behind = False
                if dc <= accept2 and candidate < anchor:
                    # the motion's parameter never runs back, and rounding puts a foot at most
                    # back_mm of arc behind the anchor: a foot farther back (its chord to the
                    # anchor, shorter than the arc, is already longer) is the leg before a
                    # turn-back or a stop, within rounding of a point after it
                    back2, span = _distance2(knots, cw, degree, n_ctrl, candidate, span, ax,
                                             ay, az, basis, dbasis, left, right, p, d)
                    behind = back2 > back_mm * back_mm
                if dc <= accept2 and not behind:
                    if not chosen or abs(candidate - predicted) < abs(u - predicted):
                        u = candidate
                        dist2 = dc
                    chosen = True
                elif not chosen and dc < dist2:
                    u = candidate
                    dist2 = dc
            if corner_after and lo == knot_after:
                passed = knot_after < anchor
                if not passed:
                    corner2, span = _distance2(knots, cw, degree, n_ctrl, knot_after, span,
                                               targets[anchor_at, 0], targets[anchor_at, 1],
                                               targets[anchor_at, 2], basis, dbasis, left, right,
                                               p, d)
                    passed = corner2 <= accept2
                if passed:
                    # the motion has reached the corner (the anchor is past it, or was written
                    # on it): this point is past it too, and a foot before it is only the
                    # nearest so far (the leg before a sharp turn-back is within rounding of the
                    # points after), so the walk goes on as if it started here
                    chosen = False
                    n_minima = 0
                    walked_mm = 0.0
                elif chosen and knot_after > anchor:
                    break
            if at_end or (n_minima > 0 and lo >= window_end
                          and ((chosen and u > anchor) or walked_mm > reach_mm)):
                break
        if n_minima == 0:
            dist2, span = _distance2(knots, cw, degree, n_ctrl, u, span, tx, ty, tz, basis,
                                     dbasis, left, right, p, d)
        if accept2 < dist2 <= anchor_mm * anchor_mm:
            # near a sharp turn or a reversal the walk can settle on the wrong leg, leaving a
            # point on the curve measured off it: before calling it a deviation, the nearest
            # place within PROJECT_LOCAL_STEPS of the largest parameter step around the anchor
            # (evenly sampled, then refined by golden section)
            u, dist2, span = _scan(knots, cw, degree, n_ctrl,
                                   max(u_first, anchor - PROJECT_LOCAL_STEPS * step_max),
                                   min(u_last, anchor + PROJECT_LOCAL_STEPS * step_max), u,
                                   dist2, span, tx, ty, tz, basis, dbasis, left, right, p, d)
        if dist2 > anchor_mm * anchor_mm:
            u, dist2, span = _scan(knots, cw, degree, n_ctrl, origin, u_last, u, dist2, span, tx,
                                   ty, tz, basis, dbasis, left, right, p, d)
        u_out[i] = u
        dist_out[i] = math.sqrt(dist2)
        far = other_hi if other_hi - u >= u - other_lo else other_lo
        other_out[i] = far if math.isfinite(far) and far != u else math.nan
        if dist_out[i] <= anchor_mm:
            pace = min(step_max, max(0.0, u - anchor))
            # the motion's parameter never runs back: a foot behind the anchor is rounding (the
            # next search starts back_mm behind anyway) or the other leg of a turn-back within
            # rounding of the point, and following it would walk that leg backwards
            if u >= anchor:
                anchor = u
                anchor_at = i


def project_points(curve: NurbsCurve, targets: np.ndarray, back_mm: float, accept_mm: float,
                   anchor_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Foot parameters and distances of ordered points (N, 3) on the curve: two (N,) arrays.

    back_mm: how far behind the last anchored point a foot may be; accept_mm: a minimum this near
    counts as on the curve; anchor_mm: a point this near moves the search on."""
    u, dist, _ = project_points_and_others(curve, targets, back_mm, accept_mm, anchor_mm)
    return u, dist


def project_points_and_others(curve: NurbsCurve, targets: np.ndarray, back_mm: float,
                              accept_mm: float, anchor_mm: float
                              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`project_points`, and per point the other foot within accept_mm farthest from the one
    taken (NaN: none), found where a point does not move the walk on (`_project_kernel`)."""
    u = np.empty(len(targets))
    dist = np.empty(len(targets))
    other = np.full(len(targets), np.nan)
    targets = np.ascontiguousarray(targets, dtype=float)
    _project_kernel(curve.knots, curve.homogeneous, curve.degree, targets, curve.u_min,
                    curve.u_max, back_mm, accept_mm, anchor_mm, u, dist, other)
    off = np.flatnonzero(dist > accept_mm)
    if off.size:
        foot, nearest = nearest_on_curve(curve, targets[off])
        better = nearest < dist[off]
        u[off[better]] = foot[better]
        dist[off[better]] = nearest[better]
        other[off[better]] = np.nan
    return u, dist, other


def nearest_on_curve(curve: NurbsCurve, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Foot parameter and distance of each point (M, 3) on the whole curve, by sampling: a point
    the ordered walk measured off the curve is measured again against every part of it before it
    counts as a deviation (past a sharp turn or a reversal the walk can hold on to the wrong
    leg). The samples' nearest is refined once, evenly around it; the distance is never below the
    true one by more than the refined samples' sag."""
    u = np.linspace(curve.u_min, curve.u_max, NEAREST_SAMPLES)
    on_curve = curve.point(u)
    # every curve point is within the longest sample chord of a sample, so the foot lies next
    # to a sample no farther than the nearest sample plus that chord: near a corner or a
    # turn-back the nearest sample can be on the wrong leg
    reach = float(np.linalg.norm(np.diff(on_curve, axis=0), axis=1).max())
    breaks = curve.span_breaks
    foot = np.empty(len(targets))
    out = np.empty(len(targets))
    for i, target in enumerate(targets):
        far = np.sqrt(np.sum((on_curve - target) ** 2, axis=1))
        out[i] = np.inf
        for k in np.flatnonzero(far <= far.min() + reach):
            lo, hi = u[max(k - 1, 0)], u[min(k + 1, u.size - 1)]
            # each span on its own: at a corner knot the distance has a minimum on each leg, a
            # hair apart in u, and one zoom across the knot can settle on the farther one
            ends = np.concatenate(([lo], breaks[(breaks > lo) & (breaks < hi)], [hi]))
            for a, b in zip(ends[:-1], ends[1:]):
                for _ in range(NEAREST_LEVELS):
                    fine = np.linspace(a, b, NEAREST_SAMPLES)
                    d2 = np.sum((curve.point(fine) - target) ** 2, axis=1)
                    best = int(np.argmin(d2))
                    a, b = fine[max(best - 1, 0)], fine[min(best + 1, fine.size - 1)]
                if d2[best] < out[i] ** 2:
                    foot[i], out[i] = fine[best], np.sqrt(d2[best])
    return foot, out


BEHIND_REACH = 4.0  # a foot behind the walk is looked for again this many times as far ahead


def feet_ahead_of_behind(curve: NurbsCurve, targets: np.ndarray, u: np.ndarray,
                         other: np.ndarray, accept_mm: float) -> np.ndarray:
    """`other` (N,) with, for each point whose foot lies behind a foot taken before it (the
    motion's parameter never runs back: the point is past a turn-back, within rounding of the
    leg in), the nearest foot within accept_mm at or past the farthest foot before it, when it
    has none yet (fuzz seed 44: a point written on the same position as one before the
    turn-back got that point's foot and no other, and its arc was off by three roundings).
    Sought on BEHIND_REACH times the way back past that foot by `_scan`."""
    out = other.copy()
    ahead = np.maximum.accumulate(u)
    behind = np.flatnonzero((u[1:] < ahead[:-1]) & np.isnan(other[1:])) + 1
    degree = curve.degree
    work = [np.empty(degree + 1) for _ in range(4)] + [np.empty(3), np.empty(3)]
    for q in behind:
        lo = ahead[q - 1]
        hi = min(curve.u_max, lo + BEHIND_REACH * (lo - u[q]))
        if not hi > lo:
            continue
        tx, ty, tz = (float(c) for c in targets[q])
        foot, dist2, _ = _scan(curve.knots, curve.homogeneous, degree, curve.homogeneous.shape[0],
                               lo, hi, lo, math.inf, degree, tx, ty, tz, *work)
        if dist2 <= accept_mm**2:
            out[q] = foot
    return out
