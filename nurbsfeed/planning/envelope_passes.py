"""The envelope planner's passes (planning.envelope, design §2e): each lowers the spline's
coefficients c to the greatest values one kind of bound allows, in closed form, and returns the
largest relative change it made. Compiled kernels, written once in numba's subset."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit

LIFT_STEPS = 30  # Newton steps of `_lift_pass`, bracketed
PICK_SHARE = 0.5  # `_row_pass`: a weight this share of the largest is a bound on the slope


@jit
def _slope_passes(xi, c, w, rows, first, last):
    """The rows alpha b' + beta b <= gamma at each knot (`_slope_rows`: gamma a budget, over
    sqrt(b) for a jerk), over coefficients first..last: on the
    interval between c_i and c_i+1 the slope is (c_i+1 - c_i) / g and b = w_i c_i +
    (1 - w_i) c_i+1, so a row reads A c_i + B c_i+1 <= gamma. The forward pass lowers c_i+1 to
    what c_i allows where B > 0, the backward pass c_i to what c_i+1 allows where A > 0; where
    both are positive (neither is a pure bound on the slope) a row broken lowers both in
    proportion. Returns the largest relative change."""
    change = 0.0
    for direction in range(2):
        for step in range(last - first):
            i = first + step if direction == 0 else last - 1 - step
            g = xi[i + 1] - xi[i]
            for r in range(rows.shape[1]):
                alpha, beta, gamma = rows[i, r, 0], rows[i, r, 1], rows[i, r, 2]
                if gamma == np.inf:
                    continue
                if rows[i, r, 3] > 0.0:
                    # a jerk's budget over sqrt(b) at the knot as it is now: it grows as b
                    # falls, so lowering b never chases a bound that does not relax
                    gamma /= math.sqrt(max(w[i] * c[i] + (1.0 - w[i]) * c[i + 1], 1e-300))
                coef_a = -alpha / g + beta * w[i]
                coef_b = alpha / g + beta * (1.0 - w[i])
                have = coef_a * c[i] + coef_b * c[i + 1]
                if have <= gamma:
                    continue
                if coef_a > 0.0 and coef_b > 0.0:
                    shrink = gamma / have
                    change = max(change, 1.0 - shrink)
                    c[i] *= shrink
                    c[i + 1] *= shrink
                elif direction == 0 and coef_b > 0.0:
                    most = max((gamma - coef_a * c[i]) / coef_b, 0.0)
                    change = max(change, (c[i + 1] - most) / max(c[i + 1], 1e-300))
                    c[i + 1] = most
                elif direction == 1 and coef_a > 0.0:
                    most = max((gamma - coef_b * c[i + 1]) / coef_a, 0.0)
                    change = max(change, (c[i] - most) / max(c[i], 1e-300))
                    c[i] = most
    return change


@jit
def _convex_pass(xi, c, width, lo, first, last, phi, hull):
    """b'' >= lo: c <= phi + the lower convex hull of c - phi over coefficients first..last,
    where b'' at an inner coefficient i is (slope_i - slope_i-1) / width_i (slope_i between
    c_i and c_i+1) and phi has b'' = lo there. Returns the largest relative change."""
    if last - first < 2:
        return 0.0
    phi[first] = 0.0
    slope = 0.0
    for i in range(first, last):
        if i > first:
            slope += lo[i] * width[i]
        phi[i + 1] = phi[i] + slope * (xi[i + 1] - xi[i])
    top = 0  # Andrew's monotone chain over (xi_i, c_i - phi_i)
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
            change = max(change, (c[i] - most) / max(c[i], 1e-300))
            c[i] = most
    return change


@jit
def _lift_pass(xi, c, width, lo_axes, kappa2, jerk, first, last):
    """b'' >= max(lo_axes, 2 kappa^2 b - 2 J_t / sqrt(b)) one coefficient at a time (forward,
    then backward), b taken as the coefficient itself: each inner coefficient lowered to the
    largest value at which its cell curves up enough between its neighbours (bisection: the
    curvature falls and the bound rises as it grows). Returns the largest relative change."""
    change = 0.0
    for direction in range(2):
        for step in range(last - first - 1):
            i = first + 1 + step if direction == 0 else last - 1 - step
            g0, g1 = xi[i] - xi[i - 1], xi[i + 1] - xi[i]
            pull = c[i - 1] / g0 + c[i + 1] / g1
            weight = 1.0 / g0 + 1.0 / g1
            x = c[i]
            if (pull - x * weight) / width[i] >= max(
                    lo_axes[i], 2.0 * kappa2[i] * x - 2.0 * jerk[i] / math.sqrt(max(x, 1e-300))):
                continue
            # the room minus the bound falls as x grows: Newton, kept inside the bracket
            # [low, high] (bisection where it would leave it); low always keeps the bound
            low, high = 0.0, x
            guess = x
            for _ in range(LIFT_STEPS):
                root = math.sqrt(max(guess, 1e-300))
                tangential = 2.0 * kappa2[i] * guess - 2.0 * jerk[i] / root
                room = (pull - guess * weight) / width[i]
                if room >= max(lo_axes[i], tangential):
                    low = guess
                else:
                    high = guess
                if high - low <= 1e-9 * x:
                    break
                if lo_axes[i] >= tangential:
                    target = (pull - lo_axes[i] * width[i]) / weight
                else:
                    slope = -weight / width[i] - 2.0 * kappa2[i] - jerk[i] / (root * guess)
                    target = guess - (room - tangential) / slope
                if not low < target < high:
                    target = 0.5 * (low + high)
                guess = target
            change = max(change, (c[i] - low) / max(c[i], 1e-300))
            c[i] = low
    return change


ROOT_STEPS = 40  # bisections of `_row_root`: 2^-40 of the coefficient's drop


@jit
def _row_root(row, left, middle, right, j, low, high):
    """The greatest x in [low, high] keeping row (A, B, C, budget, weights of b) with
    coefficient j (0, 1, 2: left, middle, right) set to x, low if none does: the row's left
    side falls with x and its b does too (budget / sqrt(b) grows), so the row holds from some
    x down, if from any."""
    for _ in range(ROOT_STEPS):
        if high - low <= 1e-12 * high:
            break
        x = 0.5 * (low + high)
        x0 = x if j == 0 else left
        x1 = x if j == 1 else middle
        x2 = x if j == 2 else right
        have = row[0] * x0 + row[1] * x1 + row[2] * x2
        if have <= row[3] / math.sqrt(max(row[4] * x0 + row[5] * x1 + row[6] * x2, 1e-300)):
            low = x
        else:
            high = x
    return low


@jit
def _row_pass(c, rows, first, last, backward_first):
    """Rows A c_k-1 + B c_k + C c_k+1 <= budget / sqrt(b) (`_cell_rows`) on the inner
    coefficients first+1..last-1, forward then backward (backward then forward with
    backward_first): a broken row lowers the coefficient ahead in the sweep where its weight is
    near the largest (a bound on how fast b may change), else the one of the largest weight.
    The first sweep settles most rows, each by the coefficient ahead of it, so a pass run in
    one order alone sinks the side of every valley the motion comes down (`envelope._profile`
    alternates the order). Returns the largest relative change."""
    change = 0.0
    for order in range(2):
        direction = 1 - order if backward_first else order
        for step in range(last - first - 1):
            k = first + 1 + step if direction == 0 else last - 1 - step
            for r in range(rows.shape[1]):
                gamma = rows[k, r, 3]
                if gamma == np.inf:
                    continue
                have = rows[k, r, 0] * c[k - 1] + rows[k, r, 1] * c[k] + rows[k, r, 2] * c[k + 1]
                if have <= 0.0:  # (gamma >= 0: held, and no square root to take)
                    continue
                # the jerk's budget over sqrt(b) at the row's point as it is now (it relaxes
                # as b falls)
                gamma /= math.sqrt(max(rows[k, r, 4] * c[k - 1] + rows[k, r, 5] * c[k]
                                       + rows[k, r, 6] * c[k + 1], 1e-300))
                if have <= gamma:
                    continue
                # the coefficient ahead in the sweep if its weight is within PICK_SHARE of the
                # largest positive one (a bound on the slope), else the largest: a tiny weight
                # would take the whole excess and drive that coefficient to 0
                largest = max(rows[k, r, 0], rows[k, r, 1], rows[k, r, 2])
                if largest <= 0.0:
                    continue
                j = 2 if direction == 0 else 0
                if rows[k, r, j] < PICK_SHARE * largest:
                    j = 0
                    for q in range(1, 3):
                        if rows[k, r, q] > rows[k, r, j]:
                            j = q
                if (rows[k, r, 0] > 0.0 and rows[k, r, 2] > 0.0 and c[k] <= c[k - 1]
                        and c[k] <= c[k + 1]):
                    # a minimum curving up too fast: both sides come down, each by its share
                    outer = rows[k, r, 0] * c[k - 1] + rows[k, r, 2] * c[k + 1]
                    shrink = max(1.0 - (have - gamma) / outer, 0.0)
                    floor = c[k]
                    for var in (k - 1, k + 1):
                        most = max(floor, c[var] * shrink)
                        change = max(change, (c[var] - most) / max(c[var], 1e-300))
                        c[var] = most
                    continue
                weight = rows[k, r, j]
                var = k - 1 + j
                most = max(c[var] - (have - gamma) / weight, 0.0)
                if most <= 0.0:  # the step took the budget at b as it was: b falls with it
                    most = _row_root(rows[k, r], c[k - 1], c[k], c[k + 1], j, most, c[var])
                if most <= 0.0:
                    # no value of this coefficient keeps the row: b = 0 inside the stretch (a
                    # motion that never arrives, cam-32 of tests/bench/dense_curves.py) where
                    # lowering another would do; lower the one the row asks least of, as a
                    # share of it
                    best = 2.0
                    for q in range(3):
                        if rows[k, r, q] <= 0.0 or c[k - 1 + q] <= 0.0:
                            continue
                        low = max(c[k - 1 + q] - (have - gamma) / rows[k, r, q], 0.0)
                        root = _row_root(rows[k, r], c[k - 1], c[k], c[k + 1], q, low,
                                         c[k - 1 + q])
                        if root > 0.0 and 1.0 - root / c[k - 1 + q] < best:
                            best, var, most = 1.0 - root / c[k - 1 + q], k - 1 + q, root
                change = max(change, (c[var] - most) / max(c[var], 1e-300))
                c[var] = most
    return change


@jit
def _round_pass(xi, c, width, hi, first, last):
    """b'' <= hi over coefficients first..last: where c rises, c_i+1 from c_i-1 and c_i; where
    it falls, c_i-1 from c_i and c_i+1; at a minimum (a = 0 there), c <= c_min + psi on both
    sides, psi'' = hi, each side's first slope taking half the room. Returns the largest
    relative change."""
    change = 0.0
    for i in range(first + 1, last):
        g0, g1 = xi[i] - xi[i - 1], xi[i + 1] - xi[i]
        if c[i - 1] <= c[i] <= c[i + 1]:
            most = c[i] + g1 * ((c[i] - c[i - 1]) / g0 + hi[i] * width[i])
            if most < c[i + 1]:
                change = max(change, (c[i + 1] - most) / max(c[i + 1], 1e-300))
                c[i + 1] = max(most, c[i])
    for i in range(last - 1, first, -1):
        g0, g1 = xi[i] - xi[i - 1], xi[i + 1] - xi[i]
        if c[i - 1] >= c[i] >= c[i + 1]:
            most = c[i] + g0 * ((c[i] - c[i + 1]) / g1 + hi[i] * width[i])
            if most < c[i - 1]:
                change = max(change, (c[i - 1] - most) / max(c[i - 1], 1e-300))
                c[i - 1] = max(most, c[i])
    for m in range(first + 1, last):
        if not (c[m] <= c[m - 1] and c[m] <= c[m + 1]):
            continue
        g0, g1 = xi[m] - xi[m - 1], xi[m + 1] - xi[m]
        if (c[m + 1] - c[m]) / g1 + (c[m - 1] - c[m]) / g0 <= hi[m] * width[m]:
            continue
        slope = 0.5 * hi[m] * width[m]
        cap = c[m]
        for k in range(m, last):
            if k > m:
                slope += hi[k] * width[k]
            cap += max(slope, 0.0) * (xi[k + 1] - xi[k])
            if cap >= c[k + 1]:
                break
            change = max(change, (c[k + 1] - cap) / max(c[k + 1], 1e-300))
            c[k + 1] = cap
        slope = 0.5 * hi[m] * width[m]
        cap = c[m]
        for k in range(m, first, -1):
            if k < m:
                slope += hi[k] * width[k]
            cap += max(slope, 0.0) * (xi[k] - xi[k - 1])
            if cap >= c[k - 1]:
                break
            change = max(change, (c[k - 1] - cap) / max(c[k - 1], 1e-300))
            c[k - 1] = cap
    return change


@jit
def _rest_pass(c, ratio, first, last):
    """Beside a rest, b = b_far y^(4/3) joins the spline C1 only if c_1 = ratio c_0 (and
    likewise at the stretch's other end): each is lowered to what the other allows."""
    change = 0.0
    for end, inner, r in ((first, first + 1, ratio[0]), (last, last - 1, ratio[1])):
        if c[inner] > r * c[end]:
            change = max(change, (c[inner] - r * c[end]) / max(c[inner], 1e-300))
            c[inner] = r * c[end]
        if c[end] > c[inner] / r:
            change = max(change, (c[end] - c[inner] / r) / max(c[end], 1e-300))
            c[end] = c[inner] / r
    return change
