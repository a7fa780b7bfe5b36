"""Controllable sets of the path planner (design §2d): at each knot, the states (b, a) from
which the rest of the stretch can still be run within every limit.

The backward pass of TOPP-RA's reachability analysis (Pham & Pham 2018), one order up. Under
jerk limits the state at a knot is (b, a) = (v^2, tangential acceleration), and the set K_j of
controllable states is convex (every limit is a row of planning.reach_rows, linear in b, a and
u = da/ds); it is kept as its upper and lower boundary at a few accelerations (*levels*,
ascending, contiguous, every one inside the set), linear between them: an inner
approximation, so that a state inside it has a way on. Going back from knot j + 1 to j:

    K_j = {(b, a) : some u keeps cell j's rows and takes (b, a) to
                   (b + 2 h a + h^2 u, a + h u) in K_j+1}

For one level a the question is one-dimensional in b. With a1 = a + h u the next state is
(b + h (a + a1), a1), so it lies in K_j+1 when gamma(a1) >= b + h a >= gamma_lo(a1), with
gamma = (upper boundary of K_j+1) - h a1, concave, and gamma_lo likewise, convex (the *chain*
the knot reads); cell j's rows keep a1 between affine functions of b. The gap between the
least upper and the greatest lower bound on a1 is concave in b: Newton's method on it from
outside the feasible interval reaches its ends without crossing them (`_upper_end`), started
from the next knot's boundary at the same acceleration (the sets change little from one knot
to the next). The levels of a knot span the accelerations its set reaches: probed at given
accelerations, the ends found by bisection (`levels`).
"""

from __future__ import annotations

import numpy as np

from nurbsfeed.jit import jit

WIDE_PROBES = 12  # accelerations every set is probed at, evenly over [-A_t, A_t] ...
# ... and, once a motion is known, this many more within FOCUS_REL A_t of its acceleration,
# where the next motion rides the sets' boundaries (chords between levels lie inside a
# concave boundary: the closer the levels, the less of it they cut off)
FOCUS_PROBES = 12
FOCUS_REL = 0.15
MAX_LEVELS = WIDE_PROBES + FOCUS_PROBES + 2
FINE_PROBES = 8  # times as many probes, evenly, where none meets the set
NEWTON_STEPS = 40
BISECTIONS = 50  # where Newton's method meets a kink it cannot step over
# a first guess from the next knot's set starts this share outside it (a boundary moves
# less than that from one knot to the next, mostly)
WARM_REL = 5e-3
RANGE_TOL_REL = 2e-3  # of the acceleration scale: how closely a set's range ends are found
ROUNDING_REL = 1e-12  # of b: where the chain's peak is met exactly, rounding aside
GAP_TOL_REL = 1e-9  # of the acceleration scale: a gap this far below 0 still counts as met
# the stored boundaries move this share of b into the set: the forward pass lands on them, and
# a state on an edge must keep a way on within rounding
SHRINK_REL = 1e-7
INFEASIBLE = -1.0
# a moving end is met within this share of its b: its set is a line, kept this thick
MOVING_END_REL = 1e-6
# ... or, for the reachable sets (what they give is a bound, not a motion), this much
LOOSE_END_REL = 1e-3


@jit
def split_rows(rows, n, h, up, down, bounds):
    """A cell's rows (n, 4) (cb b + ca a + cu u <= d) arranged for the levels: a row with u
    bounds a1 = a + h u by p + q a + s b, from above where its u coefficient is positive
    (into up (U, 3) as (p, q, s)), from below where negative (into down); a row without u
    bounds b by alpha + beta a (into bounds (B, 3) as (sign, alpha, beta): sign 1 above,
    -1 below) or a alone. Returns (U, D, B, a_min, a_max): the range of a the last ones
    leave (a_min > a_max: none)."""
    nu = 0
    nd = 0
    nb = 0
    a_min = -np.inf
    a_max = np.inf
    for r in range(n):
        cb, ca, cu, d = rows[r, 0], rows[r, 1], rows[r, 2], rows[r, 3]
        if cu != 0.0:
            p = h * d / cu
            q = 1.0 - h * ca / cu
            s = -h * cb / cu
            if cu > 0.0:
                up[nu, 0], up[nu, 1], up[nu, 2] = p, q, s
                nu += 1
            else:
                down[nd, 0], down[nd, 1], down[nd, 2] = p, q, s
                nd += 1
        elif cb != 0.0:
            bounds[nb, 0] = 1.0 if cb > 0.0 else -1.0
            bounds[nb, 1] = d / cb
            bounds[nb, 2] = -ca / cb
            nb += 1
        elif ca > 0.0:
            a_max = min(a_max, d / ca)
        elif ca < 0.0:
            a_min = max(a_min, d / ca)
        elif d < -GAP_TOL_REL * abs(d):
            a_min, a_max = 1.0, -1.0
    return nu, nd, nb, a_min, a_max


