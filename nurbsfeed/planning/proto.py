"""Prototype: ceiling (lattice passes) + valleys (U-curves from the bottoms)."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit

# geometry row layout per cell point
G_KAPPA, G_T, G_K, G_KS, G_D, G_CAP = 0, 1, 4, 7, 10, 13
G_SIZE = 14
ALONG = 0.3
TINY = 1e-300


@jit
def point_values(c, i0, g0, g1, w0, h, x):
    """b, b', b'' at share x of the inner cell whose coefficients start at i0."""
    s0 = (c[i0 + 1] - c[i0]) / g0
    s1 = (c[i0 + 2] - c[i0 + 1]) / g1
    dd = (s1 - s0) / h
    b0 = w0 * c[i0] + (1.0 - w0) * c[i0 + 1]
    xs = x * h
    return b0 + s0 * xs + 0.5 * dd * xs * xs, s0 + dd * xs, dd


@jit
def curv_bounds(geo, b, d, lim_t, lim_x, period):
    """L, U on b'' at one point with b, b' there (sqrt(b) at b): tangential and along-axis jerk."""
    bb = max(b, 1e-300)
    root = math.sqrt(bb)
    k = geo[G_KAPPA]
    lo = 2.0 * k * k * bb - 2.0 * lim_t / root
    hi = 2.0 * k * k * bb + 2.0 * lim_t / root
    for x in range(3):
        tx = geo[G_T + x]
        if abs(tx) < ALONG or lim_x[x] == np.inf:
            continue
        rho = max(lim_x[x] / root - bb * abs(geo[G_D + x]) / period, 0.0)
        r = 1.5 * d * geo[G_K + x] + bb * geo[G_KS + x]
        a = 2.0 * (-rho - r) / tx
        e = 2.0 * (rho - r) / tx
        if a > e:
            a, e = e, a
        lo = max(lo, a)
        hi = min(hi, e)
    return lo, hi


@jit
def cell_curv_bounds(c, cells, geo, lim_t, lim_x, period, lo_out, hi_out):
    """Per inner cell: L, U from its three points, b and b' from c."""
    for q in range(cells.shape[0]):
        i0 = int(cells[q, 0])
        g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
        lo = -np.inf
        hi = np.inf
        for p in range(3):
            b, d, _ = point_values(c, i0, g0, g1, w0, h, 0.5 * p)
            a, e = curv_bounds(geo[q, p], b, d, lim_t, lim_x, period)
            lo = max(lo, a)
            hi = min(hi, e)
        lo_out[q] = lo
        hi_out[q] = hi


@jit
def knot_rows(geo, b, d, dd, acc_t, acc_x, jerk_n, jerk_x, period, rows):
    """Rows (R, 3): alpha b' + beta b <= gamma at one knot side (gamma at this sqrt(b)), with
    b'' frozen at dd for the cross-axis jerk rows."""
    bb = max(b, 1e-300)
    root = math.sqrt(bb)
    n = 0
    for sign in (1.0, -1.0):
        rows[n, 0] = sign
        rows[n, 1] = 0.0
        rows[n, 2] = 2.0 * acc_t
        n += 1
    for x in range(3):
        if acc_x[x] < np.inf:
            for sign in (1.0, -1.0):
                rows[n, 0] = sign * 0.5 * geo[G_T + x]
                rows[n, 1] = sign * geo[G_K + x]
                rows[n, 2] = acc_x[x]
                n += 1
    # normal jerk: |1.5 kappa b' + kn b| <= sqrt(rho^2 - (kb b)^2)
    k = geo[G_KAPPA]
    jump = math.sqrt(geo[G_D] ** 2 + geo[G_D + 1] ** 2 + geo[G_D + 2] ** 2)
    rho = max(jerk_n / root - bb * jump / period, 0.0)
    ksx = geo[G_KS] + k * k * geo[G_T]
    ksy = geo[G_KS + 1] + k * k * geo[G_T + 1]
    ksz = geo[G_KS + 2] + k * k * geo[G_T + 2]
    if k > 0.0:
        nx, ny, nz = geo[G_K] / k, geo[G_K + 1] / k, geo[G_K + 2] / k
        kn = ksx * nx + ksy * ny + ksz * nz
        rx, ry, rz = ksx - kn * nx, ksy - kn * ny, ksz - kn * nz
        kb = math.sqrt(rx * rx + ry * ry + rz * rz)
        room = math.sqrt(max(rho * rho - (kb * bb) ** 2, 0.0))
        for sign in (1.0, -1.0):
            rows[n, 0] = sign * 1.5 * k
            rows[n, 1] = sign * kn
            rows[n, 2] = room
            n += 1
    for x in range(3):
        tx = geo[G_T + x]
        if abs(tx) >= ALONG or jerk_x[x] == np.inf:
            continue
        rho_x = max(jerk_x[x] / root - bb * abs(geo[G_D + x]) / period, 0.0)
        for sign in (1.0, -1.0):
            rows[n, 0] = sign * 1.5 * geo[G_K + x]
            rows[n, 1] = sign * geo[G_KS + x]
            rows[n, 2] = rho_x - sign * 0.5 * tx * dd
            n += 1
    return n


