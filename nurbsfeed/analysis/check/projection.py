"""Written points mapped back to their curve: foot parameters and distances, in order."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.kernel import eval_d1, find_span
from nurbsfeed.jit import jit

PROJECT_ITERATIONS = 100
PROJECT_SEED_REL = 1e-9  # first bracket step (of the knot range) where |C'| = 0
# The first bracket step is at most this share of the knot range: where |C'| is nearly 0 (a
# repeated control point) chord / |C'| would jump to the far end and bracket the wrong root.
PROJECT_STEP_MAX_REL = 1e-3
# A point the forward search leaves far from the curve is looked for again over the rest of the
# curve: the best of this many evenly spaced parameters, refined by golden section.
PROJECT_SCAN_SAMPLES = 4096
GOLDEN = 0.5 * (math.sqrt(5.0) - 1.0)


@jit
def _distance2(knots, cw, degree, n_ctrl, u, span, tx, ty, tz, basis, dbasis, left, right, p, d):
    span = find_span(knots, degree, n_ctrl, u, span)
    eval_d1(knots, cw, degree, u, span, basis, dbasis, left, right, p, d)
    return (tx - p[0]) ** 2 + (ty - p[1]) ** 2 + (tz - p[2]) ** 2, span


@jit
def _project_kernel(knots, cw, degree, targets, u_first, u_last, back_mm, anchor_mm, u_out,
                    dist_out):
    """Foot parameters of targets (N, 3), in order: u_out (N,), distances dist_out (N,).

    Each search starts back_mm of arc behind the last anchored point (rounding may put a point
    slightly behind the one before) and brackets g(u) = C'(u).(C(u) - P) < 0 <= g by doubling
    steps; a target beyond the end projects to u_last. A point left farther than anchor_mm is
    looked for again on a grid over the rest of the curve (a dropped stretch of moves puts the
    next point far ahead). A point within anchor_mm becomes the anchor.
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
    anchor = u_first
    span = find_span(knots, degree, n_ctrl, u_first, degree)
    for i in range(targets.shape[0]):
        tx = targets[i, 0]
        ty = targets[i, 1]
        tz = targets[i, 2]
        span = find_span(knots, degree, n_ctrl, anchor, span)
        eval_d1(knots, cw, degree, anchor, span, basis, dbasis, left, right, p, d)
        speed = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        chord = math.sqrt((tx - p[0]) ** 2 + (ty - p[1]) ** 2 + (tz - p[2]) ** 2)
        origin = anchor
        step = seed
        if speed > 0.0:
            origin = max(u_first, anchor - back_mm / speed)
            step = min(step_max, max(seed, (chord + back_mm) / speed))
        lo = origin
        hi = origin
        found = False
        while True:
            hi = min(origin + step, u_last)
            span = find_span(knots, degree, n_ctrl, hi, span)
            eval_d1(knots, cw, degree, hi, span, basis, dbasis, left, right, p, d)
            g = d[0] * (p[0] - tx) + d[1] * (p[1] - ty) + d[2] * (p[2] - tz)
            if g >= 0.0:
                found = True
                break
            lo = hi
            if hi >= u_last:
                break
            step *= 2.0
        u = u_last
        if found:
            u = hi
            for _ in range(PROJECT_ITERATIONS):
                span = find_span(knots, degree, n_ctrl, u, span)
                eval_d1(knots, cw, degree, u, span, basis, dbasis, left, right, p, d)
                g = d[0] * (p[0] - tx) + d[1] * (p[1] - ty) + d[2] * (p[2] - tz)
                if g > 0.0:
                    hi = u
                elif g < 0.0:
                    lo = u
                else:
                    break
                gp = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]  # Gauss-Newton: |C'|^2
                nu = u - g / gp if gp > 0.0 else 0.5 * (lo + hi)
                if not lo < nu < hi:
                    nu = 0.5 * (lo + hi)
                if abs(nu - u) <= 1e-16 * (abs(u) + u_last - u_first) or hi - lo <= 0.0:
                    u = nu
                    break
                u = nu
        dist2, span = _distance2(knots, cw, degree, n_ctrl, u, span, tx, ty, tz, basis, dbasis,
                                 left, right, p, d)
        if dist2 > anchor_mm * anchor_mm:
            width = (u_last - origin) / (PROJECT_SCAN_SAMPLES - 1)
            best = -1
            for q in range(PROJECT_SCAN_SAMPLES):
                dq, span = _distance2(knots, cw, degree, n_ctrl, origin + q * width, span, tx,
                                      ty, tz, basis, dbasis, left, right, p, d)
                if dq < dist2:
                    dist2 = dq
                    best = q
            if best >= 0:
                a = max(origin, origin + (best - 1) * width)
                b = min(u_last, origin + (best + 1) * width)
                u = origin + best * width
                for _ in range(PROJECT_ITERATIONS):
                    x1 = b - GOLDEN * (b - a)
                    x2 = a + GOLDEN * (b - a)
                    f1, span = _distance2(knots, cw, degree, n_ctrl, x1, span, tx, ty, tz, basis,
                                          dbasis, left, right, p, d)
                    f2, span = _distance2(knots, cw, degree, n_ctrl, x2, span, tx, ty, tz, basis,
                                          dbasis, left, right, p, d)
                    if f1 <= f2:
                        b = x2
                    else:
                        a = x1
                    if min(f1, f2) < dist2:
                        dist2 = min(f1, f2)
                        u = x1 if f1 <= f2 else x2
        u_out[i] = u
        dist_out[i] = math.sqrt(dist2)
        if dist_out[i] <= anchor_mm:
            anchor = u


def project_points(curve: NurbsCurve, targets: np.ndarray, back_mm: float,
                   anchor_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Foot parameters and distances of ordered points (N, 3) on the curve: two (N,) arrays."""
    u = np.empty(len(targets))
    dist = np.empty(len(targets))
    _project_kernel(curve.knots, curve.homogeneous, curve.degree,
                    np.ascontiguousarray(targets, dtype=float), curve.u_min, curve.u_max,
                    back_mm, anchor_mm, u, dist)
    return u, dist
