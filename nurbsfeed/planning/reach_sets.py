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
gamma = (upper boundary of K_j+1) - h a1, concave, and gamma_lo likewise, convex; cell j's rows
keep a1 between affine functions of b. The gap between the least upper and the greatest lower
bound on a1 is concave in b: Newton's method on it from outside the feasible interval reaches
its ends without crossing them (`_level`). The levels of a knot span the accelerations its set
reaches: probed at evenly spaced accelerations, the ends found by bisection (`levels`).
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit

WIDE_PROBES = 12  # accelerations every set is probed at, evenly over [-A_t, A_t] ...
# ... and, once a motion is known, this many more within FOCUS_REL A_t of its acceleration,
# where the next motion rides the sets' boundaries (chords between levels lie inside a
# concave boundary: the closer the levels, the less of it they cut off)
FOCUS_PROBES = 12
FOCUS_REL = 0.15
MAX_LEVELS = WIDE_PROBES + FOCUS_PROBES + 2
NEWTON_STEPS = 40
BISECTIONS = 50  # where Newton's method meets a kink it cannot step over
# a first guess from the next knot's set starts this share outside it (a boundary moves
# less than that from one knot to the next, mostly)
WARM_REL = 5e-3
RANGE_TOL_REL = 2e-3  # of the acceleration scale: how closely a set's range ends are found
FINE_PROBES = 8  # times LEVELS probes where no coarse probe meets the set
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
def split_rows(rows, n, h, up, down, fixed):
    """A cell's rows split for the levels: a row with u bounds a1 = a + h u by p + q a + s b
    (from above where its u coefficient is positive, into up (U, 3); from below, into down
    (D, 3)), one without u bounds b at each a, into fixed (F, 3) as (cb, ca, d). Returns
    (U, D, F)."""
    nu = 0
    nd = 0
    nf = 0
    for r in range(n):
        cu = rows[r, 2]
        if cu == 0.0:
            fixed[nf, 0] = rows[r, 0]
            fixed[nf, 1] = rows[r, 1]
            fixed[nf, 2] = rows[r, 3]
            nf += 1
            continue
        p = h * rows[r, 3] / cu
        q = 1.0 - h * rows[r, 1] / cu
        s = -h * rows[r, 0] / cu
        if cu > 0.0:
            up[nu, 0], up[nu, 1], up[nu, 2] = p, q, s
            nu += 1
        else:
            down[nd, 0], down[nd, 1], down[nd, 2] = p, q, s
            nd += 1
    return nu, nd, nf


@jit
def _b_bounds(fixed, nf, a):
    """Per level a: the bounds on b of the rows without u (cap, floors, ...): (low, high, ok)."""
    low = 0.0
    high = np.inf
    for r in range(nf):
        cb = fixed[r, 0]
        d = fixed[r, 2] - fixed[r, 1] * a
        if cb > 0.0:
            high = min(high, d / cb)
        elif cb < 0.0:
            low = max(low, d / cb)
        elif d < -GAP_TOL_REL * (abs(fixed[r, 2]) + abs(fixed[r, 1] * a)):
            return low, high, False
    return low, high, True


@jit
def _superlevel(cha, chg, n, peak, c):
    """The interval [lo, hi] of a1 where the concave chain (cha, chg) (n points, highest at
    peak) is >= c, and d lo / dc, d hi / dc. Empty (lo > hi) when its peak is below c. Each
    end is interpolated from the point inside it, so that c at the peak gives the peak's a1
    exactly on both sides."""
    if chg[peak] < c:
        return 1.0, -1.0, 0.0, 0.0
    k = peak
    while k > 0 and chg[k - 1] >= c:
        k -= 1
    if k == 0:
        lo, dlo = cha[0], 0.0
    else:
        slope = (cha[k] - cha[k - 1]) / (chg[k] - chg[k - 1])
        lo, dlo = cha[k] - (chg[k] - c) * slope, slope
    k = peak
    while k < n - 1 and chg[k + 1] >= c:
        k += 1
    if k == n - 1:
        hi, dhi = cha[n - 1], 0.0
    else:
        slope = (cha[k + 1] - cha[k]) / (chg[k + 1] - chg[k])
        hi, dhi = cha[k] + (c - chg[k]) * slope, slope
    return lo, hi, dlo, dhi