@jit
def slope_passes(c, knots, kgeo, acc_t, acc_x, jerk_n, jerk_x, period, first, last, kdd):
    """Forward and backward over the knots of one stretch (coefficients first..last): knot j
    between c_{first+j} and c_{first+j+1}; kgeo (J, 2, G): both sides' geometry; knots (J, 2):
    g, w; kdd (J, 2): frozen b'' on each side."""
    rows = np.empty((16, 3))
    change = 0.0
    nk = last - first
    for direction in range(2):
        for step in range(nk):
            j = step if direction == 0 else nk - 1 - step
            i = first + j
            g, w = knots[j, 0], knots[j, 1]
            for side in range(2):
                b = w * c[i] + (1.0 - w) * c[i + 1]
                d = (c[i + 1] - c[i]) / g
                n = knot_rows(kgeo[j, side], b, d, kdd[j, side], acc_t, acc_x, jerk_n, jerk_x,
                              period, rows)
                for r in range(n):
                    alpha, beta, gamma = rows[r, 0], rows[r, 1], rows[r, 2]
                    ca = -alpha / g + beta * w
                    cb = alpha / g + beta * (1.0 - w)
                    have = ca * c[i] + cb * c[i + 1]
                    if have <= gamma:
                        continue
                    if ca > 0.0 and cb > 0.0:
                        shrink = max(gamma / have, 0.0)
                        change = max(change, 1.0 - shrink)
                        c[i] *= shrink
                        c[i + 1] *= shrink
                    elif direction == 0 and cb > 0.0:
                        most = max((gamma - ca * c[i]) / cb, 0.0)
                        change = max(change, (c[i + 1] - most) / max(c[i + 1], TINY))
                        c[i + 1] = most
                    elif direction == 1 and ca > 0.0:
                        most = max((gamma - cb * c[i + 1]) / ca, 0.0)
                        change = max(change, (c[i] - most) / max(c[i], TINY))
                        c[i] = most
                    b = w * c[i] + (1.0 - w) * c[i + 1]
                    d = (c[i + 1] - c[i]) / g
                    n = knot_rows(kgeo[j, side], b, d, kdd[j, side], acc_t, acc_x, jerk_n,
                                  jerk_x, period, rows)
    return change


@jit
def convex_pass(xi, c, width, lo, first, last, phi, hull):
    """b'' >= lo (per coefficient first+1..last-1): c <= phi + lower convex hull of c - phi."""
    if last - first < 2:
        return 0.0
    phi[first] = 0.0
    slope = 0.0
    for i in range(first, last):
        if i > first:
            slope += lo[i] * width[i]
        phi[i + 1] = phi[i] + slope * (xi[i + 1] - xi[i])
    top = 0
    for i in range(first, last + 1):
        while top >= 2:
            a, m = hull[top - 2], hull[top - 1]
            ga, gm, gi = c[a] - phi[a], c[m] - phi[m], c[i] - phi[i]
            if (gm - ga) * (xi[i] - xi[a]) >= (gi - ga) * (xi[m] - xi[a]):
                top -= 1
            else:
                break
        hull[top] = i
        top += 1
    change = 0.0
    k = 0
    for i in range(first, last + 1):
        while k < top - 2 and hull[k + 1] <= i:
            k += 1
        a, m = hull[k], hull[k + 1]
        if i == a:
            continue
        t = (xi[i] - xi[a]) / (xi[m] - xi[a])
        most = max(phi[i] + (1.0 - t) * (c[a] - phi[a]) + t * (c[m] - phi[m]), 0.0)
        if most < c[i]:
            change = max(change, (c[i] - most) / max(c[i], TINY))
            c[i] = most
    return change


@jit
def rest_pass(c, r0, r1, first, last):
    change = 0.0
    for end, inner, r in ((first, first + 1, r0), (last, last - 1, r1)):
        if c[inner] > r * c[end]:
            change = max(change, (c[inner] - r * c[end]) / max(c[inner], TINY))
            c[inner] = r * c[end]
        if c[end] > c[inner] / r:
            change = max(change, (c[end] - c[inner] / r) / max(c[end], TINY))
            c[end] = c[inner] / r
    return change


@jit
def _u_at(c, cells, geo, q, lim_t, lim_x, period, k_new, value):
    """U of cell q with coefficient k_new set to value."""
    old = c[k_new]
    c[k_new] = value
    i0 = int(cells[q, 0])
    g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
    hi = np.inf
    for p in range(3):
        b, d, _ = point_values(c, i0, g0, g1, w0, h, 0.5 * p)
        _, e = curv_bounds(geo[q, p], b, d, lim_t, lim_x, period)
        hi = min(hi, e)
    c[k_new] = old
    return hi


