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
outside the feasible interval reaches its ends without crossing them (`_probe`), started
from the next knot's boundary at the same acceleration (the sets change little from one knot
to the next). The levels of a knot span the accelerations its set reaches: probed at given
accelerations, the ends found by bisection (`levels`).
"""

from __future__ import annotations

import numpy as np

from nurbsfeed.jit import inline, jit
from nurbsfeed.planning.reach_bounds import GAP_TOL_REL

WIDE_PROBES = 12  # accelerations every set is probed at, evenly over [-A_t, A_t] ...
# ... and, once a motion is known, this many more within FOCUS_REL A_t of its acceleration,
# where the next motion rides the sets' boundaries (chords between levels lie inside a
# concave boundary: the closer the levels, the less of it they cut off)
FOCUS_PROBES = 12
FOCUS_REL = 0.15
# and always at a = 0, where it lies inside the set's range: a cruise at a cap tops its set in
# a corner there, which a chord between two levels either side cuts off (1.6 % of b at 1 mm/s)
KEY_PROBES = 1
MAX_LEVELS = WIDE_PROBES + FOCUS_PROBES + 2 + KEY_PROBES
FINE_PROBES = 8  # times as many probes, evenly, where none meets the set
NEWTON_STEPS = 40
BISECTIONS = 50  # where Newton's method meets a kink it cannot step over
# a first guess from the next knot's set starts this share outside it (a boundary moves
# less than that from one knot to the next, mostly)
WARM_REL = 5e-3
RANGE_TOL_REL = 2e-3  # of the acceleration scale: how closely a set's range ends are found
ROUNDING_REL = 1e-12  # of b: where the chain's peak is met exactly, rounding aside
# the stored boundaries move this share of b into the set: the forward pass lands on them, and
# a state on an edge must keep a way on within rounding
SHRINK_REL = 1e-7
INFEASIBLE = -1.0


@inline
def on_side(v, c, sign):
    """v on the level set's side of c: v >= c (sign 1) or v <= c (sign -1)."""
    return v >= c if sign > 0.0 else v <= c


FIRST, NEWTON, INNER, BISECT = 0, 1, 2, 3  # the phases of a search in `_probe`


