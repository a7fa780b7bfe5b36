"""The path model's limits on one cell as rows over its start state (design §2d).

A cell runs from knot j to knot j + 1, h long; on it the tangential acceleration a is linear in
arc length and b = v^2 quadratic: with u = da/ds (constant on the cell),

    b(x) = b + 2 a x + u x^2,    a(x) = a + u x,    jerk along the path = sqrt(b) (u - kappa^2 b)

so at the cell's start (x = 0), middle (h/2) and end (h) every quantity is b, a and u combined
linearly, and every limit a row

    cb b + ca a + cu u <= d

over the cell's start state (b, a) and its u. The jerks are sqrt(b) |L(b, a, u)| <= J with L
linear (along the path L = u - kappa^2 b, per axis u T_x + 3 a K_x + b K_s,x, across the path
the vector 3 a K + b (K_s + kappa^2 T)); J / sqrt(b) is convex in b, so its tangent at a
linearisation point b0 lies below it and a row |L| <= tangent keeps the true limit for every b
(a convex-concave step: the rows are exact at b0, and the next pass takes them at the motion
the last one found). A knot where kappa N jumps by D adds b |D| / T, what positions one period
apart read, to the normal jerk and each axis's. At a knot a floor b >= f can join
(planning.reach_schedule: where the motion must not dip).
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.basis import G_CAP, G_D, G_K, G_KAPPA, G_KS, G_T

NORMAL_SIDES = 16  # the polygon inscribed in the circle |jerk across T| <= J_n (3-D)
PLANAR_REL = 1e-9  # K_s's part along B below this share of |K_s|: none
# an axis's share of T, K or K_s below this is rounding and counts as 0 in its rows (K's and
# K_s's shares are of their size but at least of 1 /mm and 1 /mm^2), and an axis with none
# left has no rows: on a straight piece along one axis the others' T is rounding (1e-15), and
# a jerk row with that for its u coefficient bounds a1 by terms of 1e17 whose rounding alone is
# 100 mm/s^2 (reach_bounds.split_rows divides by it): a line after a bend, and a straight leg
# after a cusp, found no motion. What such a share adds is below 1e-12 (u + 3 a + b): nothing.
ZERO_REL = 1e-12
B_FLOOR = 1e-12  # the least linearisation point
# per point at most: cap, b >= 0, 2 tangential accelerations, 6 axis accelerations, the normal
# jerk's half polygon, 2 tangential and 6 axis jerks; per cell three points, the middle control
# point's two bounds and two floors
ROWS_PER_POINT = 2 + 2 + 6 + NORMAL_SIDES // 2 + 1 + 2 + 6
ROWS_PER_CELL = 3 * ROWS_PER_POINT + 4


@jit
def _share(value, size):
    """value, or 0 where it is below ZERO_REL of size."""
    return value if abs(value) > ZERO_REL * size else 0.0


@jit
def jerk_tangent(limit, jump, b0):
    """(slope, bound) of a jerk row |L| + slope b <= bound: the tangent at b0 of the limit
    |L| <= J / sqrt(b) - sqrt(b) jump (a jump of kappa N read over one period adds b |D| / T,
    jump = |D| / T). Both sides are convex in b, so the tangent lies below the limit. Where
    kappa N jumps the tangent is taken at b0 or at the jump's own limit J / jump, the lower:
    beyond it the tangent would cross 0 and leave no b >= 0."""
    if jump > 0.0:
        b0 = min(b0, limit / jump)
    b0 = max(b0, B_FLOOR)
    root = math.sqrt(b0)
    return 0.5 * limit / (b0 * root) + 0.5 * jump / root, 1.5 * limit / root - 0.5 * jump * root


@jit
def _put(rows, r, alpha, beta, gamma, d, xb, xu, ya):
    """Row r: alpha b_p + beta a_p + gamma u <= d at a point whose state is b_p = b + xb a +
    xu u, a_p = a + ya u, written over the cell's start state."""
    rows[r, 0] = alpha
    rows[r, 1] = alpha * xb + beta
    rows[r, 2] = alpha * xu + beta * ya + gamma
    rows[r, 3] = d
    return r + 1