@jit
def valley_pass(xi, c, cells, geo, lim_t, lim_x, period, first, last, cell0, tol):
    """b'' <= U outward from every vertex that curves up too fast: where c rises, forward;
    where it falls, backward; at a minimum both ways, each side half the room. U is evaluated
    at the profile being built (predictor-corrector). cell0: the global index of the stretch's
    first inner cell; coefficient first+1+j is the middle of inner cell cell0+j."""
    change = 0.0
    nin = last - first - 1  # inner cells
    # minima first
    for j in range(nin):
        m = first + 1 + j
        q = cell0 + j
        g0, g1 = xi[m] - xi[m - 1], xi[m + 1] - xi[m]
        h = cells[q, 4]
        if not (c[m] <= c[m - 1] and c[m] <= c[m + 1]):
            continue
        curv = ((c[m + 1] - c[m]) / g1 - (c[m] - c[m - 1]) / g0) / h
        # U at the bottom with both sides at half the room
        u0 = _u_at(c, cells, geo, q, lim_t, lim_x, period, m, c[m])
        if curv <= u0 * (1.0 + tol):
            continue
        for _ in range(3):
            room = max(u0, 0.0) * h
            lft = c[m] + 0.5 * room * g0
            rgt = c[m] + 0.5 * room * g1
            save_l, save_r = c[m - 1], c[m + 1]
            c[m - 1] = min(save_l, lft)
            c[m + 1] = min(save_r, rgt)
            u1 = _u_at(c, cells, geo, q, lim_t, lim_x, period, m, c[m])
            c[m - 1], c[m + 1] = save_l, save_r
            if abs(u1 - u0) <= 1e-6 * abs(u0):
                break
            u0 = u1
        room = max(u0, 0.0) * h
        for side in range(2):
            slope = 0.5 * room
            prev = m
            jj = j
            while True:
                nxt = prev + 1 if side == 0 else prev - 1
                if nxt < first or nxt > last:
                    break
                gap = abs(xi[nxt] - xi[prev])
                cap = c[prev] + max(slope, 0.0) * gap
                if cap >= c[nxt]:
                    break
                change = max(change, (c[nxt] - cap) / max(c[nxt], TINY))
                c[nxt] = cap
                # next cell's U: the cell whose middle coefficient is nxt
                jj = jj + 1 if side == 0 else jj - 1
                if jj < 0 or jj >= nin:
                    break
                q2 = cell0 + jj
                # predictor: the next coefficient continues the slope
                far = nxt + 1 if side == 0 else nxt - 1
                if far < first or far > last:
                    break
                g_far = abs(xi[far] - xi[nxt])
                guess = min(c[far], c[nxt] + max(slope, 0.0) * g_far)
                u = _u_at(c, cells, geo, q2, lim_t, lim_x, period, far, guess)
                slope += max(u, 0.0) * cells[q2, 4]
                prev = nxt
    # rising: forward; falling: backward
    for j in range(nin):
        m = first + 1 + j
        q = cell0 + j
        g0, g1 = xi[m] - xi[m - 1], xi[m + 1] - xi[m]
        h = cells[q, 4]
        if c[m - 1] <= c[m] <= c[m + 1]:
            s0 = (c[m] - c[m - 1]) / g0
            guess = min(c[m + 1], c[m] + s0 * g1)
            u = _u_at(c, cells, geo, q, lim_t, lim_x, period, m + 1, guess)
            most = c[m] + g1 * (s0 + max(u, 0.0) * h)
            if most < c[m + 1]:
                change = max(change, (c[m + 1] - most) / max(c[m + 1], TINY))
                c[m + 1] = max(most, c[m])
    for j in range(nin - 1, -1, -1):
        m = first + 1 + j
        q = cell0 + j
        g0, g1 = xi[m] - xi[m - 1], xi[m + 1] - xi[m]
        h = cells[q, 4]
        if c[m - 1] >= c[m] >= c[m + 1]:
            s1 = (c[m] - c[m + 1]) / g1
            guess = min(c[m - 1], c[m] + s1 * g0)
            u = _u_at(c, cells, geo, q, lim_t, lim_x, period, m - 1, guess)
            most = c[m] + g0 * (s1 + max(u, 0.0) * h)
            if most < c[m - 1]:
                change = max(change, (c[m - 1] - most) / max(c[m - 1], TINY))
                c[m - 1] = max(most, c[m])
    return change


@jit
def point_ratio(geo, b, d, dd, lim_t, acc_t, jerk_n, acc_x, vel_x, jerk_x, period):
    """The motion ratio lambda at one point with (b, b', b''): the slowdown that keeps all."""
    bb = max(b, 0.0)
    root = math.sqrt(bb)
    k = geo[G_KAPPA]
    r = 0.0
    if geo[G_CAP] < np.inf:
        r = max(r, math.sqrt(bb / geo[G_CAP]) if geo[G_CAP] > 0.0 else (np.inf if bb > 0 else 0.0))
    r = max(r, math.sqrt(abs(d) / (2.0 * acc_t)))
    jt = root * (0.5 * dd - k * k * bb)
    r = max(r, (abs(jt) / lim_t) ** (1.0 / 3.0))
    jump = math.sqrt(geo[G_D] ** 2 + geo[G_D + 1] ** 2 + geo[G_D + 2] ** 2)
    nx = 1.5 * d * geo[G_K] + bb * (geo[G_KS] + k * k * geo[G_T])
    ny = 1.5 * d * geo[G_K + 1] + bb * (geo[G_KS + 1] + k * k * geo[G_T + 1])
    nz = 1.5 * d * geo[G_K + 2] + bb * (geo[G_KS + 2] + k * k * geo[G_T + 2])
    jn = root * math.sqrt(nx * nx + ny * ny + nz * nz) + bb * jump / period
    r = max(r, (jn / jerk_n) ** (1.0 / 3.0))
    for x in range(3):
        ax = abs(0.5 * d * geo[G_T + x] + bb * geo[G_K + x])
        if acc_x[x] < np.inf:
            r = max(r, math.sqrt(ax / acc_x[x]))
        if vel_x[x] < np.inf:
            r = max(r, root * abs(geo[G_T + x]) / vel_x[x])
        if jerk_x[x] < np.inf:
            jx = abs(root * (0.5 * dd * geo[G_T + x] + 1.5 * d * geo[G_K + x]
                             + bb * geo[G_KS + x])) + bb * abs(geo[G_D + x]) / period
            r = max(r, (jx / jerk_x[x]) ** (1.0 / 3.0))
    return r


@jit
def cell_ratios(c, cells, geo, lim_t, acc_t, jerk_n, acc_x, vel_x, jerk_x, period, out):
    for q in range(cells.shape[0]):
        i0 = int(cells[q, 0])
        g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
        worst = 0.0
        for p in range(3):
            b, d, dd = point_values(c, i0, g0, g1, w0, h, 0.5 * p)
            worst = max(worst, point_ratio(geo[q, p], b, d, dd, lim_t, acc_t, jerk_n, acc_x,
                                           vel_x, jerk_x, period))
        out[q] = worst


