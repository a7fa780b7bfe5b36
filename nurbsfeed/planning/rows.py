"""The path model's limits as rows of a linear program over the spline's coefficients (design
§2e), and their exact check.

Along C(s), with K = kappa N and K_s = dK/ds = -kappa^2 T + kappa' N + kappa tau B:

    velocity = sqrt(b) T,   acceleration = b'/2 T + b K,
    jerk = sqrt(b) (b''/2 T + 3/2 b' K + b K_s)

At each point of a cell (cells.POINTS) b, b' and b'' are linear in the cell's three
coefficients (cells.point_weights), so every limit is a row over three consecutive variables:

- b <= cap^2 (the chord error, the normal acceleration, the feed, each axis's velocity), as
  the box on the coefficients (cells.Layout.cap);
- |b'| / 2 <= A_t, and per axis |b'/2 T_x + b K_x| <= A_x;
- the jerks, sqrt(b) |L(b, b', b'')| <= J with L linear: along the path L = b''/2 - kappa^2 b
  (K_s . T = -kappa^2), per axis L = b''/2 T_x + 3/2 b' K_x + b K_s,x, across the path the
  vector 3/2 b' K + b (K_s + kappa^2 T) held to J_n as a polygon in the plane of N and B
  (two rows along N where the curve is planar there). Where kappa N jumps by D (a knot of a
  curve only C1), the jump read over one period adds b |D| / T to the normal jerk and to each
  axis's (path_model.jump_speeds).

J / sqrt(b) is convex in b, so its tangent at the linearization point b0 lies below it:
J (3/2 - b / (2 b0)) / sqrt(b0) <= J / sqrt(b), and a row |L| <= that tangent keeps the true
limit for every b (a convex-concave step); a jump's -sqrt(b) |D| / T is convex too. The rows
are exact at b0; the linear programs (planning.schedule) move b0 to their solution and solve
again.

`point_ratio` measures the true quantities at one point (sqrt(b) exact): the slowdown lambda
(v / lambda, a / lambda^2, jerk / lambda^3) that brings every one within its limit.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.basis import G_CAP, G_D, G_K, G_KAPPA, G_KS, G_T, point_weights

NORMAL_SIDES = 16  # the polygon inscribed in the circle |jerk across T| <= J_n (3-D)
PLANAR_REL = 1e-9  # K_s's part along B below this share of |K_s|: none
# an axis whose share of T, K and K_s is below this has no rows (a still axis: its components
# are rounding noise, which compiled and plain-Python arithmetic round apart)
ZERO_REL = 1e-12
# at most: 2 tangential accelerations, 6 axis accelerations, 2 tangential jerks, 6 axis
# jerks, the normal jerk's half polygon (or its 2 rows where the curve is planar)
ROWS_PER_POINT = 2 + 6 + 2 + 6 + NORMAL_SIDES // 2 + 1
# the largest b a linearization point takes, and the smallest: b0 of a row's sqrt(b)
B_FLOOR = 1e-12


@jit
def _normal_axes(g):
    """The unit normal (3,) the normal jerk's N part is read along, the B part's scale kb
    (|K_s across T and N|) and kn (K_s . N): (nx, ny, nz, kn, kb)."""
    k = g[G_KAPPA]
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
    # a planar curve's binormal part is rounding noise (measured against all of K_s: on a
    # circle K_s + kappa^2 T is itself noise): its two rows along N are exact
    if kb <= PLANAR_REL * math.sqrt(g[G_KS] ** 2 + g[G_KS + 1] ** 2 + g[G_KS + 2] ** 2):
        kb = 0.0
    return nx, ny, nz, kn, kb


@jit
def _jerk_tangent(jerk, jump, b0):
    """A jerk row's (slope, bound): |L| + slope b <= bound, the tangent at b0 of the limit
    |L| <= J / sqrt(b) - sqrt(b) jump, where a jump of kappa N read over one period adds
    b |D| / T to the jerk (jump = |D| / T). The limit is convex in b, so its tangent lies below
    it. Where kappa N jumps the tangent is taken at b0 or at the jump's own limit J / jump,
    the lower: beyond it (where no b'' keeps the jerk anyway) the tangent would cross 0 and
    leave no b >= 0 feasible."""
    if jump > 0.0:
        b0 = min(b0, jerk / jump)
    root = math.sqrt(b0)
    return 0.5 * jerk / (b0 * root) + 0.5 * jump / root, 1.5 * jerk / root - 0.5 * jump * root


@jit
def cell_rows(c_lin, cells, geo, q, lim_t, acc_t, jerk_n, acc_x, jerk_x, period, idx, val, rhs,
              r):
    """Write the rows of inner cell q, linearized at the coefficients c_lin, from row r on:
    idx (first coefficient), val (3 weights), rhs. Returns the next free row. (A cell's end and
    the next one's start give the same rows but for b'': left in, the interior-point solver
    does better with them, one 2 mm figure-eight's first program stalled without.)"""
    w = np.empty((3, 3))
    i0 = int(cells[q, 0])
    g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
    for p in range(3):
        point_weights(g0, g1, w0, h, 0.5 * p, w)
        g = geo[q, p]
        b0 = 0.0
        for j in range(3):
            b0 += w[0, j] * c_lin[i0 + j]
        b0 = max(b0, B_FLOOR)
        root = math.sqrt(b0)
        k = g[G_KAPPA]
        # (b <= cap^2 is the box's: each coefficient is capped by its cells' lowest cap)
        # |b'| <= 2 A_t
        for sign in (1.0, -1.0):
            for j in range(3):
                val[r, j] = sign * w[1, j]
            idx[r] = i0
            rhs[r] = 2.0 * acc_t
            r += 1
        # per axis |b'/2 T_x + b K_x| <= A_x
        k_size = abs(k)
        ks_size = math.sqrt(g[G_KS] ** 2 + g[G_KS + 1] ** 2 + g[G_KS + 2] ** 2)
        for x in range(3):
            tx, kx = g[G_T + x], g[G_K + x]
            if acc_x[x] == np.inf or (abs(tx) <= ZERO_REL and abs(kx) <= ZERO_REL * k_size):
                continue
            for sign in (1.0, -1.0):
                for j in range(3):
                    val[r, j] = sign * (0.5 * tx * w[1, j] + kx * w[0, j])
                idx[r] = i0
                rhs[r] = acc_x[x]
                r += 1
        # the jerks: |L| + (tangent slope) b <= 3/2 J / sqrt(b0) (`_jerk_tangent`)
        slope = 0.5 * lim_t / (b0 * root)
        for sign in (1.0, -1.0):
            for j in range(3):
                val[r, j] = sign * (0.5 * w[2, j] - k * k * w[0, j]) + slope * w[0, j]
            idx[r] = i0
            rhs[r] = 1.5 * lim_t / root
            r += 1
        for x in range(3):
            tx, kx, ksx = g[G_T + x], g[G_K + x], g[G_KS + x]
            if jerk_x[x] == np.inf or (abs(tx) <= ZERO_REL and abs(kx) <= ZERO_REL * k_size
                                       and abs(ksx) <= ZERO_REL * ks_size):
                continue
            slope, bound = _jerk_tangent(jerk_x[x], abs(g[G_D + x]) / period, b0)
            for sign in (1.0, -1.0):
                for j in range(3):
                    val[r, j] = (sign * (0.5 * tx * w[2, j] + 1.5 * kx * w[1, j] + ksx * w[0, j])
                                 + slope * w[0, j])
                idx[r] = i0
                rhs[r] = bound
                r += 1
        nx, ny, nz, kn, kb = _normal_axes(g)
        jump = math.sqrt(g[G_D] ** 2 + g[G_D + 1] ** 2 + g[G_D + 2] ** 2) / period
        slope, bound = _jerk_tangent(jerk_n, jump, b0)
        # the inscribed polygon: its sides at cos(pi / NORMAL_SIDES) of the radius; the part
        # along B is b kb >= 0, so only the sides facing it (angles 0 to pi) can bind: those
        # facing away are implied by the two along N
        shrink = math.cos(math.pi / NORMAL_SIDES) if kb > 0.0 else 1.0
        sides = NORMAL_SIDES // 2 + 1 if kb > 0.0 else 2
        for side in range(sides):
            if kb > 0.0:
                theta = 2.0 * math.pi * side / NORMAL_SIDES
                cn, cb = math.cos(theta), math.sin(theta)
            else:
                cn, cb = (1.0, 0.0) if side == 0 else (-1.0, 0.0)
            for j in range(3):
                val[r, j] = (cn * (1.5 * k * w[1, j] + kn * w[0, j]) + cb * kb * w[0, j]
                             + shrink * slope * w[0, j])
            idx[r] = i0
            rhs[r] = shrink * bound
            r += 1
    return r


@jit
def all_rows(c_lin, cells, geo, lim_t, acc_t, jerk_n, acc_x, jerk_x, period, idx, val, rhs):
    """Every inner cell's rows (`cell_rows`) into idx (R,), val (R, 3), rhs (R,); returns R."""
    r = np.int64(0)  # (a literal 0 would compile cell_rows a second time)
    for q in range(cells.shape[0]):
        r = cell_rows(c_lin, cells, geo, q, lim_t, acc_t, jerk_n, acc_x, jerk_x, period, idx,
                      val, rhs, r)
    return r


@jit
def point_ratio(g, b, d, dd, lim_t, acc_t, jerk_n, acc_x, vel_x, jerk_x, period):
    """The slowdown lambda >= 0 that keeps every limit at one point with b, b' = d, b'' = dd
    (<= 1: it holds as it is): a speed's share, an acceleration's square root, a jerk's cube
    root."""
    bb = max(b, 0.0)
    root = math.sqrt(bb)
    k = g[G_KAPPA]
    worst = 0.0
    if bb > 0.0:
        worst = math.sqrt(bb / g[G_CAP]) if g[G_CAP] > 0.0 else np.inf
    worst = max(worst, math.sqrt(abs(d) / (2.0 * acc_t)))
    worst = max(worst, (root * abs(0.5 * dd - k * k * bb) / lim_t) ** (1.0 / 3.0))
    jump2 = g[G_D] ** 2 + g[G_D + 1] ** 2 + g[G_D + 2] ** 2
    nx = 1.5 * d * g[G_K] + bb * (g[G_KS] + k * k * g[G_T])
    ny = 1.5 * d * g[G_K + 1] + bb * (g[G_KS + 1] + k * k * g[G_T + 1])
    nz = 1.5 * d * g[G_K + 2] + bb * (g[G_KS + 2] + k * k * g[G_T + 2])
    normal = root * math.sqrt(nx * nx + ny * ny + nz * nz) + bb * math.sqrt(jump2) / period
    worst = max(worst, (normal / jerk_n) ** (1.0 / 3.0))
    for x in range(3):
        tx = g[G_T + x]
        if vel_x[x] < np.inf:
            worst = max(worst, root * abs(tx) / vel_x[x])
        if acc_x[x] < np.inf:
            worst = max(worst, math.sqrt(abs(0.5 * d * tx + bb * g[G_K + x]) / acc_x[x]))
        if jerk_x[x] < np.inf:
            jx = (root * abs(0.5 * dd * tx + 1.5 * d * g[G_K + x] + bb * g[G_KS + x])
                  + bb * abs(g[G_D + x]) / period)
            worst = max(worst, (jx / jerk_x[x]) ** (1.0 / 3.0))
    return worst


@jit
def cell_ratios(c, cells, geo, xs, lim_t, acc_t, jerk_n, acc_x, vel_x, jerk_x, period, out):
    """Per inner cell (Q,): the largest `point_ratio` over its points at shares xs (P,) with
    the geometry geo (Q, P, G_SIZE) there, b, b', b'' from the coefficients c."""
    w = np.empty((3, 3))
    for q in range(cells.shape[0]):
        i0 = int(cells[q, 0])
        worst = 0.0
        for p in range(xs.size):
            point_weights(cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4], xs[p], w)
            b = w[0, 0] * c[i0] + w[0, 1] * c[i0 + 1] + w[0, 2] * c[i0 + 2]
            d = w[1, 0] * c[i0] + w[1, 1] * c[i0 + 1] + w[1, 2] * c[i0 + 2]
            dd = w[2, 0] * c[i0] + w[2, 1] * c[i0 + 1] + w[2, 2] * c[i0 + 2]
            worst = max(worst, point_ratio(geo[q, p], b, d, dd, lim_t, acc_t, jerk_n, acc_x,
                                           vel_x, jerk_x, period))
        out[q] = worst