@jit
def _box_value(rows, r, sign, a, b):
    return sign * (rows[r, 0] + rows[r, 1] * a + rows[r, 2] * b)


@jit
def prune(rows, n, sign, a_lo, a_hi, b_hi):
    """Drops the bounds on a1 (rows (n, 3) as `split_rows` gives them: from above with sign 1,
    from below with sign -1) that another one is tighter than everywhere in the box a in
    [a_lo, a_hi], b in [0, b_hi] (where this knot's set lies), keeping the order of the rest;
    returns their count. Of some 19 bounds a side a cell's set meets some 5: every level reads
    them all a few times. A bound is linear, so one tighter at the box's corners is tighter
    all over it; the bounds tried as the tighter one are those tightest at a corner or the
    middle (each of them stays)."""
    if n <= 1:
        return n
    corners_a = (a_lo, a_lo, a_hi, a_hi, 0.5 * (a_lo + a_hi))
    corners_b = (0.0, b_hi, 0.0, b_hi, 0.5 * b_hi)
    best = np.empty(5, dtype=np.int64)
    for c in range(5):
        k = 0
        for r in range(1, n):
            if _box_value(rows, r, sign, corners_a[c], corners_b[c]) < _box_value(
                    rows, k, sign, corners_a[c], corners_b[c]):
                k = r
        best[c] = k
    # the tightest rows' values at the corners, kept aside: compaction overwrites the rows
    tight = np.empty((5, 4))
    for c in range(5):
        for e in range(4):
            tight[c, e] = _box_value(rows, best[c], sign, corners_a[e], corners_b[e])
    m = 0
    for r in range(n):
        dominated = False
        for c in range(5):
            if best[c] == r:
                dominated = False
                break
            if not dominated:
                tighter = True
                for e in range(4):
                    if not tight[c, e] <= _box_value(rows, r, sign, corners_a[e], corners_b[e]):
                        tighter = False
                        break
                dominated = tighter
        if not dominated:
            for i in range(3):
                rows[m, i] = rows[r, i]
            m += 1
    return m


@jit
def b_top(bounds, nb, a_lo, a_hi):
    """An upper bound on b over a in [a_lo, a_hi] from the rows without u (inf: none)."""
    top = np.inf
    for r in range(nb):
        if bounds[r, 0] > 0.0:
            top = min(top, bounds[r, 1] + max(bounds[r, 2] * a_lo, bounds[r, 2] * a_hi))
    return top


@jit
def _b_bounds(bounds, nb, a):
    """The bounds on b of the rows without u at acceleration a: (low, high)."""
    low = 0.0
    high = np.inf
    for r in range(nb):
        v = bounds[r, 1] + bounds[r, 2] * a
        if bounds[r, 0] > 0.0:
            high = min(high, v)
        else:
            low = max(low, v)
    return low, high


@jit
def superlevel(chain, row, n, peak, c, idx):
    """The interval [lo, hi] of a1 where the concave chain (chain[0], chain[row]) (n points,
    highest at peak) is >= c, and d lo / dc, d hi / dc; empty (lo > hi) when its peak is below
    c. Each end is found from where it was last (idx[0], idx[1]: the sets' boundaries move
    little between the evaluations of one knot) and interpolated from the point inside it, so
    that c at the peak gives the peak's a1 exactly on both sides. (The chain is indexed, never
    sliced: a slice's reference count costs more than the search.)"""
    if chain[row, peak] < c:
        return 1.0, -1.0, 0.0, 0.0
    k = min(max(idx[0], 0), peak)
    while k < peak and chain[row, k] < c:
        k += 1
    while k > 0 and chain[row, k - 1] >= c:
        k -= 1
    idx[0] = k
    if k == 0:
        lo, dlo = chain[0, 0], 0.0
    else:
        slope = (chain[0, k] - chain[0, k - 1]) / (chain[row, k] - chain[row, k - 1])
        lo, dlo = chain[0, k] - (chain[row, k] - c) * slope, slope
    k = min(max(idx[1], peak), n - 1)
    while k > peak and chain[row, k] < c:
        k -= 1
    while k < n - 1 and chain[row, k + 1] >= c:
        k += 1
    idx[1] = k
    if k == n - 1:
        hi, dhi = chain[0, n - 1], 0.0
    else:
        slope = (chain[0, k + 1] - chain[0, k]) / (chain[row, k + 1] - chain[row, k])
        hi, dhi = chain[0, k] + (c - chain[row, k]) * slope, slope
    return lo, hi, dlo, dhi


