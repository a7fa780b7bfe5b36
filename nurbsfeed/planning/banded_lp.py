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
TOL_GAP = 1e-8  # the mean complementarity
TOL_FEAS = 1e-7  # primal residual (rows scaled to a largest coefficient of 1)
TOL_DUAL = 1e-6  # dual residual (the objective scaled to a largest coefficient of 1)
STEP_SHARE = 0.995  # of the longest step keeping s, z > 0
STALL_STEP = 0.05  # steps this short on both sides ...
STALL_ITER = 4  # ... this many times in a row: the iterate is as good as it gets


@jit
def _penta_solve(d0, d1, d2, rhs, n, out):
    """Solve the SPD pentadiagonal system H out = rhs (H[i, i] = d0[i], H[i, i+1] = d1[i],
    H[i, i+2] = d2[i]) by banded Cholesky. False where a pivot is not positive."""
    l0 = np.empty(n)
    l1 = np.zeros(n)  # l1[i] = L[i+1, i]
    l2 = np.zeros(n)  # l2[i] = L[i+2, i]
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
    y = np.empty(n)
    for i in range(n):
        v = rhs[i]
        if i >= 1:
            v -= l1[i - 1] * y[i - 1]
        if i >= 2:
            v -= l2[i - 2] * y[i - 2]
        y[i] = v / l0[i]
    for i in range(n - 1, -1, -1):
        v = y[i]
        if i + 1 < n:
            v -= l1[i] * out[i + 1]
        if i + 2 < n:
            v -= l2[i] * out[i + 2]
        out[i] = v / l0[i]
    return True