@jit
def _probe(cell, h, chain, nc, peak, valley, probes, count, scale, probe_hi, probe_lo, level,
           idx):
    """The set at the accelerations probes[:count] (ascending): at each, into probe_hi and
    probe_lo, the greatest and least b from which some u keeps the cell's rows and leads into
    the next knot's set, INFEASIBLE twice where none does; returns the first and last feasible
    probe (-1: none). The set is convex: the first infeasible probe after a feasible one ends
    the run. cell = (up, down, bounds, U, D, B, a_min, a_max) as `reach_bounds.split_rows`
    gives them; level (4, R): scratch, the bounds on a1 at one acceleration (the upper ones'
    values at b = 0 and their slopes in b, the lower ones' likewise); chain (3, L): the next
    knot's levels' a1, gamma and gamma_lo (nc of them; none for the last cell, whose u the
    end fixes).

    Each end by Newton's method on the gap (the least upper bound on a1 minus the greatest
    lower one, concave in b: its feasible b are an interval) from outside the interval: the
    tangent lies above the gap, so a step never passes the end. It starts from the next
    knot's boundary at the same acceleration, WARM_REL outside it (the sets change little
    from one knot to the next); where that turns out feasible or beyond the interval, from
    the far side (high for the top, low for the bottom); where a kink leaves Newton's method
    no step, bisection against the inner side (low, once found feasible, for the top; the
    top for the bottom).

    All of it is one function, the probes its outer loop, and the gap is evaluated in one
    place, its inner loop, which reads the chain itself rather than through
    `reach_pass.level_interval`: a call that takes arrays costs an atomic reference count on
    each, which was over half of the backward passes' time."""
    up, down, bounds, nu, nd, nb, a_min, a_max = cell
    tol = GAP_TOL_REL * scale
    no_rows = nc == 0 and nu + nd == 0
    first = -1
    final = -1
    for p in range(count):
        a = probes[p]
        b_hi = b_lo = INFEASIBLE
        low, high = 1.0, -1.0  # (none: a outside the range the rows allow)
        if a_min <= a <= a_max:
            # the rows without u bound b alone
            low, high = 0.0, np.inf
            for r in range(nb):
                value = bounds[r, 1] + bounds[r, 2] * a
                if bounds[r, 0] > 0.0:
                    high = min(high, value)
                else:
                    low = max(low, value)
        searching = not low > high and not no_rows
        if searching:
            for r in range(nu):
                level[0, r] = up[r, 0] + up[r, 1] * a
                level[1, r] = up[r, 2]
            for r in range(nd):
                level[2, r] = down[r, 0] + down[r, 1] * a
                level[3, r] = down[r, 2]
            if nc > 0:
                high = min(high, chain[1, peak] - h * a)
                low = max(low, chain[2, valley] - h * a)
            searching = not low > high
        elif not low > high:
            b_hi, b_lo = high, low
        top = bottom = INFEASIBLE
        for end in range(2 if searching else 0):
            upper = end == 0
            # the next knot's boundary at a (chain[1 + end] = boundary - h a1): the first guess
            guess = -1.0
            if nc > 0 and chain[0, 0] <= a <= chain[0, nc - 1]:
                k = 0
                while k < nc - 2 and chain[0, k + 1] < a:
                    k += 1
                if nc == 1 or chain[0, k + 1] <= chain[0, k]:
                    guess = chain[1 + end, k] + h * a
                else:
                    w = (a - chain[0, k]) / (chain[0, k + 1] - chain[0, k])
                    guess = (1.0 - w) * chain[1 + end, k] + w * chain[1 + end, k + 1] + h * a
            if upper:
                inner, far = low, high
                x = high if guess < 0.0 else min(max(guess * (1.0 + WARM_REL), low), high)
            else:
                inner, far = top, low
                x = low if guess < 0.0 else min(max(guess * (1.0 - WARM_REL), low), top)
            beyond = x
            good = bad = 0.0
            phase = FIRST
            steps = 0
            found = -1.0
            while True:
                # the gap at x: the least upper bound on a1 (ceil) minus the greatest lower one
                ceil = np.inf
                ceil_slope = 0.0
                for r in range(nu):
                    value = level[0, r] + level[1, r] * x
                    if value < ceil:
                        ceil, ceil_slope = value, level[1, r]
                floor = -np.inf
                floor_slope = 0.0
                for r in range(nd):
                    value = level[2, r] + level[3, r] * x
                    if value > floor:
                        floor, floor_slope = value, level[3, r]
                gap, slope = ceil - floor, ceil_slope - floor_slope
                if nc > 0:
                    c = x + h * a
                    c_top, c_bottom = chain[1, peak], chain[2, valley]
                    rounding = ROUNDING_REL * (abs(c) + abs(c_top) + abs(c_bottom))
                    for side in range(2):
                        # where the concave chain (chain[0], chain[1]) is >= c, then where the
                        # convex one (chain[0], chain[2]) is <= c: level_interval's lines
                        row, sign, extreme = (1, 1.0, peak) if side == 0 else (2, -1.0, valley)
                        cc = (min(c, c_top) if c - c_top <= rounding else c) if side == 0 \
                            else (max(c, c_bottom) if c_bottom - c <= rounding else c)
                        if not on_side(chain[row, extreme], cc, sign):
                            gap, slope = -np.inf, -sign
                            break
                        slot = 2 * side
                        k = min(max(idx[slot], 0), extreme)
                        while k < extreme and not on_side(chain[row, k], cc, sign):
                            k += 1
                        while k > 0 and on_side(chain[row, k - 1], cc, sign):
                            k -= 1
                        idx[slot] = k
                        if k == 0:
                            lo, dlo = chain[0, 0], 0.0
                        else:
                            w = (chain[0, k] - chain[0, k - 1]) \
                                / (chain[row, k] - chain[row, k - 1])
                            lo, dlo = chain[0, k] - (chain[row, k] - cc) * w, w
                        k = min(max(idx[slot + 1], extreme), nc - 1)
                        while k > extreme and not on_side(chain[row, k], cc, sign):
                            k -= 1
                        while k < nc - 1 and on_side(chain[row, k + 1], cc, sign):
                            k += 1
                        idx[slot + 1] = k
                        if k == nc - 1:
                            hi, dhi = chain[0, nc - 1], 0.0
                        else:
                            w = (chain[0, k + 1] - chain[0, k]) \
                                / (chain[row, k + 1] - chain[row, k])
                            hi, dhi = chain[0, k] + (cc - chain[row, k]) * w, w
                        if lo > hi:
                            gap, slope = -np.inf, -sign
                            break
                        if hi < ceil:
                            ceil, ceil_slope = hi, dhi
                        if lo > floor:
                            floor, floor_slope = lo, dlo
                        gap, slope = ceil - floor, ceil_slope - floor_slope
                if phase == BISECT:
                    if gap >= -tol:
                        good = x
                    else:
                        bad = x
                    steps += 1
                    if steps == BISECTIONS:
                        found = good
                        break
                    x = 0.5 * (good + bad)
                    continue
                if phase == INNER:
                    if gap < -tol:
                        found = -1.0
                        break
                    phase, steps, good, bad = BISECT, 0, inner, beyond
                    x = 0.5 * (good + bad)
                    continue
                if phase == FIRST:
                    phase = NEWTON
                    outward = slope > 0.0 if upper else slope < 0.0
                    if (x < far if upper else x > far) and (gap >= -tol or outward):
                        x = far
                        continue
                if steps == NEWTON_STEPS:
                    found = -1.0 if upper else inner
                    break
                if gap >= -tol:
                    found = x
                    break
                inward = slope < 0.0 if upper else slope > 0.0
                step = x - gap / slope if inward and gap > -np.inf else inner
                if step <= inner if upper else step >= inner:
                    beyond = x
                    if upper:
                        phase = INNER
                        x = inner
                    else:
                        phase, steps, good, bad = BISECT, 0, inner, x
                        x = 0.5 * (good + bad)
                    continue
                x = step
                steps += 1
            if upper:
                top = found
                if top < 0.0:
                    break
            else:
                bottom = found
                b_hi, b_lo = top, bottom
        probe_hi[p] = b_hi
        probe_lo[p] = b_lo
        if b_hi >= 0.0:
            if first < 0:
                first = p
            final = p
        elif first >= 0:
            break
    return first, final


