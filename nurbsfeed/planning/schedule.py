"""The path planner's schedule (design §2d): the spline b = v^2 on a layout's coefficients
(planning.cells), what it costs, and the static speed limit its first linearisation starts
from. planning.reach_schedule finds it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.basis import G_CAP, G_D, G_K, G_KAPPA, G_KS, G_T, point_weights
from nurbsfeed.planning.cells import Layout

# a cell whose schedule breaks a limit between its points by more than this share (of the
# speed: a third of it in a jerk) is cut and the curve planned again (path_plan.RECUTS)
BETWEEN_REL = 1e-3
GAUSS_X, GAUSS_W = np.polynomial.legendre.leggauss(8)


@dataclass(frozen=True, eq=False)
class Schedule:
    """The planned spline: its coefficients c (C,) on the layout, the cycle they take (s,
    before whole periods), the uniform slowdown (>= 1) its exact check at every cell's points
    asked for, the passes over the stretches' sets that found it, whether every stretch found
    a motion (if not, c is the start, slowed), and the inner cells (Q,) in which c breaks a
    limit by more than BETWEEN_REL between those points (at basis.BETWEEN)."""

    layout: Layout
    c: np.ndarray
    cycle_s: float
    slowdown: float
    passes: int
    solved: bool
    broken_between: np.ndarray


@jit
def static_b(geo, lim_t, jerk_n, acc_x, jerk_x, period, out):
    """Per cell point (Q, 3): b at which every limit holds with b' = b'' = 0 (a bound on the
    first linearisation, reach_schedule._estimate): kappa^2 b^1.5 <= J_t, |K_s + kappa^2 T|
    b^1.5 <= J_n, per axis |K_x| b <= A_x and |K_s,x| b^1.5 <= J_x, the cap, and where kappa N
    jumps by D, half of what the jump alone allows (b |D| / T <= J / 2: the rest of the jerk
    is the curve's)."""
    for q in range(geo.shape[0]):
        for p in range(3):
            g = geo[q, p]
            k = g[G_KAPPA]
            b = g[G_CAP]
            if k > 0.0:
                b = min(b, (lim_t / (k * k)) ** (2.0 / 3.0))
            nx = g[G_KS] + k * k * g[G_T]
            ny = g[G_KS + 1] + k * k * g[G_T + 1]
            nz = g[G_KS + 2] + k * k * g[G_T + 2]
            n = math.sqrt(nx * nx + ny * ny + nz * nz)
            if n > 0.0:
                b = min(b, (jerk_n / n) ** (2.0 / 3.0))
            for x in range(3):
                kx = abs(g[G_K + x])
                if kx > 0.0 and acc_x[x] < np.inf:
                    b = min(b, acc_x[x] / kx)
                kx = abs(g[G_KS + x])
                if kx > 0.0 and jerk_x[x] < np.inf:
                    b = min(b, (jerk_x[x] / kx) ** (2.0 / 3.0))
                if g[G_D + x] != 0.0 and jerk_x[x] < np.inf:
                    b = min(b, 0.5 * jerk_x[x] * period / abs(g[G_D + x]))
            jump = math.sqrt(g[G_D] ** 2 + g[G_D + 1] ** 2 + g[G_D + 2] ** 2)
            if jump > 0.0:
                b = min(b, 0.5 * jerk_n * period / jump)
            out[q, p] = b


@jit
def cell_times(c, cells, first, last, rest_h, times):
    """Each inner cell's duration (Q,) by Gauss-Legendre on 1 / sqrt(b) (inf where b reaches 0
    inside), and the rest cells' 3 h / sqrt(b_far) (S, 2) into times[Q:]. Returns the sum."""
    q_n = cells.shape[0]
    total = 0.0
    w = np.empty((3, 3))
    for q in range(q_n):
        i0 = int(cells[q, 0])
        h = cells[q, 4]
        t = 0.0
        for g in range(GAUSS_X.size):
            x = 0.5 * (GAUSS_X[g] + 1.0)
            point_weights(cells[q, 1], cells[q, 2], cells[q, 3], h, x, w)
            b = w[0, 0] * c[i0] + w[0, 1] * c[i0 + 1] + w[0, 2] * c[i0 + 2]
            if not b > 0.0:
                t = np.inf
                break
            t += GAUSS_W[g] / math.sqrt(b)
        t *= 0.5 * h
        times[q] = t
        total += t
    for s in range(first.size):
        for side in range(2):
            b = c[first[s]] if side == 0 else c[last[s]]
            t = 3.0 * rest_h[s, side] / math.sqrt(b) if b > 0.0 else np.inf
            times[q_n + 2 * s + side] = t
            total += t
    return total