@jit
def sublevel(chain, row, n, valley, c, idx):
    """The interval of a1 where the convex chain (chain[0], chain[row]) (lowest at valley) is
    <= c, as `superlevel` (its ends' last places in idx[2], idx[3])."""
    if chain[row, valley] > c:
        return 1.0, -1.0, 0.0, 0.0
    k = min(max(idx[2], 0), valley)
    while k < valley and chain[row, k] > c:
        k += 1
    while k > 0 and chain[row, k - 1] <= c:
        k -= 1
    idx[2] = k
    if k == 0:
        lo, dlo = chain[0, 0], 0.0
    else:
        slope = (chain[0, k] - chain[0, k - 1]) / (chain[row, k] - chain[row, k - 1])
        lo, dlo = chain[0, k] - (chain[row, k] - c) * slope, slope
    k = min(max(idx[3], valley), n - 1)
    while k > valley and chain[row, k] > c:
        k -= 1
    while k < n - 1 and chain[row, k + 1] <= c:
        k += 1
    idx[3] = k
    if k == n - 1:
        hi, dhi = chain[0, n - 1], 0.0
    else:
        slope = (chain[0, k + 1] - chain[0, k]) / (chain[row, k + 1] - chain[row, k])
        hi, dhi = chain[0, k] + (c - chain[row, k]) * slope, slope
    return lo, hi, dlo, dhi


@jit
def _gap(level, nu, nd, a, b, h, chain, nc, peak, valley, idx):
    """The least upper bound on a1 minus the greatest lower one at state (b, a), and its slope
    in b (concave in b: its feasible b are an interval). level (4, R): the upper bounds'
    values at b = 0 at this level and their slopes in b, the lower bounds' likewise; chain
    (3, L): the next knot's levels' a1, gamma and gamma_lo (nc of them; none for the last
    cell, whose u the end fixes)."""
    up = np.inf
    up_slope = 0.0
    for r in range(nu):
        value = level[0, r] + level[1, r] * b
        if value < up:
            up, up_slope = value, level[1, r]
    dn = -np.inf
    dn_slope = 0.0
    for r in range(nd):
        value = level[2, r] + level[3, r] * b
        if value > dn:
            dn, dn_slope = value, level[3, r]
    if nc == 0:
        return up - dn, up_slope - dn_slope
    c = b + h * a
    top, bottom = chain[1, peak], chain[2, valley]
    rounding = ROUNDING_REL * (abs(c) + abs(top) + abs(bottom))
    lo, hi, dlo, dhi = superlevel(chain, 1, nc, peak, min(c, top) if c - top <= rounding
                                   else c, idx)
    if lo > hi:
        return -np.inf, -1.0
    if hi < up:
        up, up_slope = hi, dhi
    if lo > dn:
        dn, dn_slope = lo, dlo
    lo, hi, dlo, dhi = sublevel(chain, 2, nc, valley, max(c, bottom) if bottom - c
                                 <= rounding else c, idx)
    if lo > hi:
        return -np.inf, 1.0
    if hi < up:
        up, up_slope = hi, dhi
    if lo > dn:
        dn, dn_slope = lo, dlo
    return up - dn, up_slope - dn_slope


@jit
def _bisect(level, nu, nd, a, h, chain, nc, peak, valley, idx, good, bad, tol):
    """The end of the feasible interval between a feasible b (good) and an infeasible one."""
    for _ in range(BISECTIONS):
        mid = 0.5 * (good + bad)
        gap, _ = _gap(level, nu, nd, a, mid, h, chain, nc, peak, valley, idx)
        if gap >= -tol:
            good = mid
        else:
            bad = mid
    return good