@jit
def lift_pass(xi, c, width, lo_axes, kappa2, jerk, first, last):
    """b'' >= max(lo_axes, 2 kappa^2 b - 2 J / sqrt(b)) per inner coefficient, b the coefficient
    itself (bisection), forward then backward."""
    change = 0.0
    for direction in range(2):
        for step in range(last - first - 1):
            i = first + 1 + step if direction == 0 else last - 1 - step
            g0, g1 = xi[i] - xi[i - 1], xi[i + 1] - xi[i]
            pull = c[i - 1] / g0 + c[i + 1] / g1
            weight = 1.0 / g0 + 1.0 / g1
            x = c[i]
            if (pull - x * weight) / width[i] >= max(
                    lo_axes[i], 2.0 * kappa2[i] * x - 2.0 * jerk / math.sqrt(max(x, 1e-300))):
                continue
            low, high = 0.0, x
            for _ in range(50):
                mid = 0.5 * (low + high)
                if (pull - mid * weight) / width[i] >= max(
                        lo_axes[i], 2.0 * kappa2[i] * mid - 2.0 * jerk / math.sqrt(max(mid, 1e-300))):
                    low = mid
                else:
                    high = mid
                if high - low <= 1e-10 * x:
                    break
            change = max(change, (c[i] - low) / max(c[i], TINY))
            c[i] = low
    return change


@jit
def axis_lo(c, cells, geo, lim_x, period, lo_out, k2_out):
    """Per inner cell: the along-axis rows' L (frozen b, b') and the largest kappa^2."""
    for q in range(cells.shape[0]):
        i0 = int(cells[q, 0])
        g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
        lo = -np.inf
        k2 = 0.0
        for p in range(3):
            b, d, _ = point_values(c, i0, g0, g1, w0, h, 0.5 * p)
            g = geo[q, p]
            k2 = max(k2, g[G_KAPPA] ** 2)
            a, _ = curv_bounds(g, b, d, 0.0 + 1e300, lim_x, period)
            lo = max(lo, a)
        lo_out[q] = lo
        k2_out[q] = k2


@jit
def _row_bound(kgeo, g, w, ca_fixed, cb_var, acc_t, acc_x, jerk_n, jerk_x, period, dd,
               forward, rows):
    """The greatest value of the free coefficient at one knot side keeping every knot row,
    the other coefficient fixed (forward: c_i fixed = ca_fixed, c_i+1 free, start cb_var;
    backward: c_i+1 fixed, c_i free). Two fixed-point rounds for sqrt(b) in the budgets."""
    x = cb_var
    for _ in range(3):
        if forward:
            ci, cj = ca_fixed, x
        else:
            ci, cj = x, ca_fixed
        b = w * ci + (1.0 - w) * cj
        d = (cj - ci) / g
        n = knot_rows(kgeo, b, d, dd, acc_t, acc_x, jerk_n, jerk_x, period, rows)
        most = x
        for r in range(n):
            alpha, beta, gamma = rows[r, 0], rows[r, 1], rows[r, 2]
            ca = -alpha / g + beta * w
            cb = alpha / g + beta * (1.0 - w)
            if forward:
                if cb > 0.0:
                    most = min(most, max((gamma - ca * ci) / cb, 0.0))
            else:
                if ca > 0.0:
                    most = min(most, max((gamma - cb * cj) / ca, 0.0))
        if most >= x * (1.0 - 1e-12):
            return x
        x = most
    return x


@jit
def sweep_pass(xi, c, width, cells, geo, knots, kgeo, kdd, lim_t, acc_t, acc_x, jerk_n,
               jerk_x, period, first, last, cell0, knot0, with_u):
    """Forward then backward over one stretch: each step lowers the coefficient ahead to the
    greatest value that the knot rows (accelerations, normal jerk, cross-axis jerk) allow
    from the one behind and, with_u, that the vertex behind it curves up no faster than U
    (where the profile rises into it going this way, or at a minimum with half the room)."""
    rows = np.empty((16, 3))
    change = 0.0
    for direction in range(2):
        forward = direction == 0
        for step in range(last - first):
            if forward:
                k = first + step  # knot between c_k and c_k+1; c_k+1 free
                j = k - first
                ahead = k + 1
                behind = k
                vertex = k
                prev_c = c[k - 1] if k > first else np.inf
            else:
                k = last - 1 - step  # knot between c_k and c_k+1; c_k free
                j = k - first
                ahead = k
                behind = k + 1
                vertex = k + 1
                prev_c = c[k + 2] if k + 1 < last else np.inf
            g, w = knots[knot0 + j, 0], knots[knot0 + j, 1]
            most = c[ahead]
            for side in range(2):
                most = _row_bound(kgeo[knot0 + j, side], g, w, c[behind], most, acc_t,
                                  acc_x, jerk_n, jerk_x, period, kdd[knot0 + j, side],
                                  forward, rows)
            if with_u and first < vertex < last and prev_c != np.inf:
                q = cell0 + vertex - first - 1
                gv_in = xi[vertex] - xi[vertex - 1] if forward else xi[vertex + 1] - xi[vertex]
                gv_out = g
                slope_in = (c[vertex] - prev_c) / gv_in  # rising into the vertex this way
                minimum = prev_c > c[vertex]
                for _ in range(2):
                    u = _u_at(c, cells, geo, q, lim_t, jerk_x, period, ahead, most)
                    room = max(u, 0.0) * width[vertex]
                    if minimum:
                        bound = c[vertex] + 0.5 * room * gv_out
                    else:
                        bound = c[vertex] + gv_out * (slope_in + room)
                    if bound >= most:
                        break
                    most = max(bound, 0.0)
            if most < c[ahead]:
                change = max(change, (c[ahead] - most) / max(c[ahead], TINY))
                c[ahead] = most
    return change