@jit
def _level(cell, a, h, chain, nc, peak, valley, scale, level, idx, one):
    """(high, low) at the acceleration a alone: `_probe` at one point; one (3,): scratch (an
    array a call allocates costs more than the search)."""
    one[0] = a
    count = np.int64(1)  # (a literal 1 compiles _probe a second time)
    _probe(cell, h, chain, nc, peak, valley, one, count, scale, one[1:], one[2:], level, idx)
    return one[1], one[2]


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
def _refine(cell, h, chain, nc, peak, valley, inside, outside, hi, lo, guess, scale, level,
            idx, one):
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
            mh, ml = _level(cell, a, h, chain, nc, peak, valley, scale, level, idx, one)
            if mh >= 0.0:
                inside, hi, lo = a, mh, ml
            else:
                outside = a
                break
            lo_end, hi_end = min(inside, outside), max(inside, outside)
    while abs(outside - inside) > tol:
        mid = 0.5 * (inside + outside)
        mh, ml = _level(cell, mid, h, chain, nc, peak, valley, scale, level, idx, one)
        if mh >= 0.0:
            inside, hi, lo = mid, mh, ml
        else:
            outside = mid
    return inside, hi, lo


@jit
def levels(cell, h, chain, nc, peak, valley, probes, keys, acc, lev_a, lev_hi, lev_lo,
           probe_hi, probe_lo, grid, level, idx, one):
    """The levels of one knot's set into lev_a, lev_hi, lev_lo (probes + 2 + keys,): the set
    at the accelerations probes (P,) (ascending; FINE_PROBES times as many evenly over [-acc,
    acc] where none meets the set, in grid), the ends of the feasible ones refined against
    their infeasible neighbours; a set that half the probes miss gets its levels again, evenly
    over its refined range; and a level at each of keys (NaN: none) inside that range. Returns
    the number of levels (0: the set is empty). probe_hi, probe_lo, grid, level, idx, one:
    scratch."""
    m = _spread(cell, h, chain, nc, peak, valley, probes, acc, lev_a, lev_hi, lev_lo,
                probe_hi, probe_lo, grid, level, idx, one)
    for key in keys:
        if not (m > 1 and lev_a[0] < key < lev_a[m - 1]):
            continue
        k = np.int64(0)  # not a literal: one compilation of what it is passed to
        while lev_a[k] < key:
            k += 1
        if lev_a[k] == key:
            continue
        hi, lo = _level(cell, key, h, chain, nc, peak, valley, acc, level, idx, one)
        if hi < 0.0:
            continue
        for i in range(m, k, -1):
            lev_a[i], lev_hi[i], lev_lo[i] = lev_a[i - 1], lev_hi[i - 1], lev_lo[i - 1]
        _store(lev_a, lev_hi, lev_lo, k, key, hi, lo)
        m += 1
    return m


