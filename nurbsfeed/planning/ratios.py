"""The path model's limits read exactly at one point of a schedule, and at every cell's
points: how much slower it must run to keep them.

Along C(s), with K = kappa N and K_s = dK/ds = -kappa^2 T + kappa' N + kappa tau B, and b = v^2:

    velocity = sqrt(b) T,   acceleration = b'/2 T + b K,
    jerk = sqrt(b) (b''/2 T + 3/2 b' K + b K_s)

so the caps on b (the chord error, the normal acceleration, the feed, each axis's velocity),
|b'| / 2 <= A_t, per axis |b'/2 T_x + b K_x| <= A_x, along the path sqrt(b) |b''/2 - kappa^2 b|
<= J_t (K_s . T = -kappa^2), per axis sqrt(b) |b''/2 T_x + 3/2 b' K_x + b K_s,x| <= J_x, and
across the path sqrt(b) |3/2 b' K + b (K_s + kappa^2 T)| <= J_n. Where kappa N jumps by D (a
knot of a curve only C1), the jump read over one period adds b |D| / T to the normal jerk and
to each axis's (path_model.jump_speeds).

`point_ratio` is the slowdown lambda (v / lambda, a / lambda^2, jerk / lambda^3) that brings
every one of them within its limit: what the planner's rows (planning.reach_rows) hold at the
cells' points, measured without their linearisation.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.basis import G_CAP, G_D, G_K, G_KAPPA, G_KS, G_T, point_weights


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