@jit
def _step_bounds(kgeo2, g, w, fixed, free_start, acc_t, acc_x, jerk_n, jerk_x, period, dd2,
                 forward, rows):
    """At one knot (both sides' geometry kgeo2 (2, G), frozen b'' dd2 (2,)), with one
    coefficient fixed: (hi, lo) on the free one from every knot row: hi the least upper bound
    (rows that lower it), lo the greatest lower bound (rows it cannot meet by falling). sqrt(b)
    in the budgets at free = hi (fixed point, 3 rounds)."""
    x = free_start
    lo = 0.0
    for _ in range(3):
        hi = x
        lo = 0.0
        for side in range(2):
            if forward:
                ci, cj = fixed, x
            else:
                ci, cj = x, fixed
            b = w * ci + (1.0 - w) * cj
            d = (cj - ci) / g
            n = knot_rows(kgeo2[side], b, d, dd2[side], acc_t, acc_x, jerk_n, jerk_x, period,
                          rows)
            for r in range(n):
                alpha, beta, gamma = rows[r, 0], rows[r, 1], rows[r, 2]
                ca = -alpha / g + beta * w
                cb = alpha / g + beta * (1.0 - w)
                cf, co = (cb, ca) if forward else (ca, cb)  # free, fixed weights
                if cf > 0.0:
                    hi = min(hi, (gamma - co * fixed) / cf)
                elif cf < 0.0:
                    lo = max(lo, (gamma - co * fixed) / cf)
                elif co * fixed > gamma:
                    lo = np.inf
        if hi >= x * (1.0 - 1e-12):
            return x, lo
        x = max(hi, 0.0)
    return x, lo


@jit
def shoot_side(ceil, xi, width, cells, geo, knots, kgeo, kdd, lim_t, acc_t, acc_x, jerk_n,
               jerk_x, period, first, last, cell0, knot0, m, b_m, first_slope, forward, out,
               max_steps):
    """From coefficient m at b_m, outward (forward: to the right) as high as the ceiling, U and
    the knot rows allow; out receives the values (out[m] = b_m). first_slope: the slope out of
    m, or NaN for a minimum (half of U's room at m). Returns (ok, last index written): not ok
    where a knot row asks the free coefficient for more than the others allow (a lower bound
    on how fast b must change that the curve cannot meet)."""
    rows = np.empty((16, 3))
    out[m] = b_m
    k = m
    slope = 0.0
    steps = 0
    merged = 0
    while steps < max_steps:
        nxt = k + 1 if forward else k - 1
        if nxt < first or nxt > last:
            return True, k
        j = (k if forward else nxt) - first  # the knot between k and nxt
        g, w = knots[knot0 + j, 0], knots[knot0 + j, 1]
        hi = ceil[nxt]
        if k == m:
            if first_slope == first_slope:
                hi = min(hi, out[m] + first_slope * g)
            elif first < m < last:
                q = cell0 + m - first - 1
                for _ in range(2):
                    u = _u_at(out, cells, geo, q, lim_t, jerk_x, period, nxt, hi)
                    bound = out[m] + 0.5 * max(u, 0.0) * width[m] * g
                    if bound >= hi:
                        break
                    hi = bound
        elif first < k < last:
            q = cell0 + k - first - 1
            for _ in range(2):
                u = _u_at(out, cells, geo, q, lim_t, jerk_x, period, nxt, hi)
                bound = out[k] + g * (slope + max(u, 0.0) * width[k])
                if bound >= hi:
                    break
                hi = bound
        hi = max(hi, 0.0)
        top, lo = _step_bounds(kgeo[knot0 + j], g, w, out[k], hi, acc_t, acc_x, jerk_n,
                               jerk_x, period, kdd[knot0 + j], forward, rows)
        if top < lo * (1.0 - 1e-9):
            return False, k
        out[nxt] = top
        slope = (top - out[k]) / g
        if top >= ceil[nxt] * (1.0 - 1e-12):
            merged += 1
            if merged >= 2:
                return True, nxt
        else:
            merged = 0
        k = nxt
        steps += 1
    return True, k


@jit
def p_hull(xi, u, width, p, q, first, last, c, active, a_, b_, d_, r_, max_iter, warm=False):
    """The greatest c <= u (coefficients first..last) with, at every inner coefficient k,
    curv_k(c) - p_k c_k >= q_k (p >= 0): a tridiagonal M-matrix obstacle problem, solved by a
    primal-dual active set (Thomas' algorithm per iteration). The ends stay at u. Returns the
    iterations taken (max_iter + 1 if not converged)."""
    n = last - first + 1
    if warm:
        changed = True
        active[first] = True
        active[last] = True
    else:
        for k in range(first, last + 1):
            c[k] = u[k]
            active[k] = True
        changed = False
    # start: inactive where the constraint fails at the obstacle
    for k in range(first + 1, last):
        if warm:
            break
        g0, g1 = xi[k] - xi[k - 1], xi[k + 1] - xi[k]
        curv = (u[k - 1] / g0 - u[k] * (1.0 / g0 + 1.0 / g1) + u[k + 1] / g1) / width[k]
        if curv - p[k] * u[k] < q[k]:
            active[k] = False
            changed = True
    if not changed:
        return 0
    for it in range(max_iter):
        # assemble: rows k (local index j = k - first): a_ c_{k-1} + b_ c_k + d_ c_{k+1} = r_
        for k in range(first, last + 1):
            j = k - first
            if active[k]:
                a_[j] = 0.0
                b_[j] = 1.0
                d_[j] = 0.0
                r_[j] = u[k]
            else:
                g0, g1 = xi[k] - xi[k - 1], xi[k + 1] - xi[k]
                w = width[k]
                a_[j] = 1.0 / (g0 * w)
                d_[j] = 1.0 / (g1 * w)
                b_[j] = -(a_[j] + d_[j]) - p[k]
                r_[j] = q[k]
        # Thomas
        for j in range(1, n):
            m = a_[j] / b_[j - 1]
            b_[j] -= m * d_[j - 1]
            r_[j] -= m * r_[j - 1]
        c[last] = r_[n - 1] / b_[n - 1]
        for j in range(n - 2, -1, -1):
            c[first + j] = (r_[j] - d_[j] * c[first + j + 1]) / b_[j]
        changed = False
        for k in range(first + 1, last):
            if active[k]:
                g0, g1 = xi[k] - xi[k - 1], xi[k + 1] - xi[k]
                curv = (c[k - 1] / g0 - c[k] * (1.0 / g0 + 1.0 / g1) + c[k + 1] / g1) / width[k]
                if curv - p[k] * c[k] < q[k] * (1.0 + 1e-12) - 1e-12 * abs(q[k]) and curv - p[k] * c[k] < q[k]:
                    active[k] = False
                    changed = True
            elif c[k] > u[k]:
                active[k] = True
                changed = True
        if not changed:
            for k in range(first, last + 1):
                c[k] = min(max(c[k], 0.0), u[k])
            return it + 1
    for k in range(first, last + 1):
        c[k] = min(max(c[k], 0.0), u[k])
    return max_iter + 1


