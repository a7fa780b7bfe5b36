"""Single-parameter NURBS evaluation in numba's subset: the span polynomials and their evaluation.

On each knot span the homogeneous curve A(u) = sum N_i,p(u) w_i P_i, W(u) = sum N_i,p(u) w_i is one
polynomial of degree p, so it is stored once as its Taylor expansions at both ends of the span:

    coef[i, 0, k, :] = (A, W)^(k)(knots[i]) / k!     coef[i, 1, k, :] = (A, W)^(k)(knots[i+1]) / k!

(k = 0..p, `span_polynomials`; the derivatives from Piegl & Tiller A2.3). An
evaluation takes the expansion at the nearer end and runs Horner's rule in t = u - knot for the
value and its derivatives, then the quotient rule (A4.2): C = A/W, C' = (A' - W'C)/W,
C'' = (A'' - 2W'C' - W''C)/W (`point_d1`, `point_d2`). That costs a third of evaluating the basis
functions at every parameter, which the stepping loop and the planning grid do millions of times.
Two expansions, not one: |t| stays below half the span, and at every knot the value is the one
A2.3 gives there, so a derivative that vanishes at a knot (a repeated control point, design §3a)
comes out exactly 0, not as rounding noise. Outside [u_min, u_max] the end spans' polynomials
extrapolate, which keeps the end-landing search of `interpolate.landing` continuous.

`eval_d1` evaluates C and C' from the basis functions directly (A2.2 carried to degree p-1,
differentiated, then raised to degree p): the independent route that `analysis.check` verifies a
converted program with.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit


@jit
def find_span(knots: np.ndarray, degree: int, n_ctrl: int, u: float, hint: int) -> int:
    """Index i with knots[i] <= u < knots[i+1], clamped to [degree, n_ctrl-1]; `hint` first."""
    last = n_ctrl - 1
    if degree <= hint <= last and knots[hint] <= u < knots[hint + 1]:
        return hint
    if u >= knots[last]:
        return last
    if u < knots[degree + 1]:
        return degree
    low = degree + 1
    high = last
    # invariant: knots[low] <= u < knots[high]
    while high - low > 1:
        mid = (low + high) // 2
        if u < knots[mid]:
            high = mid
        else:
            low = mid
    return low


@jit
def eval_d1(knots: np.ndarray, cw: np.ndarray, degree: int, u: float, span: int,
            basis: np.ndarray, dbasis: np.ndarray, left: np.ndarray, right: np.ndarray,
            p_out: np.ndarray, d_out: np.ndarray) -> None:
    """C(u) -> p_out (3,), C'(u) -> d_out (3,). cw: (n+1, 4) homogeneous control points.

    basis, dbasis, left, right: work arrays of length degree+1.
    """
    p = degree
    basis[0] = 1.0
    for j in range(1, p):
        left[j] = u - knots[span + 1 - j]
        right[j] = knots[span + j] - u
        saved = 0.0
        for r in range(j):
            temp = basis[r] / (right[r + 1] + left[j - r])
            basis[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        basis[j] = saved
    # basis[0..p-1] now hold the degree p-1 functions N_{span-p+1+r, p-1}.
    for r in range(p + 1):
        i = span - p + r
        a = basis[r - 1] / (knots[i + p] - knots[i]) if r >= 1 else 0.0
        b = basis[r] / (knots[i + p + 1] - knots[i + 1]) if r <= p - 1 else 0.0
        dbasis[r] = p * (a - b)
    left[p] = u - knots[span + 1 - p]
    right[p] = knots[span + p] - u
    saved = 0.0
    for r in range(p):
        temp = basis[r] / (right[r + 1] + left[p - r])
        basis[r] = saved + right[r + 1] * temp
        saved = left[p - r] * temp
    basis[p] = saved

    ax = 0.0
    ay = 0.0
    az = 0.0
    aw = 0.0
    dx = 0.0
    dy = 0.0
    dz = 0.0
    dw = 0.0
    for r in range(p + 1):
        row = span - p + r
        n0 = basis[r]
        n1 = dbasis[r]
        ax += n0 * cw[row, 0]
        ay += n0 * cw[row, 1]
        az += n0 * cw[row, 2]
        aw += n0 * cw[row, 3]
        dx += n1 * cw[row, 0]
        dy += n1 * cw[row, 1]
        dz += n1 * cw[row, 2]
        dw += n1 * cw[row, 3]
    cx = ax / aw
    cy = ay / aw
    cz = az / aw
    p_out[0] = cx
    p_out[1] = cy
    p_out[2] = cz
    d_out[0] = (dx - dw * cx) / aw
    d_out[1] = (dy - dw * cy) / aw
    d_out[2] = (dz - dw * cz) / aw


@jit
def span_polynomials(knots, cw, degree):
    """Taylor coefficients of (A, W) at both ends of every non-empty span: (n+1, 2, p+1, 4).

    Row i belongs to the span knots[i] <= u < knots[i+1] (the index `find_span` returns); rows
    of empty spans and rows below `degree` stay zero and are never read. At each end u of a
    span, Piegl & Tiller A2.3 gives ders[k, j], the k-th derivative of N_{span-p+j, p}(u) (one
    loop, not a helper kernel of its own: it runs once per curve, and a second kernel costs a
    first conversion its compile time).
    """
    p = degree
    n_ctrl = cw.shape[0]
    coef = np.empty((n_ctrl, 2, p + 1, 4))
    # zeros by a loop: np.zeros would compile numba's own implementation for a 4-D shape
    for i in range(n_ctrl):
        for side in range(2):
            for k in range(p + 1):
                for c in range(4):
                    coef[i, side, k, c] = 0.0
    ndu = np.empty((p + 1, p + 1))
    a = np.empty((2, p + 1))
    left = np.empty(p + 1)
    right = np.empty(p + 1)
    ders = np.empty((p + 1, p + 1))  # A2.3 writes every entry
    for span in range(p, n_ctrl):
        if knots[span + 1] <= knots[span]:
            continue
        for side in range(2):
            u = knots[span + side]
            ndu[0, 0] = 1.0
            for j in range(1, p + 1):
                left[j] = u - knots[span + 1 - j]
                right[j] = knots[span + j] - u
                saved = 0.0
                for r in range(j):
                    ndu[j, r] = right[r + 1] + left[j - r]
                    temp = ndu[r, j - 1] / ndu[j, r]
                    ndu[r, j] = saved + right[r + 1] * temp
                    saved = left[j - r] * temp
                ndu[j, j] = saved
            for j in range(p + 1):
                ders[0, j] = ndu[j, p]
            for r in range(p + 1):
                s1 = 0
                s2 = 1
                a[0, 0] = 1.0
                for k in range(1, p + 1):
                    d = 0.0
                    rk = r - k
                    pk = p - k
                    if r >= k:
                        a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                        d = a[s2, 0] * ndu[rk, pk]
                    j1 = 1 if rk >= -1 else -rk
                    j2 = k - 1 if r - 1 <= pk else p - r
                    for j in range(j1, j2 + 1):
                        a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                        d += a[s2, j] * ndu[rk + j, pk]
                    if r <= pk:
                        a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                        d += a[s2, k] * ndu[r, pk]
                    ders[k, r] = d
                    s1, s2 = s2, s1
            factor = p
            for k in range(1, p + 1):
                for j in range(p + 1):
                    ders[k, j] *= factor
                factor *= p - k
            factorial = 1.0
            for k in range(p + 1):
                if k > 0:
                    factorial *= k
                for j in range(p + 1):
                    row = span - p + j
                    b = ders[k, j] / factorial
                    for c in range(4):
                        coef[span, side, k, c] += b * cw[row, c]
    return coef


@jit
def _expansion(knots, span, u):
    """Which end of the span to expand at (0 start, 1 end), and t = u - that knot."""
    if u - knots[span] <= knots[span + 1] - u:
        return 0, u - knots[span]
    return 1, u - knots[span + 1]


@jit
def point_d1(knots, coef, degree, span, u):
    """C(u) and C'(u) on `span` from its polynomial: (cx, cy, cz, dx, dy, dz).

    `point_d2` without the second derivative, for the stepping loop: numba does not inline one
    compiled function into another, and taking C'' along costs the loop 13 %.
    """
    side, t = _expansion(knots, span, u)
    ax = coef[span, side, degree, 0]
    ay = coef[span, side, degree, 1]
    az = coef[span, side, degree, 2]
    aw = coef[span, side, degree, 3]
    dx = 0.0
    dy = 0.0
    dz = 0.0
    dw = 0.0
    for k in range(degree - 1, -1, -1):
        dx = dx * t + ax
        dy = dy * t + ay
        dz = dz * t + az
        dw = dw * t + aw
        ax = ax * t + coef[span, side, k, 0]
        ay = ay * t + coef[span, side, k, 1]
        az = az * t + coef[span, side, k, 2]
        aw = aw * t + coef[span, side, k, 3]
    # C by division (a rounding error A and W share cancels: C(u_min) is P_0 exactly); C' with
    # the reciprocal, computed alongside, so that C' waits for one division, not two in a row
    inv_w = 1.0 / aw
    cx = ax / aw
    cy = ay / aw
    cz = az / aw
    return cx, cy, cz, (dx - dw * cx) * inv_w, (dy - dw * cy) * inv_w, (dz - dw * cz) * inv_w


@jit
def point_d2(knots, coef, degree, span, u):
    """C(u), C'(u) and C''(u) on `span` from its polynomial: nine floats, C first."""
    side, t = _expansion(knots, span, u)
    ax = coef[span, side, degree, 0]
    ay = coef[span, side, degree, 1]
    az = coef[span, side, degree, 2]
    aw = coef[span, side, degree, 3]
    dx = 0.0
    dy = 0.0
    dz = 0.0
    dw = 0.0
    ex = 0.0
    ey = 0.0
    ez = 0.0
    ew = 0.0
    for k in range(degree - 1, -1, -1):
        ex = ex * t + dx
        ey = ey * t + dy
        ez = ez * t + dz
        ew = ew * t + dw
        dx = dx * t + ax
        dy = dy * t + ay
        dz = dz * t + az
        dw = dw * t + aw
        ax = ax * t + coef[span, side, k, 0]
        ay = ay * t + coef[span, side, k, 1]
        az = az * t + coef[span, side, k, 2]
        aw = aw * t + coef[span, side, k, 3]
    # Horner leaves A' in d and A''/2 in e
    inv_w = 1.0 / aw  # as in point_d1
    cx = ax / aw
    cy = ay / aw
    cz = az / aw
    c1x = (dx - dw * cx) * inv_w
    c1y = (dy - dw * cy) * inv_w
    c1z = (dz - dw * cz) * inv_w
    c2x = (2.0 * ex - 2.0 * dw * c1x - 2.0 * ew * cx) * inv_w
    c2y = (2.0 * ey - 2.0 * dw * c1y - 2.0 * ew * cy) * inv_w
    c2z = (2.0 * ez - 2.0 * dw * c1z - 2.0 * ew * cz) * inv_w
    return cx, cy, cz, c1x, c1y, c1z, c2x, c2y, c2z


