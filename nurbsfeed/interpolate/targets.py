"""The per-period targets of a stretch between rests: its plan times t_k, from the integer k
(never by summing periods), and the targets ds_k = s(t_k+1) - s(t_k) sampled from the time law
between them, with the sums the landing needs (interpolate.landing samples a stretch through
these, chunk by chunk).
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.timelaw import evaluate


def plan_time(t_a: float, t_b: float, n: int, k: int) -> float:
    """Plan time of period k of a stretch of n periods from t_a to t_b: t_a + k (t_b - t_a) / n,
    t_b exactly at k = n. From the integer k, never by summing periods."""
    if k == n:
        return t_b
    return t_a + k * ((t_b - t_a) / n)


def plan_times(t_a: float, t_b: float, n: int, lo: int, hi: int) -> np.ndarray:
    """`plan_time` of periods lo .. hi - 1: (hi - lo,), the same arithmetic in numpy."""
    t = t_a + np.arange(lo, hi) * ((t_b - t_a) / n)
    if lo <= n < hi:
        t[n - lo] = t_b
    return t


def first_period_at(t_a: float, t_b: float, n: int, x: float) -> int:
    """np.searchsorted over a stretch's plan times (n+1,), which are never stored: the first
    period k with t_k >= x, by bisection."""
    lo = 0
    hi = n + 1
    while lo < hi:
        mid = (lo + hi) // 2
        if plan_time(t_a, t_b, n, mid) < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@jit
def sample_targets(t0, s0, v0, a0, jk, t_plan, ds, grid_s, grid_kappa, with_drift, node, drift,
                   total, carry):
    """The targets ds_k = s(t_k+1) - s(t_k) between the plan times t_plan (M+1,) of consecutive
    periods (`plan_times`) into ds (M,), and the running sums over a stretch sampled chunk by
    chunk in order: returns them (node, drift, total, carry) updated.

    ds_k is taken piece by piece (the pieces' starts s0 differ, then the arcs within them), so
    that a tiny step far along the curve keeps its relative precision. total + carry is the
    targets' sum, compensated (Neumaier) and added in order, so that it does not depend on how
    the stretch is chunked. If with_drift, drift accumulates 24 times how far rk2c's arc position
    will run ahead of the targets: sum(min(kappa ds, 2)^2 ds), the arc minus the chord of a
    circular arc of curvature kappa per step, with kappa at the middle of each step interpolated
    linearly on the grid (grid_s, grid_kappa (G,); node: the grid interval reached so far);
    beside a corner (kappa infinite) from its finite side.
    """
    m = ds.size
    piece = np.empty(m + 1, dtype=np.int64)
    local = np.empty(m + 1)
    v = np.empty(m + 1)
    a = np.empty(m + 1)
    j = np.empty(m + 1)
    evaluate(t0, s0, v0, a0, jk, t_plan, piece, local, v, a, j)
    for k in range(m):
        ds[k] = (s0[piece[k + 1]] - s0[piece[k]]) + (local[k + 1] - local[k])
        added = total + ds[k]
        if abs(total) >= abs(ds[k]):
            carry += (total - added) + ds[k]
        else:
            carry += (ds[k] - added) + total
        total = added
    if with_drift:
        last = grid_s.size - 1
        for k in range(m):
            s = s0[piece[k]] + local[k] + 0.5 * ds[k]
            while node + 1 < last and grid_s[node + 1] <= s:
                node += 1
            if s <= grid_s[0]:
                kappa = grid_kappa[0]
            elif s >= grid_s[last]:
                kappa = grid_kappa[last]
            else:
                k_lo = grid_kappa[node]
                k_hi = grid_kappa[node + 1]
                if math.isinf(k_lo) or math.isinf(k_hi):  # beside a corner: the finite side
                    kappa = k_hi if math.isinf(k_lo) else k_lo
                else:
                    w = (s - grid_s[node]) / (grid_s[node + 1] - grid_s[node])
                    kappa = k_lo + w * (k_hi - k_lo)
            if math.isinf(kappa):
                continue
            turn = min(kappa * ds[k], 2.0)
            drift += turn * turn * ds[k]
    return node, drift, total, carry