@jit
def _sublevel(cha, chl, n, valley, c):
    """The interval of a1 where the convex chain (cha, chl) (lowest at valley) is <= c, ends
    interpolated from inside as in `_superlevel`."""
    if chl[valley] > c:
        return 1.0, -1.0, 0.0, 0.0
    k = valley
    while k > 0 and chl[k - 1] <= c:
        k -= 1
    if k == 0:
        lo, dlo = cha[0], 0.0
    else:
        slope = (cha[k] - cha[k - 1]) / (chl[k] - chl[k - 1])
        lo, dlo = cha[k] - (chl[k] - c) * slope, slope
    k = valley
    while k < n - 1 and chl[k + 1] <= c:
        k += 1
    if k == n - 1:
        hi, dhi = cha[n - 1], 0.0
    else:
        slope = (cha[k + 1] - cha[k]) / (chl[k + 1] - chl[k])
        hi, dhi = cha[k] + (c - chl[k]) * slope, slope
    return lo, hi, dlo, dhi


@jit
def _gap(wu, su, nu, wd, sd, nd, a, b, h, cha, chg, chl, nc, peak, valley):
    """The least upper bound on a1 minus the greatest lower one at state (b, a), and its slope
    in b (the gap is concave in b: its feasible b are an interval). wu, su (U,): the upper
    bounds' values at b = 0 at this level and their slopes in b; wd, sd likewise."""
    up = np.inf
    up_slope = 0.0
    for r in range(nu):
        value = wu[r] + su[r] * b
        if value < up:
            up, up_slope = value, su[r]
    dn = -np.inf
    dn_slope = 0.0
    for r in range(nd):
        value = wd[r] + sd[r] * b
        if value > dn:
            dn, dn_slope = value, sd[r]
    if nc == 0:
        return up - dn, up_slope - dn_slope
    c = b + h * a
    rounding = ROUNDING_REL * (abs(c) + abs(chg[peak]) + abs(chl[valley]))
    lo, hi, dlo, dhi = _superlevel(cha, chg, nc, peak, min(c, chg[peak]) if c - chg[peak]
                                   <= rounding else c)
    if lo > hi:
        return -np.inf, -1.0
    if hi < up:
        up, up_slope = hi, dhi
    if lo > dn:
        dn, dn_slope = lo, dlo
    lo, hi, dlo, dhi = _sublevel(cha, chl, nc, valley, max(c, chl[valley]) if chl[valley] - c
                                 <= rounding else c)
    if lo > hi:
        return -np.inf, 1.0
    if hi < up:
        up, up_slope = hi, dhi
    if lo > dn:
        dn, dn_slope = lo, dlo
    return up - dn, up_slope - dn_slope


@jit
def _bisect(wu, su, nu, wd, sd, nd, a, h, cha, chg, chl, nc, peak, valley, good, bad, tol):
    """The end of the feasible interval between a feasible b (good) and an infeasible one."""
    for _ in range(BISECTIONS):
        mid = 0.5 * (good + bad)
        gap, _ = _gap(wu, su, nu, wd, sd, nd, a, mid, h, cha, chg, chl, nc, peak, valley)
        if gap >= -tol:
            good = mid
        else:
            bad = mid
    return good


@jit
def _upper_end(wu, su, nu, wd, sd, nd, a, h, cha, chg, chl, nc, peak, valley, low, high, b,
               tol):
    """The greatest feasible b in [low, high], by Newton's method inward from b (the tangent
    of the concave gap lies above it: from outside it never steps past the end), and where b
    turns out feasible, or below the feasible interval, from high; bisection against low
    where a kink leaves Newton no step. -1 where no b in [low, high] is feasible."""
    gap, slope = _gap(wu, su, nu, wd, sd, nd, a, b, h, cha, chg, chl, nc, peak, valley)
    if b < high and (gap >= -tol or slope > 0.0):
        b = high
        gap, slope = _gap(wu, su, nu, wd, sd, nd, a, b, h, cha, chg, chl, nc, peak, valley)
    for _ in range(NEWTON_STEPS):
        if gap >= -tol:
            return b
        step = b - gap / slope if slope < 0.0 and gap > -np.inf else low
        if step <= low:
            gap, _ = _gap(wu, su, nu, wd, sd, nd, a, low, h, cha, chg, chl, nc, peak, valley)
            if gap < -tol:
                return -1.0
            return _bisect(wu, su, nu, wd, sd, nd, a, h, cha, chg, chl, nc, peak, valley, low,
                           b, tol)
        b = step
        gap, slope = _gap(wu, su, nu, wd, sd, nd, a, b, h, cha, chg, chl, nc, peak, valley)
    return -1.0