@jit
def _upper_end(level, nu, nd, a, h, chain, nc, peak, valley, idx, low, high, b, tol):
    """The greatest feasible b in [low, high], by Newton's method inward from b (the tangent
    of the concave gap lies above it: from outside it never steps past the end), and where b
    turns out feasible, or below the feasible interval, from high; bisection against low
    where a kink leaves Newton no step. -1 where no b in [low, high] is feasible."""
    gap, slope = _gap(level, nu, nd, a, b, h, chain, nc, peak, valley, idx)
    if b < high and (gap >= -tol or slope > 0.0):
        b = high
        gap, slope = _gap(level, nu, nd, a, b, h, chain, nc, peak, valley, idx)
    for _ in range(NEWTON_STEPS):
        if gap >= -tol:
            return b
        step = b - gap / slope if slope < 0.0 and gap > -np.inf else low
        if step <= low:
            gap, _ = _gap(level, nu, nd, a, low, h, chain, nc, peak, valley, idx)
            if gap < -tol:
                return -1.0
            return _bisect(level, nu, nd, a, h, chain, nc, peak, valley, idx, low, b, tol)
        b = step
        gap, slope = _gap(level, nu, nd, a, b, h, chain, nc, peak, valley, idx)
    return -1.0


@jit
def _lower_end(level, nu, nd, a, h, chain, nc, peak, valley, idx, low, top, b, tol):
    """The least feasible b in [low, top] (top feasible), as `_upper_end` mirrored: Newton's
    method from b upward, from low where b turns out feasible or above the interval."""
    gap, slope = _gap(level, nu, nd, a, b, h, chain, nc, peak, valley, idx)
    if b > low and (gap >= -tol or slope < 0.0):
        b = low
        gap, slope = _gap(level, nu, nd, a, b, h, chain, nc, peak, valley, idx)
    for _ in range(NEWTON_STEPS):
        if gap >= -tol:
            return b
        step = b - gap / slope if slope > 0.0 and gap > -np.inf else top
        if step >= top:
            return _bisect(level, nu, nd, a, h, chain, nc, peak, valley, idx, top, b, tol)
        b = step
        gap, slope = _gap(level, nu, nd, a, b, h, chain, nc, peak, valley, idx)
    return top


@jit
def _guess(chain, row, nc, h, a):
    """The next knot's boundary (chain[row] = boundary - h a1) at acceleration a: the first
    guess of this knot's; -1 outside it."""
    if nc == 0 or a < chain[0, 0] or a > chain[0, nc - 1]:
        return -1.0
    k = 0
    while k < nc - 2 and chain[0, k + 1] < a:
        k += 1
    if nc == 1 or chain[0, k + 1] <= chain[0, k]:
        return chain[row, k] + h * a
    w = (a - chain[0, k]) / (chain[0, k + 1] - chain[0, k])
    return (1.0 - w) * chain[row, k] + w * chain[row, k + 1] + h * a


@jit
def _level(cell, a, h, chain, nc, peak, valley, scale, level, idx):
    """(high, low): the greatest and least b at acceleration a from which the cell's rows lead
    into the next knot's set; INFEASIBLE twice where none does. cell = (up, down, bounds, U,
    D, B, a_min, a_max) as `split_rows` gives them; level (4, R): scratch."""
    up, down, bounds, nu, nd, nb, a_min, a_max = cell
    if a < a_min or a > a_max:
        return INFEASIBLE, INFEASIBLE
    low, high = _b_bounds(bounds, nb, a)
    if low > high:
        return INFEASIBLE, INFEASIBLE
    if nc == 0 and nu + nd == 0:
        return high, low
    for r in range(nu):
        level[0, r] = up[r, 0] + up[r, 1] * a
        level[1, r] = up[r, 2]
    for r in range(nd):
        level[2, r] = down[r, 0] + down[r, 1] * a
        level[3, r] = down[r, 2]
    tol = GAP_TOL_REL * scale
    if nc > 0:
        high = min(high, chain[1, peak] - h * a)
        low = max(low, chain[2, valley] - h * a)
    if low > high:
        return INFEASIBLE, INFEASIBLE
    guess = _guess(chain, 1, nc, h, a)
    start = high if guess < 0.0 else min(max(guess * (1.0 + WARM_REL), low), high)
    top = _upper_end(level, nu, nd, a, h, chain, nc, peak, valley, idx, low, high, start, tol)
    if top < 0.0:
        return INFEASIBLE, INFEASIBLE
    guess = _guess(chain, 2, nc, h, a)
    start = low if guess < 0.0 else min(max(guess * (1.0 - WARM_REL), low), top)
    return top, _lower_end(level, nu, nd, a, h, chain, nc, peak, valley, idx, low, top, start,
                           tol)


