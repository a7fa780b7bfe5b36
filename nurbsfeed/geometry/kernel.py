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