@jit
def linearized_lo(c, cells, geo, lim_t, lim_x, period, cell0, p_out, q_out, first, last):
    """Per inner coefficient k (cell cell0 + k - first - 1): L(c_k) ~ p_k c_k + q_k, the
    tangent at the current c of the largest L over the cell's points, with b at a point taken
    as r c_k (r = b_point / c_k now): tangential 2 kappa^2 b - 2 J / sqrt(b) (concave: its
    tangent lies above it), along-axis rows with b' frozen."""
    for k in range(first + 1, last):
        q = cell0 + k - first - 1
        i0 = int(cells[q, 0])
        g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
        x = max(c[k], 1e-20)
        best = -np.inf
        bp = 0.0
        bq = 0.0
        for pt in range(3):
            b, d, _ = point_values(c, i0, g0, g1, w0, h, 0.5 * pt)
            b = max(b, 1e-20)
            r = b / x
            g = geo[q, pt]
            kap = g[G_KAPPA]
            root = math.sqrt(b)
            val = 2.0 * kap * kap * b - 2.0 * lim_t / root
            if val > best:
                best = val
                # d/dc_k of L(r c_k) = r (2 kappa^2 + J / b^1.5)
                slope = r * (2.0 * kap * kap + lim_t / (b * root))
                bp = slope
                bq = val - slope * x
            for ax in range(3):
                tx = g[G_T + ax]
                if abs(tx) < ALONG or lim_x[ax] == np.inf:
                    continue
                rho = max(lim_x[ax] / root - b * abs(g[G_D + ax]) / period, 0.0)
                rr = 1.5 * d * g[G_K + ax] + b * g[G_KS + ax]
                lo1 = 2.0 * (-rho - rr) / tx
                lo2 = 2.0 * (rho - rr) / tx
                v = min(lo1, lo2)
                if v > best:
                    best = v
                    bp = 0.0
                    bq = v
        p_out[k] = max(bp, 0.0)
        q_out[k] = best - max(bp, 0.0) * x


@jit
def slope_interval(geo, b, acc_t, acc_x, jerk_n, jerk_x, period, rows):
    """The interval [lo, hi] of b' that every knot row allows at this b (b'' = 0)."""
    n = knot_rows(geo, b, 0.0, 0.0, acc_t, acc_x, jerk_n, jerk_x, period, rows)
    lo = -np.inf
    hi = np.inf
    for r in range(n):
        alpha, beta, gamma = rows[r, 0], rows[r, 1], rows[r, 2]
        if alpha > 0.0:
            hi = min(hi, (gamma - beta * b) / alpha)
        elif alpha < 0.0:
            lo = max(lo, (gamma - beta * b) / alpha)
        elif beta * b > gamma:
            return 1.0, -1.0
    return lo, hi


@jit
def _knot_interval(kgeo2, b, acc_t, acc_x, jerk_n, jerk_x, period, rows):
    lo = -np.inf
    hi = np.inf
    for side in range(2):
        a, e = slope_interval(kgeo2[side], b, acc_t, acc_x, jerk_n, jerk_x, period, rows)
        lo = max(lo, a)
        hi = min(hi, e)
    return lo, hi


@jit
def feasibility_caps(kgeo, cap, acc_t, acc_x, jerk_n, jerk_x, period, out):
    """Per knot (J,): the greatest b <= cap at which some slope keeps every knot row of both
    sides."""
    rows = np.empty((16, 3))
    for j in range(kgeo.shape[0]):
        top = cap[j]
        lo, hi = _knot_interval(kgeo[j], top, acc_t, acc_x, jerk_n, jerk_x, period, rows)
        if lo <= hi:
            out[j] = top
            continue
        low, high = 0.0, top
        for _ in range(60):
            mid = 0.5 * (low + high)
            lo, hi = _knot_interval(kgeo[j], mid, acc_t, acc_x, jerk_n, jerk_x, period, rows)
            if lo <= hi:
                low = mid
            else:
                high = mid
            if high - low <= 1e-12 * top:
                break
        out[j] = low


@jit
def frozen_bounds(c, xi, width, cells, geo, knots, kgeo, lim_t, acc_t, acc_x, jerk_n, jerk_x,
                  period, first, last, cell0, knot0, lo, hi, rl, ru):
    """At the profile c: per knot k (first..last-1) the slope interval [lo_k, hi_k] the knot
    rows allow at its b (both sides), per inner coefficient k the rate interval [rl_k, ru_k]
    (L w, U w) of its cell."""
    rows = np.empty((16, 3))
    for k in range(first, last):
        j = k - first
        g, w = knots[knot0 + j, 0], knots[knot0 + j, 1]
        b = max(w * c[k] + (1.0 - w) * c[k + 1], 0.0)
        lo_k = -np.inf
        hi_k = np.inf
        for side in range(2):
            a, e = slope_interval(kgeo[knot0 + j, side], b, acc_t, acc_x, jerk_n, jerk_x, period,
                                  rows)
            lo_k = max(lo_k, a)
            hi_k = min(hi_k, e)
        lo[k] = lo_k
        hi[k] = hi_k
    for k in range(first + 1, last):
        q = cell0 + k - first - 1
        i0 = int(cells[q, 0])
        g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
        lo_c = -np.inf
        hi_c = np.inf
        for p in range(3):
            b, d, _ = point_values(c, i0, g0, g1, w0, h, 0.5 * p)
            a, e = curv_bounds(geo[q, p], b, d, lim_t, jerk_x, period)
            lo_c = max(lo_c, a)
            hi_c = min(hi_c, e)
        rl[k] = lo_c * width[k]
        ru[k] = hi_c * width[k]