@jit
def point_rows(g, b0, lim, with_jerk, xb, xu, ya, rows, r):
    """The rows of one point with geometry g (G_SIZE,) linearised at b0, from row r on; lim =
    (A_t, J_t, J_n, T, A_x, A_y, A_z, J_x, J_y, J_z). with_jerk: also the jerks along the
    path and per axis (they need the cell's u). Returns the next free row."""
    acc_t, jerk_t, jerk_n, period = lim[0], lim[1], lim[2], lim[3]
    k = g[G_KAPPA]
    r = _put(rows, r, 1.0, 0.0, 0.0, g[G_CAP], xb, xu, ya)
    r = _put(rows, r, -1.0, 0.0, 0.0, 0.0, xb, xu, ya)
    r = _put(rows, r, 0.0, 1.0, 0.0, acc_t, xb, xu, ya)
    r = _put(rows, r, 0.0, -1.0, 0.0, acc_t, xb, xu, ya)
    k_size = max(abs(k), 1.0)
    ks_size = math.sqrt(g[G_KS] ** 2 + g[G_KS + 1] ** 2 + g[G_KS + 2] ** 2)
    for x in range(3):
        acc_x = lim[4 + x]
        tx, kx = _share(g[G_T + x], 1.0), _share(g[G_K + x], k_size)
        if acc_x == np.inf or (tx == 0.0 and kx == 0.0):
            continue
        r = _put(rows, r, kx, tx, 0.0, acc_x, xb, xu, ya)
        r = _put(rows, r, -kx, -tx, 0.0, acc_x, xb, xu, ya)
    # across the path: |3 a K + b (K_s + kappa^2 T)| sqrt(b) + b |D| / T <= J_n, the vector
    # in the plane of N and B as an inscribed polygon; its B part is b kb >= 0, so only the
    # sides facing +B can bind
    ksx = g[G_KS] + k * k * g[G_T]
    ksy = g[G_KS + 1] + k * k * g[G_T + 1]
    ksz = g[G_KS + 2] + k * k * g[G_T + 2]
    if k > 0.0:
        nx, ny, nz = g[G_K] / k, g[G_K + 1] / k, g[G_K + 2] / k
    else:
        norm = math.sqrt(ksx * ksx + ksy * ksy + ksz * ksz)
        if norm > 0.0:
            nx, ny, nz = ksx / norm, ksy / norm, ksz / norm
        else:
            nx, ny, nz = 0.0, 0.0, 0.0
    kn = ksx * nx + ksy * ny + ksz * nz
    bx, by, bz = ksx - kn * nx, ksy - kn * ny, ksz - kn * nz
    kb = math.sqrt(bx * bx + by * by + bz * bz)
    if kb <= PLANAR_REL * ks_size:
        kb = 0.0
    jump = math.sqrt(g[G_D] ** 2 + g[G_D + 1] ** 2 + g[G_D + 2] ** 2) / period
    slope, bound = jerk_tangent(jerk_n, jump, b0)
    if kb > 0.0:
        shrink = math.cos(math.pi / NORMAL_SIDES)
        for side in range(NORMAL_SIDES // 2 + 1):
            theta = 2.0 * math.pi * side / NORMAL_SIDES
            cn, cb = math.cos(theta), math.sin(theta)
            r = _put(rows, r, cn * kn + cb * kb + shrink * slope, 3.0 * cn * k, 0.0,
                     shrink * bound, xb, xu, ya)
    elif k > 0.0 or kn != 0.0:
        r = _put(rows, r, kn + slope, 3.0 * k, 0.0, bound, xb, xu, ya)
        r = _put(rows, r, -kn + slope, -3.0 * k, 0.0, bound, xb, xu, ya)
    elif jump > 0.0:  # a straight piece: nothing across the path but the jump, b |D| / T
        r = _put(rows, r, 1.0, 0.0, 0.0, jerk_n / jump, xb, xu, ya)
    if not with_jerk:
        return r
    slope, bound = jerk_tangent(jerk_t, 0.0, b0)
    ks_scale = max(ks_size, 1.0)
    r = _put(rows, r, -k * k + slope, 0.0, 1.0, bound, xb, xu, ya)
    r = _put(rows, r, k * k + slope, 0.0, -1.0, bound, xb, xu, ya)
    for x in range(3):
        jerk_x = lim[7 + x]
        tx, kx = _share(g[G_T + x], 1.0), _share(g[G_K + x], k_size)
        ksx_ = _share(g[G_KS + x], ks_scale)
        if jerk_x == np.inf or (tx == 0.0 and kx == 0.0 and ksx_ == 0.0):
            continue
        slope, bound = jerk_tangent(jerk_x, abs(g[G_D + x]) / period, b0)
        r = _put(rows, r, ksx_ + slope, 3.0 * kx, tx, bound, xb, xu, ya)
        r = _put(rows, r, -ksx_ + slope, -3.0 * kx, -tx, bound, xb, xu, ya)
    return r


@jit
def cell_rows(g0, gm, g1, h, b0, bm, b1, floor0, floor1, lim, rows):
    """Every row of one cell (h long; geometry g0, gm, g1 at its start, middle and end,
    linearised at b0, bm, b1 there) over its start state (b, a) and u, into rows
    (ROWS_PER_CELL, 4); floors b >= floor0 at its start and b >= floor1 at its end (0: none).
    Returns the row count."""
    r = point_rows(g0, b0, lim, True, 0.0, 0.0, 0.0, rows, np.int64(0))  # not a literal 0
    r = point_rows(gm, bm, lim, True, h, 0.25 * h * h, 0.5 * h, rows, r)
    r = point_rows(g1, b1, lim, True, 2.0 * h, h * h, h, rows, r)
    # the quadratic's middle control point b + h a under the lowest of the three caps: with
    # its ends under theirs, b stays under the caps all along the cell, not just at the three
    # points (a cell ending at the cap, its middle just below, bulges over it in between)
    r = _put(rows, r, 1.0, 0.0, 0.0, min(g0[G_CAP], gm[G_CAP], g1[G_CAP]), h, 0.0, 0.0)
    # ... and at least 0: b >= 0 at the three points leaves room for a dive to nearly 0 and
    # back between them (v a hundredth of its ends'), which no period-long law step follows
    r = _put(rows, r, -1.0, 0.0, 0.0, 0.0, h, 0.0, 0.0)
    if floor0 > 0.0:
        r = _put(rows, r, -1.0, 0.0, 0.0, -floor0, 0.0, 0.0, 0.0)
    if floor1 > 0.0:
        r = _put(rows, r, -1.0, 0.0, 0.0, -floor1, 2.0 * h, h * h, h)
    return r


def limits_vector(lim) -> np.ndarray:
    """The limits point_rows reads, as one array: (A_t, J_t, J_n, T, A_xyz, J_xyz)."""
    return np.array([lim.acc_mm_s2, lim.jerk_mm_s3, lim.normal_jerk_mm_s3, lim.period_s,
                     *lim.axis_acc_mm_s2, *lim.axis_jerk_mm_s3], dtype=float)
