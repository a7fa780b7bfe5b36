"""The passes of the path planner over one stretch (design §2d): the backward pass that builds
every knot's controllable set (planning.reach_sets), the forward pass that runs the fastest
motion those sets allow, and the highest b each knot can be passed at.

A stretch has Q cells between Q + 1 knots; at its start and its end it rests (after a rest cell
b = b_end y^(4/3), constant jerk from rest: at the knot beside it a = 2 b / (3 h_rest), and b is
at most the rest cell's own cap) or moves in a given state (b, a) (a chain's window, design
§3b). Arrays per cell (Q,): h, the geometry at its start, middle and end (Q, G_SIZE), the
linearisation points at its middle, its limits (Q, 10) (planning.reach_rows.limits_vector:
looser near a moving start that needs it); per knot (Q + 1,): the linearisation points and
floors.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.reach_bounds import b_top, fold_end, prune, split_rows
from nurbsfeed.planning.reach_rows import ROWS_PER_CELL, cell_rows
from nurbsfeed.planning.reach_sets import (
    FINE_PROBES,
    FOCUS_PROBES,
    FOCUS_REL,
    KEY_PROBES,
    MAX_LEVELS,
    WIDE_PROBES,
    chain_of,
    levels,
    on_side,
    probes_around,
)
from nurbsfeed.planning.schedule import GAUSS_W, GAUSS_X

END_REST, END_MOVING, END_MOVING_LOOSE = 0, 1, 2
FORWARD_TOL_REL = 1e-9  # a row the forward pass's state breaks by less than this share holds
U_TOL_REL = 1e-7  # an empty range of u narrower than this share of its size is rounding


@jit
def controllable(h, g0, gm, g1, b_knot, b_mid, floors, lims, end_kind, end_p1, end_p2, focus,
                 focused, top, lev_a, lev_hi, lev_lo, lev_n):
    """The backward pass: every knot's levels (Q + 1, MAX_LEVELS) and their count (Q + 1,)
    (the last knot's are not needed: the end is folded into the last cell), from knot top
    down (the knots after it keep the levels they have). focused: probe each knot's set
    closely around the acceleration focus (Q + 1,) of a motion already found too (NaN where
    none is). Returns the knot whose set came out empty, -1 when none did."""
    q_n = h.size
    rows = np.empty((ROWS_PER_CELL, 4))
    folded = np.empty((ROWS_PER_CELL + 2, 4))
    chain = np.empty((3, MAX_LEVELS))
    idx = np.zeros(4, dtype=np.int64)
    probe_hi = np.empty(MAX_LEVELS * FINE_PROBES)
    probe_lo = np.empty(MAX_LEVELS * FINE_PROBES)
    grid = np.empty(MAX_LEVELS * FINE_PROBES)
    probes = np.empty(WIDE_PROBES + FOCUS_PROBES)
    keys = np.zeros(KEY_PROBES)  # a = 0 (reach_sets.levels)
    up = np.empty((ROWS_PER_CELL + 2, 3))
    down = np.empty((ROWS_PER_CELL + 2, 3))
    bounds = np.empty((ROWS_PER_CELL + 2, 3))
    level = np.empty((4, ROWS_PER_CELL + 2))
    one = np.empty(3)
    lev_n[q_n] = 0
    for j in range(top, -1, -1):
        n = cell_rows(g0[j], gm[j], g1[j], h[j], b_knot[j], b_mid[j], b_knot[j + 1], floors[j],
                      floors[j + 1], lims[j], rows)
        acc = lims[j, 0]
        here = focused and focus[j] == focus[j]  # (NaN: no motion known at this knot)
        p_n = probes_around(acc, WIDE_PROBES, FOCUS_PROBES if here else 0, focus[j],
                            FOCUS_REL * acc, probes)
        nc, peak, valley = 0, 0, 0
        if j == q_n - 1:
            n = fold_end(rows, n, h[j], end_kind, end_p1, end_p2, folded)
            nu, nd, nb, a_min, a_max = split_rows(folded, n, h[j], up, down, bounds)
        else:
            nu, nd, nb, a_min, a_max = split_rows(rows, n, h[j], up, down, bounds)
            nc, peak, valley = chain_of(lev_a[j + 1], lev_hi[j + 1], lev_lo[j + 1],
                                        lev_n[j + 1], h[j], chain, idx)
        # the box this knot's set lies in, where the bounds on a1 are pruned
        a_lo, a_hi = max(a_min, -acc), min(a_max, acc)
        b_hi = b_top(bounds, nb, a_lo, a_hi)
        if nc > 0:
            b_hi = min(b_hi, chain[1, peak] - h[j] * a_lo)
        if a_lo <= a_hi and 0.0 <= b_hi < np.inf:
            nu = prune(up, nu, 1.0, a_lo, a_hi, b_hi)
            nd = prune(down, nd, -1.0, a_lo, a_hi, b_hi)
        m = levels((up, down, bounds, nu, nd, nb, a_min, a_max), h[j], chain, nc, peak, valley,
                   probes[:p_n], keys, acc, lev_a[j], lev_hi[j], lev_lo[j], probe_hi, probe_lo,
                   grid, level, idx, one)
        lev_n[j] = m
        if m == 0:
            return j
    return -1


@jit
def level_interval(chain, row, n, extreme, c, sign, idx):
    """The interval [lo, hi] of a1 where the chain (chain[0], chain[row]) (n points) is on
    c's side: sign 1, the concave chain >= c (highest at extreme); sign -1, the convex one <=
    c (lowest at extreme); and d lo / dc, d hi / dc. Empty (lo > hi) when its extreme is not.
    Each end is found from where it was last (idx[0], idx[1] for sign 1, idx[2], idx[3] for
    -1: the sets' boundaries move little between the evaluations of one knot) and interpolated
    from the point inside it, so that c at the extreme gives the extreme's a1 exactly on both
    sides. (The chain is indexed, never sliced: a slice's reference count costs more than the
    search.) The forward pass reads the chain with it once a knot; reach_sets._probe, which
    reads it at every step of its searches, has the same lines written out (a call there cost
    a fifth of the backward pass: 12.4 against 10.0 us a knot)."""
    if not on_side(chain[row, extreme], c, sign):
        return 1.0, -1.0, 0.0, 0.0
    slot = 0 if sign > 0.0 else 2
    k = min(max(idx[slot], 0), extreme)
    while k < extreme and not on_side(chain[row, k], c, sign):
        k += 1
    while k > 0 and on_side(chain[row, k - 1], c, sign):
        k -= 1
    idx[slot] = k
    if k == 0:
        lo, dlo = chain[0, 0], 0.0
    else:
        slope = (chain[0, k] - chain[0, k - 1]) / (chain[row, k] - chain[row, k - 1])
        lo, dlo = chain[0, k] - (chain[row, k] - c) * slope, slope
    k = min(max(idx[slot + 1], extreme), n - 1)
    while k > extreme and not on_side(chain[row, k], c, sign):
        k -= 1
    while k < n - 1 and on_side(chain[row, k + 1], c, sign):
        k += 1
    idx[slot + 1] = k
    if k == n - 1:
        hi, dhi = chain[0, n - 1], 0.0
    else:
        slope = (chain[0, k + 1] - chain[0, k]) / (chain[row, k + 1] - chain[row, k])
        hi, dhi = chain[0, k] + (c - chain[row, k]) * slope, slope
    return lo, hi, dlo, dhi


@jit
def _at(lev_a, lev_hi, lev_lo, n, a):
    """The set's boundaries (low, high) at acceleration a, linear between its levels; (1, -1)
    outside its range."""
    if n == 0 or a < lev_a[0] or a > lev_a[n - 1]:
        return 1.0, -1.0
    k = 0
    while k < n - 2 and lev_a[k + 1] < a:
        k += 1
    if n == 1:
        return lev_lo[0], lev_hi[0]
    w = (a - lev_a[k]) / (lev_a[k + 1] - lev_a[k]) if lev_a[k + 1] > lev_a[k] else 0.0
    w = min(max(w, 0.0), 1.0)
    return ((1.0 - w) * lev_lo[k] + w * lev_lo[k + 1],
            (1.0 - w) * lev_hi[k] + w * lev_hi[k + 1])


@jit
def _last_root(lev_a, values, n):
    """The greatest a at which the piecewise linear (lev_a, values) (n points, concave) is
    still >= 0; -inf where it is negative everywhere."""
    if values[n - 1] >= 0.0:
        return lev_a[n - 1]
    for k in range(n - 2, -1, -1):
        if values[k] >= 0.0:
            return lev_a[k] + (lev_a[k + 1] - lev_a[k]) * values[k] / (values[k] - values[k + 1])
    return -np.inf


@jit
def _ray_start(lev_a, lev_hi, lev_lo, n, slope, a_cap):
    """The greatest state (b, a = slope b) on a rest cell's ray inside a set, with a <= a_cap
    (the rest cell's own cap on b, as an acceleration); b <= 0 where the ray misses the set.
    hi(a) - a / slope and a / slope - lo(a) are concave in a: the ray runs inside the set up
    to the last root of either."""
    if n == 0:
        return -1.0
    above = np.empty(n)
    below = np.empty(n)
    for k in range(n):
        above[k] = lev_hi[k] - lev_a[k] / slope
        below[k] = lev_a[k] / slope - lev_lo[k]
    a = min(_last_root(lev_a, above, n), _last_root(lev_a, below, n), a_cap)
    if not a >= max(lev_a[0], 0.0):
        return -1.0
    low, high = _at(lev_a, lev_hi, lev_lo, n, a)
    b = a / slope
    if not low - 1e-9 * abs(low) <= b <= high + 1e-9 * abs(high):
        return -1.0
    return b


@jit
def _u_range(rows, n, b, a):
    """The u that keep every row at start state (b, a): (low, high); low > high where a row
    without u breaks, or the rows leave none."""
    low = -np.inf
    high = np.inf
    for r in range(n):
        rest = rows[r, 3] - rows[r, 0] * b - rows[r, 1] * a
        tol = FORWARD_TOL_REL * (abs(rows[r, 3]) + abs(rows[r, 0] * b) + abs(rows[r, 1] * a))
        cu = rows[r, 2]
        if cu > 0.0:
            high = min(high, (rest + tol) / cu)
        elif cu < 0.0:
            low = max(low, (rest + tol) / cu)
        elif rest < -tol:
            return 1.0, -1.0
    return low, high


@jit
def forward(h, g0, gm, g1, b_knot, b_mid, floors, lims, start_kind, start_p1, start_p2,
            end_kind, end_p1, end_p2, lev_a, lev_hi, lev_lo, lev_n, b_out, a_out):
    """The fastest motion the sets allow: from the start, at every knot the greatest u that
    keeps the cell's rows and lands in the next knot's set (it takes b and a up together).
    start_kind END_REST: after a rest cell start_p1 long with far value at most start_p2;
    END_MOVING: in state (start_p1, start_p2). b_out, a_out (Q + 1,). Returns -1, or the knot
    the pass found no way on from."""
    q_n = h.size
    rows = np.empty((ROWS_PER_CELL, 4))
    chain = np.empty((3, MAX_LEVELS))
    idx = np.zeros(4, dtype=np.int64)
    if start_kind == END_REST:
        slope = 2.0 / (3.0 * start_p1)
        b = _ray_start(lev_a[0], lev_hi[0], lev_lo[0], lev_n[0], slope, start_p2 * slope)
        if not b > 0.0:
            return 0
        a = slope * b
    else:
        b, a = start_p1, start_p2
        low, high = _at(lev_a[0], lev_hi[0], lev_lo[0], lev_n[0], a)
        if not low - 1e-6 * abs(low) <= b <= high + 1e-6 * abs(high):
            return 0
    b_out[0] = b
    a_out[0] = a
    for j in range(q_n):
        hj = h[j]
        n = cell_rows(g0[j], gm[j], g1[j], hj, b_knot[j], b_mid[j], b_knot[j + 1], floors[j],
                      floors[j + 1], lims[j], rows)
        low, high = _u_range(rows, n, b, a)
        if j == q_n - 1:
            if end_kind == END_REST:
                u = -(b + (2.0 * hj + 1.5 * end_p1) * a) / (hj * hj + 1.5 * end_p1 * hj)
            else:
                u = (end_p2 - a) / hj
            tol = U_TOL_REL * (abs(low) + abs(high) + abs(u) + 1.0)
            if not low - tol <= u <= high + tol:
                return j
        else:
            nc, peak, valley = chain_of(lev_a[j + 1], lev_hi[j + 1], lev_lo[j + 1],
                                        lev_n[j + 1], hj, chain, idx)
            c = min(b + hj * a, chain[1, peak])
            # (rows as int64, not literals: a literal compiles level_interval once for each)
            lo1, hi1, _, _ = level_interval(chain, np.int64(1), nc, peak, c, 1.0, idx)
            lo2, hi2, _, _ = level_interval(chain, np.int64(2), nc, valley,
                                            max(c, chain[2, valley]), -1.0, idx)
            low = max(low, (max(lo1, lo2) - a) / hj)
            high = min(high, (min(hi1, hi2) - a) / hj)
            tol = U_TOL_REL * (abs(low) + abs(high) + 1.0)
            if low > high + tol:
                return j
            u = high if high >= low else 0.5 * (low + high)
        b += hj * (2.0 * a + hj * u)
        a += hj * u
        b_out[j + 1] = max(b, 0.0)
        a_out[j + 1] = a
        b = b_out[j + 1]
    return -1


@jit
def _segment_top(l1a, h1a, l2a, h2a, l1b, h1b, l2b, h2b):
    """The greatest min(h1, h2) where both lows lie below both highs, all four linear from their
    values at one end (a) to the other (b) of a piece of the a axis; -1 where nowhere."""
    ta, tb = 0.0, 1.0
    for p in range(4):
        fa = (h1a if p < 2 else h2a) - (l1a if p % 2 == 0 else l2a)
        fb = (h1b if p < 2 else h2b) - (l1b if p % 2 == 0 else l2b)
        if fa < 0.0 and fb < 0.0:
            return -1.0
        if fa < 0.0:
            ta = max(ta, fa / (fa - fb))
        elif fb < 0.0:
            tb = min(tb, fa / (fa - fb))
    if ta > tb:
        return -1.0
    top = -1.0
    for t in (ta, tb):
        top = max(top, min(h1a + t * (h1b - h1a), h2a + t * (h2b - h2a)))
    da, db = h1a - h2a, h1b - h2b
    if da * db < 0.0:  # the two highs cross in between
        t = da / (da - db)
        if ta <= t <= tb:
            top = max(top, h1a + t * (h1b - h1a))
    return top


@jit
def highest(ka, khi, klo, kn, ra, rhi, rlo, rn, out):
    """Per knot (Q + 1,): the greatest b of a state both controllable (levels ka, khi, klo, kn,
    (Q + 1, L)) and reachable from the start (levels of the reversed stretch, ra ..., at knot
    Q - j with a's sign turned), into out; 0 where the two do not meet. Both sets' boundaries
    are linear between the levels of either (walked in ascending order, the reversed ones from
    their end): on each such piece the top is where the lower high peaks inside the part where
    both lows lie below both highs, a one-dimensional program with a closed form."""
    q1 = khi.shape[0]
    for j in range(q1):
        jr = q1 - 1 - j
        nk, nr = kn[j], rn[jr]
        best = 0.0
        if nk > 0 and nr > 0:
            lo_a = max(ka[j, 0], -ra[jr, nr - 1])
            hi_a = min(ka[j, nk - 1], -ra[jr, 0])
            i = 0
            k = nr - 1
            x = lo_a
            first = True
            l1p = h1p = l2p = h2p = 0.0
            while lo_a <= hi_a:
                l1, h1 = _at(ka[j], khi[j], klo[j], nk, x)
                l2, h2 = _at(ra[jr], rhi[jr], rlo[jr], nr, -x)
                if first:
                    if max(l1, l2) <= min(h1, h2):
                        best = max(best, min(h1, h2))
                    first = False
                else:
                    best = max(best, _segment_top(l1p, h1p, l2p, h2p, l1, h1, l2, h2))
                l1p, h1p, l2p, h2p = l1, h1, l2, h2
                while i < nk and ka[j, i] <= x:
                    i += 1
                while k >= 0 and -ra[jr, k] <= x:
                    k -= 1
                nxt = hi_a
                if i < nk:
                    nxt = min(nxt, ka[j, i])
                if k >= 0:
                    nxt = min(nxt, -ra[jr, k])
                if nxt <= x:
                    break
                x = nxt
        out[j] = best


@jit
def motion_time(h, b, a, start_h, end_h):
    """The time of a stretch's motion (b, a) (Q + 1,) at its knots: each cell's b = b + 2 a x +
    u x^2 by Gauss-Legendre on 1 / sqrt(b) (schedule.cell_times' points), and each rest
    cell's 3 h / sqrt(b) (0 h: a moving end, none)."""
    q_n = h.size
    total = 0.0
    if start_h > 0.0:
        total += 3.0 * start_h / math.sqrt(max(b[0], 1e-300))
    if end_h > 0.0:
        total += 3.0 * end_h / math.sqrt(max(b[q_n], 1e-300))
    for j in range(q_n):
        hj = h[j]
        u = (a[j + 1] - a[j]) / hj
        t = 0.0
        for g in range(GAUSS_X.size):
            x = 0.5 * hj * (GAUSS_X[g] + 1.0)
            bx = b[j] + x * (2.0 * a[j] + u * x)
            t += GAUSS_W[g] / math.sqrt(max(bx, 1e-300))
        total += 0.5 * hj * t
    return total