@jit
def segment_total(F, G, H, theta, gaps, a, e):
    total = 0.0
    for k in range(a, e):
        s = min(F[k], H[k] - theta)
        if s < G[k]:
            s = G[k]
        total += s * gaps[k]
    return total


@jit
def solve_segment(lo, hi, rl, ru, gaps, a, e, s_start, s_end, delta, F, G, H, out):
    """Slopes sigma_a .. sigma_{e-1} (knots a..e-1) between two keys: as high as the bounds
    allow early, as low as they allow late, their sum (weighted by the gaps) delta.
    s_start: the first slope's upper bound (the key's half room), s_end: the last slope's
    lower bound (minus the next key's half room). rl, ru: per vertex k (between slopes k-1 and
    k) the rate interval. Returns status: 0 ok, 1 the sum cannot reach delta (the right key is
    too high), 2 the sum cannot go down to delta (the left key is too high), 3 no slopes fit
    between the bounds (F < G somewhere)."""
    # F: greatest slopes from the start under hi, rising at most ru, falling at most -rl
    for k in range(a, e):
        top = hi[k]
        if k == a:
            top = min(top, s_start)
        else:
            top = min(top, F[k - 1] + ru[k])
        F[k] = top
    for k in range(e - 1, a, -1):
        F[k - 1] = min(F[k - 1], F[k] - rl[k])
    # G: least slopes into the end over lo
    for k in range(e - 1, a - 1, -1):
        bot = lo[k]
        if k == e - 1:
            bot = max(bot, s_end)
        else:
            bot = max(bot, G[k + 1] - ru[k + 1])
        G[k] = bot
    for k in range(a + 1, e):
        G[k] = max(G[k], G[k - 1] + rl[k])
    for k in range(a, e):
        if F[k] < G[k] - 1e-12 * max(abs(G[k]), 1.0):
            return 3
    # H: the latest fall onto G
    H[e - 1] = G[e - 1]
    for k in range(e - 1, a, -1):
        H[k - 1] = min(hi[k - 1], H[k] - rl[k])
    t_max = segment_total(F, G, H, 0.0, gaps, a, e)
    if t_max < delta:
        for k in range(a, e):
            out[k] = max(G[k], min(F[k], H[k]))
        return 1
    t_min = 0.0
    for k in range(a, e):
        t_min += G[k] * gaps[k]
    if t_min > delta:
        for k in range(a, e):
            out[k] = G[k]
        return 2
    # theta: lowering H shifts the fall earlier; the sum falls monotonically with theta
    lo_t = 0.0
    span = 0.0
    for k in range(a, e):
        span = max(span, F[k] - G[k])
    hi_t = 0.0
    for k in range(a, e):
        hi_t = max(hi_t, H[k] - G[k])
    hi_t += 1.0
    for _ in range(100):
        mid = 0.5 * (lo_t + hi_t)
        if segment_total(F, G, H, mid, gaps, a, e) > delta:
            lo_t = mid
        else:
            hi_t = mid
        if hi_t - lo_t <= 1e-13 * max(hi_t, 1e-300):
            break
    theta = hi_t
    total = 0.0
    for k in range(a, e):
        s = min(F[k], H[k] - theta)
        if s < G[k]:
            s = G[k]
        out[k] = s
        total += s * gaps[k]
    # the rounding left over goes to the slope with the most room (the plateau's last)
    return 0


@jit
def frozen_bounds_range(c, xi, width, cells, geo, knots, kgeo, lim_t, acc_t, acc_x, jerk_n,
                        jerk_x, period, first, last, cell0, knot0, lo, hi, rl, ru, a, e):
    """`frozen_bounds` on knots a..e-1 and vertices a+1..e-1 only."""
    rows = np.empty((16, 3))
    for k in range(max(a, first), min(e, last)):
        j = k - first
        g, w = knots[knot0 + j, 0], knots[knot0 + j, 1]
        b = max(w * c[k] + (1.0 - w) * c[k + 1], 0.0)
        lo_k = -np.inf
        hi_k = np.inf
        for side in range(2):
            lo2, hi2 = slope_interval(kgeo[knot0 + j, side], b, acc_t, acc_x, jerk_n, jerk_x,
                                      period, rows)
            lo_k = max(lo_k, lo2)
            hi_k = min(hi_k, hi2)
        lo[k] = lo_k
        hi[k] = hi_k
    for k in range(max(a, first + 1), min(e + 1, last)):
        q = cell0 + k - first - 1
        i0 = int(cells[q, 0])
        g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
        lo_c = -np.inf
        hi_c = np.inf
        for p in range(3):
            b, d, _ = point_values(c, i0, g0, g1, w0, h, 0.5 * p)
            lo2, hi2 = curv_bounds(geo[q, p], b, d, lim_t, jerk_x, period)
            lo_c = max(lo_c, lo2)
            hi_c = min(hi_c, hi2)
        rl[k] = lo_c * width[k]
        ru[k] = hi_c * width[k]


@jit
def point_weights(i0, g0, g1, w0, h, x, out):
    """Weights (3, 3) of the three coefficients c_i0..c_i0+2 in b, b', b'' at share x of an
    inner cell: out[0] for b, out[1] for b', out[2] for b''."""
    # s0 = (c1 - c0)/g0, s1 = (c2 - c1)/g1, dd = (s1 - s0)/h, b0 = w0 c0 + (1-w0) c1
    xs = x * h
    s0 = (-1.0 / g0, 1.0 / g0, 0.0)
    s1 = (0.0, -1.0 / g1, 1.0 / g1)
    for j in range(3):
        dd = (s1[j] - s0[j]) / h
        b0 = (w0 if j == 0 else (1.0 - w0) if j == 1 else 0.0)
        out[0, j] = b0 + s0[j] * xs + 0.5 * dd * xs * xs
        out[1, j] = s0[j] + dd * xs
        out[2, j] = dd