@jit
def chain_of(lev_a, lev_hi, lev_lo, count, h, chain, idx):
    """A knot's levels as the chain the knot before it reads over a cell h long, into chain
    (3, L): a1, gamma and gamma_lo. Returns (count, peak, valley); idx (4,) starts at them."""
    peak = 0
    valley = 0
    for k in range(count):
        chain[0, k] = lev_a[k]
        chain[1, k] = lev_hi[k] - h * lev_a[k]
        chain[2, k] = lev_lo[k] - h * lev_a[k]
        if chain[1, k] > chain[1, peak]:
            peak = k
        if chain[2, k] < chain[2, valley]:
            valley = k
    idx[0] = idx[1] = peak
    idx[2] = idx[3] = valley
    return count, peak, valley


@jit
def _store(lev_a, lev_hi, lev_lo, m, a, high, low):
    """Level m: the boundaries moved SHRINK_REL into the set (a thin set keeps its middle)."""
    margin = SHRINK_REL * max(high, 0.0) + 1e-300
    lev_a[m] = a
    hi = high - margin
    lo = low + margin
    if lo > hi:
        hi = lo = 0.5 * (high + low)
    lev_hi[m] = hi
    lev_lo[m] = lo


@jit
def _probe(cell, h, chain, nc, peak, valley, probes, count, scale, probe_hi, probe_lo, level,
           idx):
    """The set at probes[:count] (ascending): (first, last) feasible ones (-1: none). The set
    is convex: the first infeasible probe after a feasible one ends the run."""
    first = -1
    last = -1
    for k in range(count):
        hi, lo = _level(cell, probes[k], h, chain, nc, peak, valley, scale, level, idx)
        probe_hi[k] = hi
        probe_lo[k] = lo
        if hi >= 0.0:
            if first < 0:
                first = k
            last = k
        elif first >= 0:
            break
    return first, last


@jit
def _refine(cell, h, chain, nc, peak, valley, inside, outside, hi, lo, guess, scale, level,
            idx):
    """The acceleration range's end between a feasible probe (inside, with its hi and lo)
    and an infeasible one: (a, hi, lo) of the last feasible point found, to RANGE_TOL_REL of
    the acceleration scale. guess: where the next knot's range ends, first tried with a
    point just beyond it (the ends move little from knot to knot)."""
    tol = RANGE_TOL_REL * scale
    lo_end, hi_end = min(inside, outside), max(inside, outside)
    if lo_end < guess < hi_end:
        toward = 1.0 if outside > inside else -1.0
        for a in (guess, guess + toward * 2.0 * tol):
            if not lo_end < a < hi_end:
                continue
            mh, ml = _level(cell, a, h, chain, nc, peak, valley, scale, level, idx)
            if mh >= 0.0:
                inside, hi, lo = a, mh, ml
            else:
                outside = a
                break
            lo_end, hi_end = min(inside, outside), max(inside, outside)
    while abs(outside - inside) > tol:
        mid = 0.5 * (inside + outside)
        mh, ml = _level(cell, mid, h, chain, nc, peak, valley, scale, level, idx)
        if mh >= 0.0:
            inside, hi, lo = mid, mh, ml
        else:
            outside = mid
    return inside, hi, lo


