"""Single-parameter NURBS evaluation for the stepping loop, in numba's subset.

`eval_d1` returns C(u) and C'(u) in preallocated arrays; the basis functions and their first
derivatives come from Piegl & Tiller A2.2 carried to degree p-1, differentiated, then raised to
degree p. Outside [u_min, u_max] the end spans' polynomials extrapolate, which keeps the end-landing
search of `interpolate` continuous.
"""

from __future__ import annotations

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
def _basis_ders(knots, p, span, u, n, ndu, a, left, right, ders):
    """Piegl & Tiller A2.3: ders[k, j] = k-th derivative of N_{span-p+j, p}(u), k <= n <= p."""
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
        for k in range(1, n + 1):
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
    for k in range(1, n + 1):
        for j in range(p + 1):
            ders[k, j] *= factor
        factor *= p - k


@jit
def eval_many(knots, cw, degree, u, order, out):
    """C and its derivatives up to `order` (0, 1 or 2) at every u: out (order+1, M, 3).

    Parameters in increasing order are fastest (the span of the previous one is tried first);
    outside [u_min, u_max] the end spans extrapolate. Derivatives of order > degree are 0.
    """
    p = degree
    n_ctrl = cw.shape[0]
    n = min(order, p)
    ndu = np.empty((p + 1, p + 1))
    a = np.empty((2, p + 1))
    left = np.empty(p + 1)
    right = np.empty(p + 1)
    ders = np.zeros((3, p + 1))
    h = np.empty((3, 4))
    span = p
    for q in range(u.size):
        uq = u[q]
        span = find_span(knots, p, n_ctrl, uq, span)
        _basis_ders(knots, p, span, uq, n, ndu, a, left, right, ders)
        for k in range(3):
            for c in range(4):
                h[k, c] = 0.0
        for j in range(p + 1):
            row = span - p + j
            for k in range(n + 1):
                b = ders[k, j]
                for c in range(4):
                    h[k, c] += b * cw[row, c]
        w0 = h[0, 3]
        for c in range(3):
            c0 = h[0, c] / w0
            out[0, q, c] = c0
            if order >= 1:
                c1 = (h[1, c] - h[1, 3] * c0) / w0
                out[1, q, c] = c1
                if order >= 2:
                    out[2, q, c] = (h[2, c] - 2.0 * h[1, 3] * c1 - h[2, 3] * c0) / w0