@jit
def _lower_end(wu, su, nu, wd, sd, nd, a, h, cha, chg, chl, nc, peak, valley, low, top, b,
               tol):
    """The least feasible b in [low, top] (top feasible), as `_upper_end` mirrored: Newton's
    method from b upward, from low where b turns out feasible or above the interval."""
    gap, slope = _gap(wu, su, nu, wd, sd, nd, a, b, h, cha, chg, chl, nc, peak, valley)
    if b > low and (gap >= -tol or slope < 0.0):
        b = low
        gap, slope = _gap(wu, su, nu, wd, sd, nd, a, b, h, cha, chg, chl, nc, peak, valley)
    for _ in range(NEWTON_STEPS):
        if gap >= -tol:
            return b
        step = b - gap / slope if slope > 0.0 and gap > -np.inf else top
        if step >= top:
            return _bisect(wu, su, nu, wd, sd, nd, a, h, cha, chg, chl, nc, peak, valley, top,
                           b, tol)
        b = step
        gap, slope = _gap(wu, su, nu, wd, sd, nd, a, b, h, cha, chg, chl, nc, peak, valley)
    return top


@jit
def _guess(cha, chv, nc, h, a):
    """The next knot's boundary (chain values chv = boundary - h a1) at acceleration a: the
    first guess of this knot's (the sets change little from knot to knot); -1 outside it."""
    if nc == 0 or a < cha[0] or a > cha[nc - 1]:
        return -1.0
    k = 0
    while k < nc - 2 and cha[k + 1] < a:
        k += 1
    if nc == 1 or cha[k + 1] <= cha[k]:
        return chv[k] + h * a
    w = (a - cha[k]) / (cha[k + 1] - cha[k])
    return (1.0 - w) * chv[k] + w * chv[k + 1] + h * a


@jit
def _level(cell, a, h, cha, chg, chl, nc, peak, valley, scale, work, lower):
    """(high, low): the greatest and least b at acceleration a from which the cell's rows lead
    into the next knot's set, the chain (cha, chg, chl) of its levels (gamma and gamma_lo,
    above); INFEASIBLE twice where none does. cell = (up, down, fixed, nu, nd, nf): the rows
    as `split_rows` gives them; work (4, U): scratch. Without a chain (nc = 0, the last
    cell, its u fixed by the end: `fold_end`) the rows bound b alone. Each end by Newton's
    method from the next knot's boundary at a (`_upper_end`). lower: the least b too (else
    only what the rows without u bound it by)."""
    up, down, fixed, nu, nd, nf = cell
    low, high, ok = _b_bounds(fixed, nf, a)
    if not ok or low > high:
        return INFEASIBLE, INFEASIBLE
    if nc == 0 and nu + nd == 0:
        return high, low
    wu, su, wd, sd = work[0], work[1], work[2], work[3]
    for r in range(nu):
        wu[r] = up[r, 0] + up[r, 1] * a
        su[r] = up[r, 2]
    for r in range(nd):
        wd[r] = down[r, 0] + down[r, 1] * a
        sd[r] = down[r, 2]
    tol = GAP_TOL_REL * scale
    if nc > 0:
        high = min(high, chg[peak] - h * a)
        low = max(low, chl[valley] - h * a)
    if low > high:
        return INFEASIBLE, INFEASIBLE
    guess = _guess(cha, chg, nc, h, a)
    start = high if guess < 0.0 else min(max(guess * (1.0 + WARM_REL), low), high)
    top = _upper_end(wu, su, nu, wd, sd, nd, a, h, cha, chg, chl, nc, peak, valley, low, high,
                     start, tol)
    if top < 0.0:
        return INFEASIBLE, INFEASIBLE
    if not lower:
        return top, min(low, top)
    guess = _guess(cha, chl, nc, h, a)
    start = low if guess < 0.0 else min(max(guess * (1.0 - WARM_REL), low), top)
    return top, _lower_end(wu, su, nu, wd, sd, nd, a, h, cha, chg, chl, nc, peak, valley, low,
                           top, start, tol)