@jit
def levels(cell, h, chain, nc, peak, valley, probes, acc, lev_a, lev_hi, lev_lo, probe_hi,
           probe_lo, grid, level, idx):
    """The levels of one knot's set into lev_a, lev_hi, lev_lo (probes + 2,): the set at the
    accelerations probes (P,) (ascending; FINE_PROBES times as many evenly over [-acc, acc]
    where none meets the set, in grid), the ends of the feasible ones refined against their
    infeasible neighbours; a set that half the probes miss gets its levels again, evenly
    over its refined range. Returns the number of levels (0: the set is empty)."""
    p_n = probes.size
    scale = acc
    points = probes
    count = p_n
    first, last = _probe(cell, h, chain, nc, peak, valley, points, count, scale, probe_hi,
                         probe_lo, level, idx)
    if first < 0:
        count = p_n * FINE_PROBES
        for k in range(count):
            grid[k] = -acc + 2.0 * acc * k / (count - 1)
        points = grid[:count]
        first, last = _probe(cell, h, chain, nc, peak, valley, points, count, scale, probe_hi,
                             probe_lo, level, idx)
        if first < 0:
            return 0
    ends_a = (chain[0, 0], chain[0, nc - 1]) if nc > 0 else (np.nan, np.nan)
    a0, hi0, lo0 = points[first], probe_hi[first], probe_lo[first]
    if first > 0:
        a0, hi0, lo0 = _refine(cell, h, chain, nc, peak, valley, a0, points[first - 1], hi0,
                               lo0, ends_a[0], scale, level, idx)
    a1, hi1, lo1 = points[last], probe_hi[last], probe_lo[last]
    if last < count - 1:
        a1, hi1, lo1 = _refine(cell, h, chain, nc, peak, valley, a1, points[last + 1], hi1,
                               lo1, ends_a[1], scale, level, idx)
    m = 0
    if count == p_n and last - first + 1 >= p_n // 2:
        if a0 < points[first]:
            _store(lev_a, lev_hi, lev_lo, m, a0, hi0, lo0)
            m += 1
        for k in range(first, last + 1):
            _store(lev_a, lev_hi, lev_lo, m, points[k], probe_hi[k], probe_lo[k])
            m += 1
        if a1 > points[last]:
            _store(lev_a, lev_hi, lev_lo, m, a1, hi1, lo1)
            m += 1
        return m
    _store(lev_a, lev_hi, lev_lo, m, a0, hi0, lo0)
    m += 1
    width = a1 - a0
    if width <= 0.0:
        return m
    for k in range(1, p_n - 1):
        a = a0 + width * k / (p_n - 1)
        hi, lo = _level(cell, a, h, chain, nc, peak, valley, scale, level, idx)
        if hi >= 0.0:
            _store(lev_a, lev_hi, lev_lo, m, a, hi, lo)
            m += 1
    _store(lev_a, lev_hi, lev_lo, m, a1, hi1, lo1)
    return m + 1


@jit
def probes_around(acc, wide, focus, centre, half_width, out):
    """Probe accelerations (wide + focus,), ascending: wide evenly over [-acc, acc] and focus
    evenly over [centre - half_width, centre + half_width] (clipped to it); focus = 0: the wide
    ones alone. Returns the count (the two runs merged, duplicates dropped)."""
    lo = max(centre - half_width, -acc)
    hi = min(centre + half_width, acc)
    i = 0
    k = 0
    n = 0
    while i < wide or k < focus:
        x_wide = -acc + 2.0 * acc * i / (wide - 1) if i < wide else np.inf
        x_focus = (lo + (hi - lo) * k / (focus - 1) if focus > 1 else centre) if k < focus \
            else np.inf
        if x_wide <= x_focus:
            x = x_wide
            i += 1
        else:
            x = x_focus
            k += 1
        if n == 0 or x > out[n - 1]:
            out[n] = x
            n += 1
    return n


@jit
def fold_end(rows, n, h, end_kind, p1, p2, out):
    """The last cell's rows with its u fixed by the end it runs into, as rows over (b, a) alone
    (u = 0 in them) into out; returns the count. end_kind 0: a rest after a rest cell p1 long
    whose far value is at most p2 (b = b_end y^(4/3): at the knot a = -2 b / (3 p1), so
    u = -(b + (2 h + 1.5 p1) a) / (h^2 + 1.5 p1 h)); 1: a moving end in state (b, a) = (p1,
    p2) (u = (p2 - a) / h, and b = p1 - h (a + p2), two rows, MOVING_END_REL apart; 2: the
    same, LOOSE_END_REL apart)."""
    if end_kind == 0:
        den = h * h + 1.5 * p1 * h
        pb, pa, p0 = -1.0 / den, -(2.0 * h + 1.5 * p1) / den, 0.0
    else:
        pb, pa, p0 = 0.0, -1.0 / h, p2 / h
    m = 0
    for r in range(n):
        cu = rows[r, 2]
        out[m, 0] = rows[r, 0] + cu * pb
        out[m, 1] = rows[r, 1] + cu * pa
        out[m, 2] = 0.0
        out[m, 3] = rows[r, 3] - cu * p0
        m += 1
    if end_kind == 0:
        # the far value b + 2 h a + h^2 u of the rest cell: at most p2, at least 0
        for sign, bound in ((1.0, p2), (-1.0, 0.0)):
            out[m, 0] = sign * (1.0 + h * h * pb)
            out[m, 1] = sign * (2.0 * h + h * h * pa)
            out[m, 2] = 0.0
            out[m, 3] = sign * bound
            m += 1
    else:
        thick = (MOVING_END_REL if end_kind == 1 else LOOSE_END_REL) * max(abs(p1), 1e-300)
        for sign in (1.0, -1.0):
            out[m, 0] = sign
            out[m, 1] = sign * h
            out[m, 2] = 0.0
            out[m, 3] = sign * (p1 - h * p2) + thick
            m += 1
    return m