@jit
def point_d3(knots, coef, degree, span, u):
    """C(u) and its first three derivatives on `span`: twelve floats, C first.

    `point_d2` carried one order further, for the path model's dkappa/ds and torsion:
    C3 = (A3 - 3 W1 C2 - 3 W2 C1 - W3 C) / W, the k in Ak and Wk the order of the derivative.
    A copy, neither calling `point_d2` nor called by it, for `point_d1`'s reason: the grid's
    loops call `point_d2` millions of times and would pay for C3 there."""
    side, t = _expansion(knots, span, u)
    ax = coef[span, side, degree, 0]
    ay = coef[span, side, degree, 1]
    az = coef[span, side, degree, 2]
    aw = coef[span, side, degree, 3]
    dx = dy = dz = dw = 0.0
    ex = ey = ez = ew = 0.0
    fx = fy = fz = fw = 0.0
    for k in range(degree - 1, -1, -1):
        fx = fx * t + ex
        fy = fy * t + ey
        fz = fz * t + ez
        fw = fw * t + ew
        ex = ex * t + dx
        ey = ey * t + dy
        ez = ez * t + dz
        ew = ew * t + dw
        dx = dx * t + ax
        dy = dy * t + ay
        dz = dz * t + az
        dw = dw * t + aw
        ax = ax * t + coef[span, side, k, 0]
        ay = ay * t + coef[span, side, k, 1]
        az = az * t + coef[span, side, k, 2]
        aw = aw * t + coef[span, side, k, 3]
    # Horner leaves A1 in d, A2 / 2 in e and A3 / 6 in f
    inv_w = 1.0 / aw
    cx = ax / aw
    cy = ay / aw
    cz = az / aw
    c1x = (dx - dw * cx) * inv_w
    c1y = (dy - dw * cy) * inv_w
    c1z = (dz - dw * cz) * inv_w
    w2 = 2.0 * ew
    c2x = (2.0 * ex - 2.0 * dw * c1x - w2 * cx) * inv_w
    c2y = (2.0 * ey - 2.0 * dw * c1y - w2 * cy) * inv_w
    c2z = (2.0 * ez - 2.0 * dw * c1z - w2 * cz) * inv_w
    w3 = 6.0 * fw
    c3x = (6.0 * fx - 3.0 * dw * c2x - 3.0 * w2 * c1x - w3 * cx) * inv_w
    c3y = (6.0 * fy - 3.0 * dw * c2y - 3.0 * w2 * c1y - w3 * cy) * inv_w
    c3z = (6.0 * fz - 3.0 * dw * c2z - 3.0 * w2 * c1z - w3 * cz) * inv_w
    return cx, cy, cz, c1x, c1y, c1z, c2x, c2y, c2z, c3x, c3y, c3z