@jit
def solve_lp(n, ridx, rval, rhs, f, u, scale, x_start, hist):
    """The LP of the module docstring; returns (x (n,), status): 0 solved, 1 iterations ran
    out (x is the last iterate, possibly infeasible), 2 numerical failure."""
    # rows the box implies (|a . x| <= sum |a_j| u_j <= rhs for every x in it) are left out: a
    # row whose coefficients are rounding noise would otherwise scale to an enormous bound
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
    # scaling: x = u * y, rows divided by their largest coefficient (in y)
    a = np.empty((m, 3))
    b = np.empty(m)
    rows = np.empty(m, dtype=np.int64)
    for q in range(m):
        r = take[q]
        rows[q] = ridx[r]
        big = 0.0
        for j in range(3):
            k = ridx[r] + j
            v = rval[r, j] * (scale[k] if k < n and u[k] > 0.0 else 0.0)
            a[q, j] = v
            big = max(big, abs(v))
        for j in range(3):
            a[q, j] /= big
        b[q] = rhs[r] / big
    ridx = rows
    free = np.empty(n, dtype=np.bool_)
    top = np.empty(n)  # the box in y: u / scale
    g = np.empty(n)
    fscale = 0.0
    for i in range(n):
        free[i] = u[i] > 0.0
        top[i] = u[i] / scale[i] if free[i] else 0.0
        g[i] = f[i] * scale[i]
        fscale = max(fscale, abs(g[i]))
    if fscale == 0.0:
        fscale = 1.0
    for i in range(n):
        g[i] /= fscale
    # variables y in [0, 1] (fixed ones at 0); slacks: rows s (m), lower sl = y, upper su = 1 - y
    y = np.empty(n)
    for i in range(n):
        if free[i]:
            y[i] = min(max(x_start[i] / scale[i], 0.05 * top[i]), 0.95 * top[i])
        else:
            y[i] = 0.0
    s = np.empty(m)
    z = np.empty(m)
    lowest = 0.0
    for r in range(m):
        v = b[r]
        for j in range(3):
            k = ridx[r] + j
            if k < n:
                v -= a[r, j] * y[k]
        s[r] = v
        lowest = min(lowest, v)
    # slacks shifted positive (Mehrotra's start): the rows the start breaks begin as far inside
    # as the worst of them is outside
    shift = max(-1.5 * lowest, 0.0) + 1e-3
    for r in range(m):
        s[r] = max(s[r] + shift, 1e-3)
        z[r] = 1.0
    zl = np.ones(n)
    zu = np.ones(n)
    sl = y.copy()
    su = top - y
    for i in range(n):
        if not free[i]:
            sl[i] = 1.0
            su[i] = 1.0
    d0 = np.empty(n)
    d1 = np.empty(n)
    d2 = np.empty(n)
    rd = np.empty(n)
    rhs_n = np.empty(n)
    dy = np.empty(n)
    dy2 = np.empty(n)
    rp = np.empty(m)
    ds = np.empty(m)
    dz = np.empty(m)
    dsl = np.empty(n)
    dsu = np.empty(n)
    dzl = np.empty(n)
    dzu = np.empty(n)
    cor = np.zeros(m)
    corl = np.zeros(n)
    coru = np.zeros(n)
    n_ineq = m
    for i in range(n):
        if free[i]:
            n_ineq += 2
    status = 1
    stalled = 0
    # the best primal-feasible iterate (least objective), returned where the dual side stalls
    best_y = y.copy()
    best_obj = np.inf
    for it in range(MAX_ITER):
        # residuals
        for i in range(n):
            rd[i] = g[i] - zl[i] + zu[i] if free[i] else 0.0
        for r in range(m):
            v = s[r] - b[r]
            for j in range(3):
                k = ridx[r] + j
                if k < n:
                    v += a[r, j] * y[k]
                    if free[k]:
                        rd[k] += a[r, j] * z[r]
            rp[r] = v
        mu = 0.0
        for r in range(m):
            mu += s[r] * z[r]
        for i in range(n):
            if free[i]:
                mu += sl[i] * zl[i] + su[i] * zu[i]
        mu /= max(n_ineq, 1)
        res_p = 0.0
        for r in range(m):
            res_p = max(res_p, abs(rp[r]))
        res_d = 0.0
        for i in range(n):
            res_d = max(res_d, abs(rd[i]))
        # bound residuals: sl = y, su = 1 - y hold exactly (kept so)
        if it < hist.shape[0]:
            hist[it, 0] = mu
            hist[it, 1] = res_p
            hist[it, 2] = res_d
        if mu < TOL_GAP and res_p < TOL_FEAS and res_d < TOL_DUAL:
            status = 0
            break
        if res_p < TOL_FEAS:
            obj = 0.0
            for i in range(n):
                obj += g[i] * y[i]
            if obj < best_obj:
                best_obj = obj
                for i in range(n):
                    best_y[i] = y[i]
            if mu < TOL_GAP:  # the gap closed, the dual residual stalled on rounding
                status = 0
                break
        # normal matrix H = A^T (z/s) A + zl/sl + zu/su
        for i in range(n):
            d0[i] = zl[i] / sl[i] + zu[i] / su[i] if free[i] else 1.0
            d1[i] = 0.0
            d2[i] = 0.0
        for r in range(m):
            w = z[r] / s[r]
            i0 = ridx[r]
            for j in range(3):
                kj = i0 + j
                if kj >= n or not free[kj]:
                    continue
                for l in range(j, 3):
                    kl = i0 + l
                    if kl >= n or not free[kl]:
                        continue
                    v = w * a[r, j] * a[r, l]
                    if l == j:
                        d0[kj] += v
                    elif l == j + 1:
                        d1[kj] += v
                    else:
                        d2[kj] += v
        for phase in range(2):
            # predictor (sigma = 0) then corrector
            if phase == 0:
                target = 0.0
                for r in range(m):
                    cor[r] = 0.0
                for i in range(n):
                    corl[i] = 0.0
                    coru[i] = 0.0
            else:
                # step lengths of the predictor
                alpha_p = 1.0
                alpha_d = 1.0
                for r in range(m):
                    if ds[r] < 0.0:
                        alpha_p = min(alpha_p, -s[r] / ds[r])
                    if dz[r] < 0.0:
                        alpha_d = min(alpha_d, -z[r] / dz[r])
                for i in range(n):
                    if not free[i]:
                        continue
                    if dsl[i] < 0.0:
                        alpha_p = min(alpha_p, -sl[i] / dsl[i])
                    if dsu[i] < 0.0:
                        alpha_p = min(alpha_p, -su[i] / dsu[i])
                    if dzl[i] < 0.0:
                        alpha_d = min(alpha_d, -zl[i] / dzl[i])
                    if dzu[i] < 0.0:
                        alpha_d = min(alpha_d, -zu[i] / dzu[i])
                mu_aff = 0.0
                for r in range(m):
                    mu_aff += (s[r] + alpha_p * ds[r]) * (z[r] + alpha_d * dz[r])
                for i in range(n):
                    if free[i]:
                        mu_aff += ((sl[i] + alpha_p * dsl[i]) * (zl[i] + alpha_d * dzl[i])
                                   + (su[i] + alpha_p * dsu[i]) * (zu[i] + alpha_d * dzu[i]))
                mu_aff /= max(n_ineq, 1)
                sigma = (mu_aff / mu) ** 3
                target = sigma * mu
                for r in range(m):
                    cor[r] = ds[r] * dz[r]
                for i in range(n):
                    corl[i] = dsl[i] * dzl[i]
                    coru[i] = dsu[i] * dzu[i]
            # rc = s z - target (+ corrector term); rhs of the normal equations:
            # H dy = -rd + A^T S^-1 (rc - Z rp) + bound terms
            for i in range(n):
                rhs_n[i] = -rd[i] if free[i] else 0.0
            for r in range(m):
                rc = s[r] * z[r] - target + cor[r]
                t = (rc - z[r] * rp[r]) / s[r]
                i0 = ridx[r]
                for j in range(3):
                    k = i0 + j
                    if k < n and free[k]:
                        rhs_n[k] += a[r, j] * t
            for i in range(n):
                if not free[i]:
                    continue
                # lower: -y + sl = 0 (G row -e_i, h 0): rp_l = -y + sl = 0; upper: y + su = 1
                rcl = sl[i] * zl[i] - target + corl[i]
                rcu = su[i] * zu[i] - target + coru[i]
                rhs_n[i] += -rcl / sl[i] + rcu / su[i]
            ok = _penta_solve(d0, d1, d2, rhs_n, n, dy2)
            if not ok:
                return y * u, 2
            for i in range(n):
                dy[i] = dy2[i] if free[i] else 0.0
            for r in range(m):
                v = -rp[r]
                for j in range(3):
                    k = ridx[r] + j
                    if k < n:
                        v -= a[r, j] * dy[k]
                ds[r] = v
                rc = s[r] * z[r] - target + cor[r]
                dz[r] = -(rc + z[r] * ds[r]) / s[r]
            for i in range(n):
                if not free[i]:
                    dsl[i] = dsu[i] = dzl[i] = dzu[i] = 0.0
                    continue
                dsl[i] = dy[i]
                dsu[i] = -dy[i]
                rcl = sl[i] * zl[i] - target + corl[i]
                rcu = su[i] * zu[i] - target + coru[i]
                dzl[i] = -(rcl + zl[i] * dsl[i]) / sl[i]
                dzu[i] = -(rcu + zu[i] * dsu[i]) / su[i]
        # step
        alpha_p = 1.0
        alpha_d = 1.0
        for r in range(m):
            if ds[r] < 0.0:
                alpha_p = min(alpha_p, -s[r] / ds[r])
            if dz[r] < 0.0:
                alpha_d = min(alpha_d, -z[r] / dz[r])
        for i in range(n):
            if not free[i]:
                continue
            if dsl[i] < 0.0:
                alpha_p = min(alpha_p, -sl[i] / dsl[i])
            if dsu[i] < 0.0:
                alpha_p = min(alpha_p, -su[i] / dsu[i])
            if dzl[i] < 0.0:
                alpha_d = min(alpha_d, -zl[i] / dzl[i])
            if dzu[i] < 0.0:
                alpha_d = min(alpha_d, -zu[i] / dzu[i])
        alpha_p = min(1.0, STEP_SHARE * alpha_p)
        alpha_d = min(1.0, STEP_SHARE * alpha_d)
        stalled = stalled + 1 if max(alpha_p, alpha_d) < STALL_STEP else 0
        if stalled >= STALL_ITER:
            break
        if it < hist.shape[0] and hist.shape[1] > 3:
            hist[it, 3] = alpha_p
            hist[it, 4] = alpha_d
        for i in range(n):
            if free[i]:
                y[i] += alpha_p * dy[i]
                sl[i] += alpha_p * dsl[i]
                su[i] += alpha_p * dsu[i]
                zl[i] += alpha_d * dzl[i]
                zu[i] += alpha_d * dzu[i]
        for r in range(m):
            s[r] += alpha_p * ds[r]
            z[r] += alpha_d * dz[r]
    if status != 0 and best_obj < np.inf:
        for i in range(n):
            y[i] = best_y[i]
        status = 0
    x = np.empty(n)
    for i in range(n):
        x[i] = min(max(y[i], 0.0), top[i]) * scale[i] if free[i] else 0.0
    return x, status