@jit
def lp_rows(c_lin, cells, geo, lim_t, acc_t, jerk_n, acc_x, jerk_x, period, rows_idx, rows_val,
            rows_rhs, points):
    """Linearized inequality rows (R,) over the coefficients, three per row: at each inner cell
    and each point of `points`: b <= cap, |b'| <= 2 A_t, |0.5 T_x b' + K_x b| <= A_x, and the
    jerk rows with J / sqrt(b) replaced by its tangent at b_lin (below it: conservative):
    |0.5 b'' - kappa^2 b| <= J (1.5 - 0.5 b / b0) / sqrt(b0), each axis's and the normal jerk's
    (N and B: two rows each way, 3-D adds two). Returns the row count."""
    W = np.empty((3, 3))
    r = 0
    for q in range(cells.shape[0]):
        i0 = int(cells[q, 0])
        g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
        for pi in range(points.size):
            x = points[pi]
            point_weights(i0, g0, g1, w0, h, x, W)
            b0 = 0.0
            for j in range(3):
                b0 += W[0, j] * c_lin[i0 + j]
            b0 = max(b0, 1e-12)
            root = math.sqrt(b0)
            g = geo[q, int(round(2 * x))]
            k = g[G_KAPPA]
            # cap
            for j in range(3):
                rows_idx[r] = i0
                rows_val[r, j] = W[0, j]
            rows_rhs[r] = g[G_CAP]
            r += 1
            for sign in (1.0, -1.0):
                for j in range(3):
                    rows_val[r, j] = sign * W[1, j]
                rows_idx[r] = i0
                rows_rhs[r] = 2.0 * acc_t
                r += 1
            for ax in range(3):
                if acc_x[ax] < np.inf and (g[G_T + ax] != 0.0 or g[G_K + ax] != 0.0):
                    for sign in (1.0, -1.0):
                        for j in range(3):
                            rows_val[r, j] = sign * (0.5 * g[G_T + ax] * W[1, j] + g[G_K + ax] * W[0, j])
                        rows_idx[r] = i0
                        rows_rhs[r] = acc_x[ax]
                        r += 1
            # tangential jerk, tangent of J / sqrt(b): J (1.5 - 0.5 b / b0) / sqrt(b0)
            slope_t = 0.5 * lim_t / (b0 * root)
            for sign in (1.0, -1.0):
                for j in range(3):
                    rows_val[r, j] = sign * (0.5 * W[2, j] - k * k * W[0, j]) + slope_t * W[0, j]
                rows_idx[r] = i0
                rows_rhs[r] = 1.5 * lim_t / root
                r += 1
            for ax in range(3):
                if jerk_x[ax] < np.inf and (g[G_T + ax] != 0.0 or g[G_K + ax] != 0.0 or g[G_KS + ax] != 0.0):
                    slope_x = 0.5 * jerk_x[ax] / (b0 * root)
                    jump = abs(g[G_D + ax]) / period
                    for sign in (1.0, -1.0):
                        for j in range(3):
                            rows_val[r, j] = (sign * (0.5 * g[G_T + ax] * W[2, j] + 1.5 * g[G_K + ax] * W[1, j]
                                                      + g[G_KS + ax] * W[0, j]) + (slope_x + jump) * W[0, j])
                        rows_idx[r] = i0
                        rows_rhs[r] = 1.5 * jerk_x[ax] / root
                        r += 1
            # normal jerk: |1.5 b' K + b Ks_perp| within J_n / sqrt(b) - b |D| / T, along N and B
            slope_n = 0.5 * jerk_n / (b0 * root)
            jump = math.sqrt(g[G_D] ** 2 + g[G_D + 1] ** 2 + g[G_D + 2] ** 2) / period
            ksx = g[G_KS] + k * k * g[G_T]
            ksy = g[G_KS + 1] + k * k * g[G_T + 1]
            ksz = g[G_KS + 2] + k * k * g[G_T + 2]
            if k > 0.0:
                nx, ny, nz = g[G_K] / k, g[G_K + 1] / k, g[G_K + 2] / k
            else:
                nn = math.sqrt(ksx * ksx + ksy * ksy + ksz * ksz)
                if nn > 0.0:
                    nx, ny, nz = ksx / nn, ksy / nn, ksz / nn
                else:
                    nx, ny, nz = 0.0, 0.0, 0.0
            kn = ksx * nx + ksy * ny + ksz * nz
            bx, by, bz = ksx - kn * nx, ksy - kn * ny, ksz - kn * nz
            kb = math.sqrt(bx * bx + by * by + bz * bz)
            # the N and B parts each within J_n / sqrt(2) would lose; use an octagon on (N, B)
            for dirn in range(8 if kb > 0.0 else 2):
                if kb > 0.0:
                    th = dirn * math.pi / 4.0
                    cn, cb = math.cos(th), math.sin(th)
                    scale = 1.0 / math.cos(math.pi / 8.0)  # octagon circumscribing the unit circle: inner side at cos(pi/8)
                    scale = 1.0
                else:
                    cn, cb = (1.0, 0.0) if dirn == 0 else (-1.0, 0.0)
                    scale = 1.0
                for j in range(3):
                    rows_val[r, j] = (cn * (1.5 * k * W[1, j] + kn * W[0, j]) + cb * kb * W[0, j]) * scale \
                        + (slope_n + jump) * W[0, j]
                rows_idx[r] = i0
                rows_rhs[r] = 1.5 * jerk_n / root
                r += 1
    return r