@jit
def curvature(x1, y1, z1, x2, y2, z2):
    """kappa = |C' x C''| / |C'|^3 (NaN where C' = 0) and |C'|, from C' and C''.

    Scalars only: loops call find_span and point_d2 themselves and pass the derivatives here,
    since a compiled helper that takes the curve's arrays costs a call per evaluation.
    """
    cross = math.sqrt((y1 * z2 - z1 * y2) ** 2 + (z1 * x2 - x1 * z2) ** 2
                      + (x1 * y2 - y1 * x2) ** 2)
    speed = math.sqrt(x1 * x1 + y1 * y1 + z1 * z1)
    cube = speed * speed * speed  # underflows to 0 below ~1e-103 even where speed > 0
    kappa = cross / cube if cube > 0.0 else math.nan
    return kappa, speed


@jit
def eval_many(knots, coef, degree, u, order, out):
    """C and its derivatives up to `order` (0 to 3) at every u: out (order+1, M, 3).

    Parameters in increasing order are fastest (the span of the previous one is tried first);
    outside [u_min, u_max] the end spans extrapolate. Derivatives of order > degree are 0.
    Every order goes through `point_d3` (its C, C' and C'' are `point_d2`'s to the bit): one
    path to compile, at a fifth more arithmetic for the lower orders.
    """
    n_ctrl = coef.shape[0]
    span = degree
    for q in range(u.size):
        span = find_span(knots, degree, n_ctrl, u[q], span)
        d = point_d3(knots, coef, degree, span, u[q])
        for k in range(order + 1):
            out[k, q, 0] = d[3 * k]
            out[k, q, 1] = d[3 * k + 1]
            out[k, q, 2] = d[3 * k + 2]


@jit
def eval3_on_spans(knots, coef, degree, u, spans, out):
    """C and its first three derivatives at every u, each on the span given for it (spans (M,):
    a knot's left limit is the span before it, which `eval_many`'s search never picks):
    out (4, M, 3). For `analysis.bound`, whose cells end on knots from the left."""
    for q in range(u.size):
        d = point_d3(knots, coef, degree, spans[q], u[q])
        out[0, q, 0], out[0, q, 1], out[0, q, 2] = d[0], d[1], d[2]
        out[1, q, 0], out[1, q, 1], out[1, q, 2] = d[3], d[4], d[5]
        out[2, q, 0], out[2, q, 1], out[2, q, 2] = d[6], d[7], d[8]
        out[3, q, 0], out[3, q, 1], out[3, q, 2] = d[9], d[10], d[11]
