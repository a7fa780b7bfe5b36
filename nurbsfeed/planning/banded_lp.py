"""A linear program whose every row spans three consecutive variables, solved by a primal-dual
interior-point method (Mehrotra's predictor-corrector): the normal matrix A^T D A is then
pentadiagonal, so each iteration costs O(rows).

    minimize f . x   subject to   a_r . x[i_r : i_r + 3] <= rhs_r  (each row r),  0 <= x <= u

Rows are given as (i_r, a_r (3,), rhs_r); variables with u = 0 are fixed at 0 (their columns
may still appear in rows). The solver works on y = x / scale (scale: the size each variable is
expected to take, not its bound: a variable far below its bound would otherwise take rows
scaled by the others) and on rows scaled to a largest coefficient of 1.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit

MAX_ITER = 80
TOL_GAP = 1e-6  # the mean complementarity
# primal residual, each row's over its bound (rows scaled to a largest coefficient of 1): a
# row whose terms nearly cancel (b'' on a short cell) has a bound far below its coefficients,
# and a residual measured against them would leave it broken by a share of its bound
TOL_FEAS = 1e-7
ROW_FLOOR = 1e-9  # ... or over this, for a bound near 0
TOL_DUAL = 1e-6  # dual residual (the objective scaled to a largest coefficient of 1)
STEP_SHARE = 0.995  # of the longest step keeping s, z > 0
SHORT_STEP = 0.1  # a step this short on either side: the next one aims at ...
CENTRE_SHARE = 0.5  # ... this share of the complementarity at least (a centring step)
STALL_STEP = 0.05  # steps this short on both sides ...
STALL_ITER = 4  # ... this many times in a row: the iterate is as good as it gets


@jit
def _penta_factor(d0, d1, d2, l0, l1, l2):
    """Banded Cholesky of the SPD pentadiagonal H (H[i, i] = d0[i], H[i, i+1] = d1[i],
    H[i, i+2] = d2[i]) into l0 (the diagonal), l1[i] = L[i+1, i], l2[i] = L[i+2, i]. False
    where a pivot is not positive."""
    n = d0.size
    for i in range(n):
        a = d0[i]
        if i >= 2:
            l2[i - 2] = d2[i - 2] / l0[i - 2]
            a -= l2[i - 2] * l2[i - 2]
        if i >= 1:
            v = d1[i - 1]
            if i >= 2:
                v -= l2[i - 2] * l1[i - 2]
            l1[i - 1] = v / l0[i - 1]
            a -= l1[i - 1] * l1[i - 1]
        if not a > 1e-14 * d0[i]:
            # a pivot lost to rounding (an almost dependent row set near the optimum): that
            # direction is taken as infinitely stiff, its step 0 (Cholesky-infinity)
            if not d0[i] > 0.0:
                return False
            a = 1e64 * d0[i]
        l0[i] = math.sqrt(a)
    return True


@jit
def _penta_solve(l0, l1, l2, rhs, out):
    """out = H^-1 rhs from the factor of `_penta_factor`."""
    n = l0.size
    for i in range(n):
        v = rhs[i]
        if i >= 1:
            v -= l1[i - 1] * out[i - 1]
        if i >= 2:
            v -= l2[i - 2] * out[i - 2]
        out[i] = v / l0[i]
    for i in range(n - 1, -1, -1):
        v = out[i]
        if i + 1 < n:
            v -= l1[i] * out[i + 1]
        if i + 2 < n:
            v -= l2[i] * out[i + 2]
        out[i] = v / l0[i]


@jit
def _presolve(n, ridx, rval, rhs, u, scale):
    """The rows the solver keeps, scaled (module docstring): (index, a0, a1, a2, b), a
    coefficient 0 where its variable is fixed or past the last. Rows the box implies
    (|a . x| <= sum |a_j| u_j <= rhs for every x in it) are left out: a row whose coefficients
    are rounding noise would otherwise scale to an enormous bound."""
    m_all = ridx.size
    take = np.empty(m_all, dtype=np.int64)
    m = 0
    for r in range(m_all):
        reach = 0.0
        for j in range(3):
            k = ridx[r] + j
            if k < n:
                reach += abs(rval[r, j]) * u[k]
        if reach > rhs[r]:
            take[m] = r
            m += 1
    rows = np.empty(m, dtype=np.int64)
    a = np.zeros((3, m))
    b = np.empty(m)
    for q in range(m):
        r = take[q]
        rows[q] = ridx[r]
        big = 0.0
        for j in range(3):
            k = ridx[r] + j
            if k < n and u[k] > 0.0:
                a[j, q] = rval[r, j] * scale[k]
                big = max(big, abs(a[j, q]))
        for j in range(3):
            a[j, q] /= big
        b[q] = rhs[r] / big
    return rows, a[0].copy(), a[1].copy(), a[2].copy(), b


@jit
def _row_steps(ridx, a0, a1, a2, rp, s, z, dy, target, cor, ds, dz):
    """The rows' slack and multiplier steps from dy, and the longest steps (primal, dual)
    keeping s, z > 0; cor (the corrector's ds dz) where target >= 0."""
    alpha_p = 1.0
    alpha_d = 1.0
    for r in range(ridx.size):
        i = ridx[r]
        v = -rp[r] - a0[r] * dy[i] - a1[r] * dy[i + 1] - a2[r] * dy[i + 2]
        rc = s[r] * z[r]
        if target >= 0.0:
            rc += cor[r] - target  # (read before ds takes the step: cor may be ds itself)
        ds[r] = v
        w = -(rc + z[r] * v) / s[r]
        dz[r] = w
        if v < 0.0:
            alpha_p = min(alpha_p, -s[r] / v)
        if w < 0.0:
            alpha_d = min(alpha_d, -z[r] / w)
    return alpha_p, alpha_d


@jit
def _bound_steps(free, top, y, sl, su, zl, zu, dy, target, corl, coru, dzl, dzu,
                 alpha_p, alpha_d):
    """The box's multiplier steps (its slacks step by +-dy) and the longest steps with them."""
    for i in range(free.size):
        if not free[i]:
            dzl[i] = dzu[i] = 0.0
            continue
        rcl = sl[i] * zl[i]
        rcu = su[i] * zu[i]
        if target >= 0.0:
            rcl += corl[i] - target
            rcu += coru[i] - target
        dzl[i] = -(rcl + zl[i] * dy[i]) / sl[i]
        dzu[i] = -(rcu - zu[i] * dy[i]) / su[i]
        if dy[i] < 0.0:
            alpha_p = min(alpha_p, -sl[i] / dy[i])
        elif dy[i] > 0.0:
            alpha_p = min(alpha_p, su[i] / dy[i])
        if dzl[i] < 0.0:
            alpha_d = min(alpha_d, -zl[i] / dzl[i])
        if dzu[i] < 0.0:
            alpha_d = min(alpha_d, -zu[i] / dzu[i])
    return alpha_p, alpha_d


@jit
def solve_lp(n, ridx, rval, rhs, f, u, scale, x_start, hist):
    """The LP of the module docstring; returns (x (n,), status): 0 solved, 1 iterations ran
    out (x is the last iterate, possibly infeasible), 2 numerical failure."""
    ridx, a0, a1, a2, b = _presolve(n, ridx, rval, rhs, u, scale)
    m = ridx.size
    # the variables y = x / scale in [0, top], two past the last (always 0) so that every
    # row reads three without a test
    nn = n + 2
    free = np.zeros(nn, dtype=np.bool_)
    top = np.zeros(nn)
    g = np.zeros(nn)
    fscale = 0.0
    for i in range(n):
        free[i] = u[i] > 0.0
        top[i] = u[i] / scale[i] if free[i] else 0.0
        g[i] = f[i] * scale[i] if free[i] else 0.0
        fscale = max(fscale, abs(g[i]))
    if fscale == 0.0:
        fscale = 1.0
    for i in range(n):
        g[i] /= fscale
    y = np.zeros(nn)
    for i in range(n):
        if free[i]:
            y[i] = min(max(x_start[i] / scale[i], 0.05 * top[i]), 0.95 * top[i])
    # row slacks s, multipliers z; the box's slacks sl = y, su = top - y and multipliers
    s = np.empty(m)
    z = np.ones(m)
    lowest = 0.0
    for r in range(m):
        i = ridx[r]
        s[r] = b[r] - a0[r] * y[i] - a1[r] * y[i + 1] - a2[r] * y[i + 2]
        lowest = min(lowest, s[r])
    # slacks shifted positive (Mehrotra's start): the rows the start breaks begin as far inside
    # as the worst of them is outside
    shift = max(-1.5 * lowest, 0.0) + 1e-3
    for r in range(m):
        s[r] = max(s[r] + shift, 1e-3)
    zl = np.ones(nn)
    zu = np.ones(nn)
    sl = np.ones(nn)
    su = np.ones(nn)
    for i in range(n):
        if free[i]:
            sl[i] = y[i]
            su[i] = top[i] - y[i]
    d0, d1, d2 = np.empty(nn), np.empty(nn), np.empty(nn)
    l0, l1, l2 = np.empty(nn), np.zeros(nn), np.zeros(nn)
    rd, r_pred, r_cor, r_inv = np.empty(nn), np.empty(nn), np.empty(nn), np.empty(nn)
    rhs_n, dy = np.empty(nn), np.zeros(nn)
    rp, ds, dz = np.empty(m), np.zeros(m), np.zeros(m)
    dzl, dzu = np.zeros(nn), np.zeros(nn)
    corl, coru = np.zeros(nn), np.zeros(nn)
    n_ineq = m
    for i in range(n):
        if free[i]:
            n_ineq += 2
    status = 1
    stalled = 0
    short = False
    # the best primal-feasible iterate (least objective), returned where the dual side stalls
    best_y = y.copy()
    best_obj = np.inf
    for it in range(MAX_ITER):
        # one pass over the rows: the residuals, the normal matrix H = A^T (z / s) A (+ the
        # box's), the predictor's right-hand side
        for i in range(nn):
            rd[i] = g[i] - zl[i] + zu[i] if free[i] else 0.0
            d0[i] = zl[i] / sl[i] + zu[i] / su[i] if free[i] else 1.0
            d1[i] = d2[i] = 0.0
            r_pred[i] = r_cor[i] = r_inv[i] = 0.0
        mu = 0.0
        res_p = 0.0
        res_abs = 0.0
        for r in range(m):
            i = ridx[r]
            c0, c1, c2 = a0[r], a1[r], a2[r]
            sr, zr = s[r], z[r]
            v = sr - b[r] + c0 * y[i] + c1 * y[i + 1] + c2 * y[i + 2]
            rp[r] = v
            res_p = max(res_p, abs(v) / (abs(b[r]) + ROW_FLOOR))
            res_abs = max(res_abs, abs(v))
            mu += sr * zr
            rd[i] += c0 * zr
            rd[i + 1] += c1 * zr
            rd[i + 2] += c2 * zr
            w = zr / sr
            d0[i] += w * c0 * c0
            d0[i + 1] += w * c1 * c1
            d0[i + 2] += w * c2 * c2
            d1[i] += w * c0 * c1
            d1[i + 1] += w * c1 * c2
            d2[i] += w * c0 * c2
            # (s z - z rp) / s: the predictor's term, target 0
            t = zr - w * v
            r_pred[i] += c0 * t
            r_pred[i + 1] += c1 * t
            r_pred[i + 2] += c2 * t
        for i in range(n):
            if free[i]:
                mu += sl[i] * zl[i] + su[i] * zu[i]
        mu /= max(n_ineq, 1)
        res_d = 0.0
        for i in range(n):
            res_d = max(res_d, abs(rd[i]))
        if it < hist.shape[0]:
            hist[it, 0] = mu
            hist[it, 1] = res_p
            hist[it, 2] = res_d
        if mu < TOL_GAP and res_p < TOL_FEAS and res_d < TOL_DUAL:
            status = 0
            break
        if res_abs < TOL_FEAS:
            obj = 0.0
            for i in range(n):
                obj += g[i] * y[i]
            if obj < best_obj:
                best_obj = obj
                best_y[:] = y
            if mu < TOL_GAP and res_p < TOL_FEAS:  # the dual residual stalled on rounding
                status = 0
                break
        if not _penta_factor(d0, d1, d2, l0, l1, l2):
            return _unscaled(y, free, top, scale, n), 2
        # predictor (target 0): H dy = -rd + A^T S^-1 (s z - Z rp) + the box's terms
        for i in range(nn):
            rhs_n[i] = -rd[i] + r_pred[i] - zl[i] + zu[i] if free[i] else 0.0
        _penta_solve(l0, l1, l2, rhs_n, dy)
        for i in range(nn):
            if not free[i]:
                dy[i] = 0.0
        alpha_p, alpha_d = _row_steps(ridx, a0, a1, a2, rp, s, z, dy, -1.0, ds, ds, dz)
        alpha_p, alpha_d = _bound_steps(free, top, y, sl, su, zl, zu, dy, -1.0, corl, coru,
                                        dzl, dzu, alpha_p, alpha_d)
        # the corrector's target from the predictor's complementarity; its right-hand side
        # adds A^T S^-1 (ds dz - target)
        mu_aff = 0.0
        for r in range(m):
            i = ridx[r]
            mu_aff += (s[r] + alpha_p * ds[r]) * (z[r] + alpha_d * dz[r])
            c = ds[r] * dz[r]
            inv = 1.0 / s[r]
            r_cor[i] += a0[r] * c * inv
            r_cor[i + 1] += a1[r] * c * inv
            r_cor[i + 2] += a2[r] * c * inv
            r_inv[i] += a0[r] * inv
            r_inv[i + 1] += a1[r] * inv
            r_inv[i + 2] += a2[r] * inv
        for i in range(n):
            if free[i]:
                mu_aff += ((sl[i] + alpha_p * dy[i]) * (zl[i] + alpha_d * dzl[i])
                           + (su[i] - alpha_p * dy[i]) * (zu[i] + alpha_d * dzu[i]))
                corl[i] = dy[i] * dzl[i]
                coru[i] = -dy[i] * dzu[i]
        mu_aff /= max(n_ineq, 1)
        target = (mu_aff / mu) ** 3 * mu
        if short:
            # the last step was blocked (Mehrotra's target too greedy for this iterate): centre
            target = max(target, CENTRE_SHARE * mu)
        for r in range(m):
            ds[r] = ds[r] * dz[r]  # the corrector term ds dz, kept in ds until the next steps
        for i in range(nn):
            if free[i]:
                rcl = sl[i] * zl[i] - target + corl[i]
                rcu = su[i] * zu[i] - target + coru[i]
                rhs_n[i] = (-rd[i] + r_pred[i] + r_cor[i] - target * r_inv[i]
                            - rcl / sl[i] + rcu / su[i])
            else:
                rhs_n[i] = 0.0
        _penta_solve(l0, l1, l2, rhs_n, dy)
        for i in range(nn):
            if not free[i]:
                dy[i] = 0.0
        alpha_p, alpha_d = _row_steps(ridx, a0, a1, a2, rp, s, z, dy, target, ds, ds, dz)
        alpha_p, alpha_d = _bound_steps(free, top, y, sl, su, zl, zu, dy, target, corl, coru,
                                        dzl, dzu, alpha_p, alpha_d)
        alpha_p = min(1.0, STEP_SHARE * alpha_p)
        alpha_d = min(1.0, STEP_SHARE * alpha_d)
        short = min(alpha_p, alpha_d) < SHORT_STEP
        stalled = stalled + 1 if max(alpha_p, alpha_d) < STALL_STEP else 0
        if stalled >= STALL_ITER:
            break
        if it < hist.shape[0] and hist.shape[1] > 3:
            hist[it, 3] = alpha_p
            hist[it, 4] = alpha_d
        for i in range(n):
            if free[i]:
                y[i] += alpha_p * dy[i]
                sl[i] += alpha_p * dy[i]
                su[i] -= alpha_p * dy[i]
                zl[i] += alpha_d * dzl[i]
                zu[i] += alpha_d * dzu[i]
        for r in range(m):
            s[r] += alpha_p * ds[r]
            z[r] += alpha_d * dz[r]
    if status != 0 and best_obj < np.inf:
        y[:] = best_y
        status = 0
    if status == 0:
        _scale_into_rows(ridx, a0, a1, a2, b, y)
    return _unscaled(y, free, top, scale, n), status


@jit
def _scale_into_rows(ridx, a0, a1, a2, b, y):
    """y scaled down until it keeps every row exactly where every bound is >= 0 (0 keeps them
    all, and a row is linear in y): the best iterate of a program that stalled breaks the rows
    with bounds near 0 by a share of their bound, beyond its absolute tolerance."""
    share = 1.0
    for r in range(ridx.size):
        if b[r] < 0.0:
            return
        i = ridx[r]
        left = a0[r] * y[i] + a1[r] * y[i + 1] + a2[r] * y[i + 2]
        if left > b[r]:
            share = min(share, b[r] / left)
    if share < 1.0:
        for i in range(y.size):
            y[i] *= share


@jit
def _unscaled(y, free, top, scale, n):
    x = np.empty(n)
    for i in range(n):
        x[i] = min(max(y[i], 0.0), top[i]) * scale[i] if free[i] else 0.0
    return x