@jit
def chain_of(lev_a, lev_hi, lev_lo, count, h, cha, chg, chl):
    """A knot's levels as the chain the knot before it reads over a cell h long: gamma (chg)
    and gamma_lo (chl) at the accelerations cha. Returns (count, peak, valley)."""
    peak = 0
    valley = 0
    for k in range(count):
        cha[k] = lev_a[k]
        chg[k] = lev_hi[k] - h * lev_a[k]
        chl[k] = lev_lo[k] - h * lev_a[k]
        if chg[k] > chg[peak]:
            peak = k
        if chl[k] < chl[valley]:
            valley = k
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
def _probe(cell, h, cha, chg, chl, nc, peak, valley, probes, count, scale, probe_hi,
           probe_lo, work, lower):
    """The sets' levels at probes[:count] (ascending): (first, last) feasible ones (-1: none).
    The set is convex: the first infeasible probe after a feasible one ends the run."""
    first = -1
    last = -1
    for k in range(count):
        hi, lo = _level(cell, probes[k], h, cha, chg, chl, nc, peak, valley, scale, work, lower)
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
def _refine(cell, h, cha, chg, chl, nc, peak, valley, inside, outside, hi, lo, scale, work,
            lower):
    """The acceleration range's end between a feasible probe (inside, with its hi and lo)
    and an infeasible one: (a, hi, lo) of the last feasible point bisection finds, to
    RANGE_TOL_REL of the acceleration scale."""
    while abs(outside - inside) > RANGE_TOL_REL * scale:
        mid = 0.5 * (inside + outside)
        mh, ml = _level(cell, mid, h, cha, chg, chl, nc, peak, valley, scale, work, lower)
        if mh >= 0.0:
            inside, hi, lo = mid, mh, ml
        else:
            outside = mid
    return inside, hi, lo


@jit
def levels(cell, h, cha, chg, chl, nc, peak, valley, probes, acc, lev_a, lev_hi, lev_lo,
           probe_hi, probe_lo, work, lower):
    """The levels of one knot's set into lev_a, lev_hi, lev_lo (probes + 2,): the set at the
    accelerations probes (P,) (ascending; FINE_PROBES times as many evenly over [-acc, acc]
    where none meets the set), the ends of the feasible ones refined by bisection against
    their infeasible neighbours; a set that half the probes miss gets its levels again,
    evenly over its refined range. Returns the number of levels (0: the set is empty)."""
    p_n = probes.size
    scale = acc
    grid = probes
    count = p_n
    first, last = _probe(cell, h, cha, chg, chl, nc, peak, valley, grid, count, scale,
                         probe_hi, probe_lo, work, lower)
    if first < 0:
        count = p_n * FINE_PROBES
        grid = np.empty(count)
        for k in range(count):
            grid[k] = -acc + 2.0 * acc * k / (count - 1)
        first, last = _probe(cell, h, cha, chg, chl, nc, peak, valley, grid, count, scale,
                             probe_hi, probe_lo, work, lower)
        if first < 0:
            return 0
    a0, hi0, lo0 = grid[first], probe_hi[first], probe_lo[first]
    if first > 0:
        a0, hi0, lo0 = _refine(cell, h, cha, chg, chl, nc, peak, valley, a0,
                               grid[first - 1], hi0, lo0, scale, work, lower)
    a1, hi1, lo1 = grid[last], probe_hi[last], probe_lo[last]
    if last < count - 1:
        a1, hi1, lo1 = _refine(cell, h, cha, chg, chl, nc, peak, valley, a1,
                               grid[last + 1], hi1, lo1, scale, work, lower)
    m = 0
    if count == p_n and last - first + 1 >= p_n // 2:
        if a0 < grid[first]:
            _store(lev_a, lev_hi, lev_lo, m, a0, hi0, lo0)
            m += 1
        for k in range(first, last + 1):
            _store(lev_a, lev_hi, lev_lo, m, grid[k], probe_hi[k], probe_lo[k])
            m += 1
        if a1 > grid[last]:
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
        hi, lo = _level(cell, a, h, cha, chg, chl, nc, peak, valley, scale, work, lower)
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
        scale = max(abs(p1), 1e-300)
        for sign in (1.0, -1.0):
            out[m, 0] = sign
            out[m, 1] = sign * h
            out[m, 2] = 0.0
            out[m, 3] = sign * (p1 - h * p2) + (MOVING_END_REL if end_kind == 1
                                                else LOOSE_END_REL) * scale
            m += 1
    return m