@jit
def _spread(cell, h, chain, nc, peak, valley, probes, acc, lev_a, lev_hi, lev_lo, probe_hi,
            probe_lo, grid, level, idx, one):
    """`levels` but the keys."""
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
            # a set narrower than the fine probes' spacing (a cell of half a micrometre at a
            # hundredth of a mm/s beside a 0.1 um turn): probed at a = 0 and at the next
            # knot's levels, where the motion may go on
            count = _near_next(chain, nc, grid)
            points = grid[:count]
            first, last = _probe(cell, h, chain, nc, peak, valley, points, count, scale,
                                 probe_hi, probe_lo, level, idx)
            if first < 0:
                return 0
    ends_a = (chain[0, 0], chain[0, nc - 1]) if nc > 0 else (np.nan, np.nan)
    a0, hi0, lo0 = points[first], probe_hi[first], probe_lo[first]
    if first > 0:
        a0, hi0, lo0 = _refine(cell, h, chain, nc, peak, valley, a0, points[first - 1], hi0,
                               lo0, ends_a[0], scale, level, idx, one)
    a1, hi1, lo1 = points[last], probe_hi[last], probe_lo[last]
    if last < count - 1:
        a1, hi1, lo1 = _refine(cell, h, chain, nc, peak, valley, a1, points[last + 1], hi1,
                               lo1, ends_a[1], scale, level, idx, one)
    m = np.int64(0)  # (a literal 0 compiles _store a second time)
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
        hi, lo = _level(cell, a, h, chain, nc, peak, valley, scale, level, idx, one)
        if hi >= 0.0:
            _store(lev_a, lev_hi, lev_lo, m, a, hi, lo)
            m += 1
    _store(lev_a, lev_hi, lev_lo, m, a1, hi1, lo1)
    return m + 1


@jit
def _near_next(chain, nc, out):
    """The next knot's levels' accelerations (chain[0], nc of them, ascending) and 0, ascending
    and distinct, into out; returns the count."""
    n = 0
    zero_in = False
    for k in range(nc):
        x = chain[0, k]
        if not zero_in and x >= 0.0:
            zero_in = True
            if x > 0.0:
                out[n] = 0.0
                n += 1
        if n == 0 or x > out[n - 1]:
            out[n] = x
            n += 1
    if not zero_in:
        out[n] = 0.0
        n += 1
    return n


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
