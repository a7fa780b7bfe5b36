"""The envelope planner (profile key `planner: envelope`, design §2e): the greatest squared
speed b = v^2 over arc length that the path model's limits allow, found by closed-form passes
over the nodes instead of linear programs.

Along C(s), with K = kappa N and K_s = dK/ds, b' = db/ds and b'' = d2b/ds2:

    velocity = sqrt(b) T,  acceleration = b'/2 T + b K,  jerk = sqrt(b) (b''/2 T + 3/2 b' K + b K_s)

With sqrt(b), b' and b'' frozen where they multiply a limit (each pass freezes them at the last
profile and the passes repeat), every limit is one of three kinds at a node:

- a cap, b <= B (chord error, normal acceleration, feed, axis velocities, binormal jerk, jumps
  of kappa N at knots);
- a slope bound linear in b on each interval, b' <= p + q b or b' >= p + q b (the tangential
  and axis accelerations, the normal jerk, an axis's jerk where the path runs nearly across the
  axis): the forward pass lowers b_i+1 to what b_i allows, the backward pass b_i to what b_i+1
  allows. Each pass is exact, so the two give the greatest profile under these bounds (the
  classic forward and backward passes of time-optimal path parametrization, TOPP-RA's
  controllable sets in closed form);
- a bound on the curvature of b(s), L <= b'' <= U (the tangential jerk, j - kappa^2 v^3, and
  each axis's jerk): b'' >= L keeps a deceleration from starting abruptly. With phi'' = L, it
  says b - phi is convex, so the greatest profile under it is phi plus the lower convex hull of
  b - phi, one pass. b'' <= U rounds every speed minimum: at a minimum a = b'/2 = 0, so on
  either side b cannot rise above b_min + psi, psi'' = U, psi = psi' = 0 there; and where b
  rises or falls, the next node cannot outrun the curvature U allows from the last two.

The passes only ever lower b, so they stop; what they stop at keeps every bound at every node.
Why it is near the optimum: each kind of bound is met with equality wherever it binds (the
passes take the greatest value each bound allows), and the law's own jerk j = sqrt(b) b''/2 is
free to follow kappa^2 v^3 at a curvature peak, where the S-curve planner holds it at zero.

The law and its verification are the optimal planner's (planning.optimal): b on cubic Hermite
cells (constant jerk from a rest), sampled into a spline in time, every path-model quantity
measured twice a period; where one exceeds its limit, the limits of that cell and its
neighbours are lowered by the ratio and the passes run again (FIX_ROUNDS).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.jit import jit
from nurbsfeed.planning.grid import Grid
from nurbsfeed.planning.limits import Limits, speed_limit
from nurbsfeed.planning.optimal import (
    MAX_NODES,
    SAMPLES_PER_PERIOD,
    Schedule,
    _arc_at,
    _cell_ratios,
    _cell_times,
    _hermite_basis,
    _jumps,
    _Nodes,
    _refined,
    cycle_s,
    schedule_nodes,
)
from nurbsfeed.planning.path_model import frames, jump_speeds, static_limit
from nurbsfeed.planning.timelaw import TimeLaw

# each round raises the last round's profile by this factor (of b) at most, then lowers it to
# what the limits allow with their terms frozen at the raised one: the factors fall to 1 so
# that the last rounds' frozen terms are within a per cent of the profile they shape
GROWTH = (2.0, 1.5, 1.5, 1.3, 1.3, 1.2, 1.1, 1.05, 1.03, 1.02, 1.01, 1.0)
INNER_ROUNDS = 60  # cap, slope and curvature passes of the last round, at most
EARLY_ROUNDS = 10  # ... of the rounds before it, which only shape the terms to freeze
CONVERGED_REL = 1e-4  # a pass lowering no b by more than this share of it: converged
LIFT_STEPS = 30  # Newton steps of `_lift_pass`, bracketed
FIX_ROUNDS = 4  # rounds that lower the limits where the law exceeds them
FIX_REL = 0.01  # ... while it does so by more than this
FIX_WORST = 1.5  # ... and while their profile lasts less than this times the best plan's
REFINE_ROUNDS = 2  # times cells lasting longer than the optimal planner's limit are split
TINY = 1e-12
LAW_CHUNK = 1 << 14  # samples `sampled_law` finds the arc length of at once
# the law has a piece a sample: past this many periods a curve keeps the S-curve plan, whose
# pieces do not grow with its duration (a two-hour curve's law would take 1.2 GB)
MAX_LAW_PERIODS = 1_000_000


def _geometry(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    """Per point (N,): kappa, dkappa/ds, T (3), K = kappa N (3), K_s (3), tau, as (N, 12)."""
    f = frames(curve, u)
    k = f.kappa[:, None]
    k_s = (-(f.kappa**2)[:, None] * f.tangent + f.dkappa_ds[:, None] * f.normal
           + (f.kappa * f.torsion)[:, None] * f.binormal)
    return np.ascontiguousarray(np.column_stack([f.kappa, f.dkappa_ds, f.tangent, k * f.normal,
                                                 k_s, f.torsion]))


def _caps(curve: NurbsCurve, lim: Limits, u: np.ndarray, feed_mm_s: np.ndarray) -> np.ndarray:
    """The speed limit (N,) where b' and b'' play no part: `limits.speed_limit`, the axis
    velocities, the binormal jerk sqrt(b) kappa tau b <= J_n, jumps of kappa N at knots, and
    where the path is straight (kappa = 0) the normal jerk kappa' v^3 <= J_n."""
    f = frames(curve, u)
    cap = np.minimum(speed_limit(f.kappa, lim, feed_mm_s), jump_speeds(_jumps(curve, u), lim))
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(f.tangent[:, x])
            cap = np.minimum(cap, np.where(tx > 0.0, lim.axis_vel_mm_s[x]
                                           / np.where(tx > 0.0, tx, 1.0), np.inf))
        kt = np.abs(f.kappa * f.torsion)
        cap = np.minimum(cap, np.where(kt > 0.0, np.cbrt(lim.normal_jerk_mm_s3
                                                         / np.where(kt > 0.0, kt, 1.0)), np.inf))
        straight = (f.kappa <= TINY) & (np.abs(f.dkappa_ds) > 0.0)
        cap = np.where(straight, np.minimum(cap, np.cbrt(
            lim.normal_jerk_mm_s3 / np.where(straight, np.abs(f.dkappa_ds), 1.0))), cap)
    return np.minimum(cap, lim.feed_mm_s)


ROWS = 10  # first-order rows a knot: two sides of 5 limits


@jit
def _slope_rows(geo, scale, acc, jerk_n, axis_acc, rows):
    """Per knot (K,): rows[i, r] = (alpha, beta, budget, root) with alpha b' + beta b <=
    budget / sqrt(b) where root is 1, <= budget where it is 0: both sides of the tangential
    acceleration, each axis's acceleration and the normal jerk |3/2 kappa b' + kappa' b|
    sqrt(b) <= J_n. A row that does not apply has budget inf."""
    for i in range(rows.shape[0]):
        for r in range(rows.shape[1]):
            rows[i, r, 0] = 0.0
            rows[i, r, 1] = 0.0
            rows[i, r, 2] = np.inf
            rows[i, r, 3] = 0.0
        s2 = scale[i] * scale[i]
        s3 = s2 * scale[i]
        kappa, dkappa = geo[i, 0], geo[i, 1]
        for side in range(2):
            sign = 1.0 if side == 0 else -1.0
            rows[i, side, 0] = sign
            rows[i, side, 2] = 2.0 * acc * s2
            rows[i, 2 + side, 0] = sign * 1.5 * kappa
            rows[i, 2 + side, 1] = sign * dkappa
            rows[i, 2 + side, 2] = jerk_n * s3
            rows[i, 2 + side, 3] = 1.0
            for x in range(3):
                if axis_acc[x] < np.inf:
                    rows[i, 4 + 2 * x + side, 0] = sign * 0.5 * geo[i, 2 + x]
                    rows[i, 4 + 2 * x + side, 1] = sign * geo[i, 5 + x]
                    rows[i, 4 + 2 * x + side, 2] = axis_acc[x] * s2


def _tangential_bounds(kappa: np.ndarray, b: np.ndarray, root: np.ndarray,
                       jerk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point (N,): L <= b'' <= U from the tangential jerk |b''/2 - kappa^2 b| sqrt(b) <= J_t,
    with sqrt(b) frozen at root and jerk the (scaled) limit."""
    return 2.0 * kappa**2 * b - 2.0 * jerk / root, 2.0 * kappa**2 * b + 2.0 * jerk / root


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


@jit
def _row_pass(c, rows, first, last):
    """Rows A c_k-1 + B c_k + C c_k+1 <= budget / sqrt(b) (`_cell_rows`) on the inner
    coefficients first+1..last-1,
    forward then backward: a broken row lowers the coefficient ahead in the sweep where its
    weight is near the largest (a bound on how fast b may change), else the one of the largest
    weight. Returns the largest relative change."""
    change = 0.0
    for direction in range(2):
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


def _rest_caps(lim: Limits, nodes: _Nodes, geo: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """A cap on b (M,) at the far node of each cell beside a rest, where b = b_far y^(4/3) runs
    at constant jerk j = 2/9 b_far^1.5 / h^2 and acceleration up to 2/3 b_far / h: within the
    tangential limits and, along the tangent, each axis's."""
    cap = np.full(nodes.s_mm.size, np.inf)
    rest = nodes.rest
    from_rest = np.flatnonzero(rest[:-1] & ~rest[1:])
    into_rest = np.flatnonzero(rest[1:] & ~rest[:-1])
    far = np.concatenate([from_rest + 1, into_rest])
    if far.size == 0:
        return cap
    h = nodes.h_mm[np.concatenate([from_rest, into_rest])]
    jerk = np.full(far.size, lim.jerk_mm_s3)
    acc = np.full(far.size, lim.acc_mm_s2)
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(geo[far, 2 + x])
            safe = np.where(tx > 0.0, tx, 1.0)
            jerk = np.minimum(jerk, np.where(tx > 0.0, lim.axis_jerk_mm_s3[x] / safe, np.inf))
            acc = np.minimum(acc, np.where(tx > 0.0, lim.axis_acc_mm_s2[x] / safe, np.inf))
    sc = scale[far]
    np.minimum.at(cap, far, np.minimum((4.5 * jerk * sc**3 * h**2) ** (2 / 3),
                                       1.5 * acc * sc**2 * h))
    return cap


class _Spline:
    """The quadratic spline b(s) of each stretch between rests: its knots are the stretch's
    nodes but the two beside the rests (those cells are b_far y^(4/3)), its coefficients c
    (C,) of all stretches one after another. Coefficient k of a stretch of K knots sits at the
    Greville point xi_k (the first knot, each cell's middle, the last knot); the slope between
    c_k and c_k+1 is b' at knot k, where b = w_k c_k + (1 - w_k) c_k+1; b'' on cell k-1 is
    (slope_k - slope_k-1) / width_k."""

    def __init__(self, nodes: _Nodes) -> None:
        s = nodes.s_mm
        rests = np.flatnonzero(nodes.rest)
        xi, w, width, knot, cell, ratio, ranges = [], [], [], [], [], [], []
        offset = 0
        for a, e in zip(rests[:-1], rests[1:]):
            knots = np.arange(a + 1, e)  # (K,)
            h = np.diff(s[knots])  # (K-1,) cells
            xi.append(np.concatenate([[s[a + 1]], 0.5 * (s[knots[:-1]] + s[knots[1:]]),
                                      [s[e - 1]]]))
            inner = h[1:] / (h[:-1] + h[1:])
            w.append(np.concatenate([[1.0], inner, [0.0], [0.5]]))  # the last: no interval
            width.append(np.concatenate([[1.0], h, [1.0]]))
            knot.append(np.concatenate([knots, [knots[-1]]]))
            cell.append(np.concatenate([[knots[0]], knots[:-1], [knots[-2]]]))
            rest_h = (s[a + 1] - s[a], s[e] - s[e - 1])
            ratio.append((1.0 + 2.0 / 3.0 * h[0] / rest_h[0], 1.0 + 2.0 / 3.0 * h[-1] / rest_h[1]))
            ranges.append((offset, offset + knots.size))
            offset += knots.size + 1
        self.xi = np.concatenate(xi)
        self.w = np.concatenate(w)
        self.width = np.concatenate(width)
        self.knot = np.concatenate(knot)  # (C,): the node of the knot after coefficient k
        self.cell = np.concatenate(cell)  # (C,): the node starting coefficient k's cell
        self.ratio = np.array(ratio)
        self.ranges = ranges
        self.nodes = nodes

    def at_nodes(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """b and b' (M,) at the nodes (0 at rests) and b'' (M-1,) on each cell (0 on a rest
        cell), from coefficients c (C,)."""
        m = self.nodes.s_mm.size
        b, d, dd = np.zeros(m), np.zeros(m), np.zeros(m - 1)
        for first, last in self.ranges:
            cs = c[first:last + 1]
            knots = self.knot[first:last]
            slope = np.diff(cs) / np.diff(self.xi[first:last + 1])
            ws = self.w[first:last]
            b[knots] = ws * cs[:-1] + (1.0 - ws) * cs[1:]
            d[knots] = slope
            dd[knots[:-1]] = np.diff(slope) / self.width[first + 1:last]
        return b, d, dd


def _coefficient_caps(spline: _Spline, node_cap: np.ndarray, mid_cap: np.ndarray,
                      rest_cap: np.ndarray) -> np.ndarray:
    """Caps (C,) on the coefficients from caps on b at the nodes (M,) and the cells' middles
    (M-1,): b on a cell is a convex combination of its three coefficients, so each is capped
    by the lowest cap of the cells it shapes; the ends by their knots' (and the rest cells')."""
    m = node_cap.size
    cell_cap = np.minimum(np.minimum(node_cap[:-1], node_cap[1:]), mid_cap)
    cap = np.empty(spline.xi.size)
    for first, last in spline.ranges:
        cells = spline.cell[first:last + 1]
        cap[first:last + 1] = np.minimum(cell_cap[cells], np.minimum(
            cell_cap[np.maximum(cells - 1, 0)], cell_cap[np.minimum(cells + 1, m - 2)]))
        for end in (first, last):
            knot = spline.knot[end]
            cap[end] = min(cap[end], node_cap[knot], rest_cap[knot])
    return np.maximum(cap, 0.0)


POINTS = (0.0, 0.5, 1.0)  # where a cell's rows hold, as a share of its length
ROWS3 = 2 * 4 * len(POINTS)  # rows a cell: two sides of the normal jerk and three axes'
ALONG = 0.3  # |T_x| from which an axis's jerk joins the tangential bounds on b''
PICK_SHARE = 0.5  # `_row_pass`: a weight this share of the largest is a bound on the slope


def _cell_rows(spline: _Spline, s: np.ndarray, geo: np.ndarray, geo_end: np.ndarray,
               geo_mid: np.ndarray,
               scale: np.ndarray, mid_scale: np.ndarray, jump: np.ndarray, upper_b: np.ndarray,
               b: np.ndarray, d: np.ndarray, lim: Limits
               ) -> tuple[np.ndarray, ...]:
    """What holds on each inner coefficient's cell (C,), at its two ends and its middle:

    - L <= b'' <= U of the tangential jerk, the tightest of the three points: sqrt(b) at the
      cell's largest b and L's term in b at upper_b (M,) (the ceiling: b only falls below it,
      so L is conservative), U's at b (M,), the last profile;
    - the largest kappa^2 and the least scale^3 (`_lift_pass` solves b'' >= 2 kappa^2 b -
      2 J_t / sqrt(b) for b itself where L > 0);
    - rows (C, ROWS3, 7): (A, B, C, budget, weights of b) with A c_k-1 + B c_k + C c_k+1 <=
      budget / sqrt(b) (b at the point, from the weights): the normal jerk and each axis's,
      |b''/2 T_x + 3/2 b' K_x + b K_s,x| sqrt(b) + b |D_x| / T <= J_x, both sides, linear in the
      three coefficients that shape the cell (the jump term at upper_b)."""
    m = s.size
    n = spline.xi.size
    first = spline.cell
    after = np.minimum(first + 1, m - 1)
    cell = np.minimum(first, m - 2)
    h = s[after] - s[first]

    def middle(values: np.ndarray, slopes: np.ndarray) -> np.ndarray:
        return 0.5 * (values[first] + values[after]) - h / 8.0 * (slopes[after] - slopes[first])

    top = np.maximum(np.maximum(upper_b[first], upper_b[after]), middle(upper_b, d))
    root = np.sqrt(np.maximum(top, 1e-300))
    at = ((geo[first], b[first], upper_b[first], scale[first], jump[first]),
          (geo_mid[cell], middle(b, d), middle(upper_b, d), mid_scale[cell], np.zeros((n, 3))),
          (geo_end[after], b[after], upper_b[after], scale[after], jump[after]))
    b_at = {0.0: b[first], 0.5: middle(b, d), 1.0: b[after]}
    d_at = {0.0: d[first], 0.5: 0.5 * (d[first] + d[after]), 1.0: d[after]}
    lo = np.full(n, -np.inf)
    hi = np.full(n, np.inf)
    kappa2 = np.zeros(n)
    scale3 = np.full(n, np.inf)
    for g, bb, b_up, sc, _ in at:
        jerk = lim.jerk_mm_s3 * sc**3
        lo = np.maximum(lo, _tangential_bounds(g[:, 0], b_up, root, jerk)[0])
        hi = np.minimum(hi, _tangential_bounds(g[:, 0], bb, root, jerk)[1])
        kappa2 = np.maximum(kappa2, g[:, 0] ** 2)
        scale3 = np.minimum(scale3, sc**3)
    # the three coefficients' weights in b, b' and b'' at a share x of the cell (k inner)
    xi, w, width = spline.xi, spline.w, spline.width
    k = np.arange(n)
    g_left = np.where(k > 0, xi - np.roll(xi, 1), 1.0)
    g_right = np.where(k < n - 1, np.roll(xi, -1) - xi, 1.0)
    left_w = np.roll(w, 1)  # the weight of c_k-1 in the knot value where the cell starts
    d_left = np.stack([-1.0 / g_left, 1.0 / g_left, np.zeros(n)], axis=1)
    d_right = np.stack([np.zeros(n), -1.0 / g_right, 1.0 / g_right], axis=1)
    curve2 = (d_right - d_left) / width[:, None]
    start = np.stack([left_w, 1.0 - left_w, np.zeros(n)], axis=1)
    rows = np.zeros((n, ROWS3, 7))
    rows[:, :, 3] = np.inf
    lo_axes = np.full(n, -np.inf)
    r = 0
    for x, (g, _, b_up, sc, jp) in zip(POINTS, at):
        slope = (1.0 - x) * d_left + x * d_right
        value = start + width[:, None] * (x * d_left + 0.5 * x * x * (d_right - d_left))
        # the normal jerk |3/2 kappa b' + kappa' b| sqrt(b) within what the binormal's
        # kappa tau b^1.5 leaves of J_n
        binormal = np.abs(g[:, 0] * g[:, 11]) * np.maximum(b_up, 0.0) ** 1.5
        budget_n = np.sqrt(np.maximum((lim.normal_jerk_mm_s3 * sc**3) ** 2 - binormal**2,
                                      0.0))
        coef = 1.5 * g[:, 0, None] * slope + g[:, 1, None] * value
        for sign in (1.0, -1.0):
            rows[:, r, :3] = sign * coef
            rows[:, r, 3] = budget_n
            rows[:, r, 4:] = value
            r += 1
        for axis in range(3):
            if not math.isfinite(lim.axis_jerk_mm_s3[axis]):
                r += 2
                continue
            t_x = g[:, 2 + axis]
            budget = np.maximum(lim.axis_jerk_mm_s3[axis] * sc**3
                                - b_up * jp[:, axis] / lim.period_s, 0.0)
            along = np.abs(t_x) >= ALONG
            # along the axis the row bounds b'' (with b' and b frozen at the last profile) and
            # joins the tangential bounds, which the hull and the rounding pass meet in one
            # sweep (the row pass would creep there, a coefficient at a time); across it b''
            # weighs little and the row pass holds the row itself
            e = 1.5 * g[:, 5 + axis] * d_at[x] + g[:, 8 + axis] * b_at[x]
            safe = np.where(along, t_x, 1.0)
            first_bound = 2.0 * (budget / root - e) / safe
            second_bound = 2.0 * (-budget / root - e) / safe
            lo_axes = np.where(along, np.maximum(lo_axes, np.minimum(first_bound, second_bound)),
                               lo_axes)
            # a frozen b' that overstates the one the new profile takes can ask b'' < 0 all
            # along a stretch, and the rounding pass would sink the whole stretch: hi >= 0
            hi = np.where(along, np.minimum(hi, np.maximum(np.maximum(first_bound,
                                                                      second_bound), 0.0)), hi)
            coef = (0.5 * t_x[:, None] * curve2 + 1.5 * g[:, 5 + axis, None] * slope
                    + g[:, 8 + axis, None] * value)
            for sign in (1.0, -1.0):
                rows[:, r, :3] = sign * coef
                rows[:, r, 3] = np.where(along, np.inf, budget)
                rows[:, r, 4:] = value
                r += 1
    lo = np.maximum(lo, lo_axes)
    # only inner coefficients shape a cell of their own
    for first_k, last_k in spline.ranges:
        rows[first_k, :, 3] = np.inf
        rows[last_k, :, 3] = np.inf
        lo[[first_k, last_k]] = -np.inf
        lo_axes[[first_k, last_k]] = -np.inf
        hi[[first_k, last_k]] = np.inf
    return (lo, np.maximum(hi, lo), lo_axes, kappa2, scale3, np.ascontiguousarray(rows))


def _node_slopes(s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """d values / ds (N,) at the points s (N,) by differences, 0 where two points coincide."""
    if s.size < 2:
        return np.zeros(s.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.gradient(values, s) if np.all(np.diff(s) > 0.0) else np.full(s.size, np.nan)
    if not np.all(np.isfinite(out)):
        step = np.diff(s)
        slope = np.divide(np.diff(values), step, out=np.zeros(step.size), where=step > 0.0)
        out = np.concatenate([slope[:1], 0.5 * (slope[:-1] + slope[1:]), slope[-1:]])
    return out


def _profile(curve: NurbsCurve, grid: Grid, lim: Limits, nodes: _Nodes,
             feed_at_u: Callable[[np.ndarray], np.ndarray], scale: np.ndarray,
             start: np.ndarray | None, growth_rounds: tuple[float, ...] = GROWTH
             ) -> tuple[np.ndarray, np.ndarray]:
    """The greatest spline the passes find on these nodes, as b and b' (M,) at the nodes; the
    limits scaled per node by scale (M,) (FIX_ROUNDS lower it where the law exceeded a limit):
    a speed by scale, an acceleration by scale^2, a jerk by scale^3.

    The rounds grow b from a profile that keeps the static limits (a = j = 0: kappa^2 v^3 <=
    J_t ...), by at most GROWTH a round: the terms frozen at the last round's profile stay
    near the new one, so the passes never act on a b far above the profile they shape (a
    curvature bound frozen at the caps asks b'' > 0 over whole stretches and drives b to 0).
    start: b (M,) at the nodes to grow from instead (a profile planned before, on other
    nodes or limits), growth_rounds the factors of the rounds (GROWTH)."""
    from nurbsfeed.planning.planner import arc_parameters

    spline = _Spline(nodes)
    s = nodes.s_mm
    m = s.size
    geo = _geometry(curve, nodes.u)
    # a cell's end read from inside it: at a knot kappa' (through C''') jumps, and the span
    # before the knot is the cell's
    before = np.maximum(np.nextafter(nodes.u, -np.inf), np.concatenate([[nodes.u[0]],
                                                                        nodes.u[:-1]]))
    geo_end = _geometry(curve, before)
    mid_u = arc_parameters(curve, grid, 0.5 * (s[:-1] + s[1:]))
    geo_mid = _geometry(curve, mid_u)
    mid_scale = np.minimum(scale[:-1], scale[1:])
    node_cap = (_caps(curve, lim, nodes.u, feed_at_u(nodes.u)) * scale) ** 2
    mid_cap = (_caps(curve, lim, mid_u, feed_at_u(mid_u)) * mid_scale) ** 2
    rest_cap = _rest_caps(lim, nodes, geo, scale)
    cap = _coefficient_caps(spline, node_cap, mid_cap, rest_cap)
    jump = np.abs(_jumps(curve, nodes.u))
    knot_geo = np.ascontiguousarray(geo[spline.knot])
    knot_scale = np.ascontiguousarray(scale[spline.knot])
    axis_acc = np.array(lim.axis_acc_mm_s2, dtype=float)
    n = spline.xi.size
    rows = np.empty((n, ROWS, 4))
    phi = np.empty(n)
    hull = np.empty(n, dtype=np.int64)
    if start is None:
        static = _coefficient_caps(
            spline, np.minimum(node_cap, (static_limit(frames(curve, nodes.u), lim) * scale)
                               ** 2),
            np.minimum(mid_cap, (static_limit(frames(curve, mid_u), lim) * mid_scale) ** 2),
            rest_cap)
        ceiling = static
    else:
        ceiling = np.minimum(cap, np.interp(spline.xi, s, start))
    c = ceiling.copy()
    frozen_b = np.minimum(spline.at_nodes(c)[0], node_cap)
    if start is None:
        # the static ceiling's slopes are no motion's (it jumps where the caps do), and it
        # keeps every limit at b' = b'' = 0
        frozen_d, frozen_dd = np.zeros(m), np.zeros(m - 1)
    else:
        frozen_d = _node_slopes(s, frozen_b)
        step = np.diff(s)
        frozen_dd = np.divide(np.diff(frozen_d), step, out=np.zeros(m - 1), where=step > 0.0)
    for index, growth in enumerate(growth_rounds):
        last_round = index == len(growth_rounds) - 1
        # sqrt(b) where it divides a limit, and the terms in b that tighten a bound, at the
        # ceiling: b only falls below it, so those rows are conservative; the rest at the last
        # round's profile
        ceiling_b = np.minimum(spline.at_nodes(c)[0], node_cap)
        _slope_rows(knot_geo, knot_scale, lim.acc_mm_s2, lim.normal_jerk_mm_s3, axis_acc, rows)
        lo, hi, lo_axes, kappa2, scale3, rows3 = _cell_rows(
            spline, s, geo, geo_end, geo_mid, scale, mid_scale, jump, ceiling_b, frozen_b,
            frozen_d, lim)
        # b'' >= lo > 0 (b above the static limit, by the frozen terms) by local steps: the
        # hull would ask it of the whole stretch and drive b to 0
        lo_hull = np.minimum(lo, 0.0)
        # an axis's bound lo > 0 rests on b' frozen at the last profile: lifting to it cut
        # notches the next profile did not need (the verification holds what is left)
        no_axes = np.full(n, -np.inf)
        del lo_axes
        for _ in range(INNER_ROUNDS if last_round else EARLY_ROUNDS):
            change = 0.0
            for (first, last), ratio in zip(spline.ranges, spline.ratio):
                change = max(change, _slope_passes(spline.xi, c, spline.w, rows, first,
                                                   last))
                change = max(change, _convex_pass(spline.xi, c, spline.width, lo_hull, first,
                                                  last, phi, hull))
                change = max(change, _lift_pass(spline.xi, c, spline.width, no_axes, kappa2,
                                                lim.jerk_mm_s3 * scale3, first, last))
                change = max(change, _row_pass(c, rows3, first, last))
                change = max(change, _round_pass(spline.xi, c, spline.width, hi, first, last))
                change = max(change, _rest_pass(c, ratio, first, last))
            if change <= CONVERGED_REL:
                break
        frozen_b, frozen_d, frozen_dd = spline.at_nodes(c)
        c = np.minimum(cap, growth * c)
    return frozen_b, frozen_d


def envelope_schedule(curve: NurbsCurve, grid: Grid, lim: Limits, rest_nodes: np.ndarray,
                      v_start: np.ndarray, feed_at_u: Callable[[np.ndarray], np.ndarray],
                      worst_s: float = math.inf, slowdown: float = 1.0) -> Schedule | None:
    """The schedule of `curve` under `lim` (path model) resting at grid nodes rest_nodes: the
    ends, corners and cusps. v_start (M,): a speed at the grid's nodes that keeps the limits
    (the S-curve plan's), which sets where cells are cut finer. feed_at_u: parameters (N,) ->
    programmed feed (N,). None where it cannot plan (a profile of b = 0 inside a stretch: a
    motion that never arrives), where its schedule would last longer than worst_s (the plan
    it would replace) or MAX_LAW_PERIODS, or on a grid of more than MAX_NODES nodes (each
    takes about 2.5 kB of rows: a two-hour curve's 200,000 took 750 MB). slowdown: a uniform
    slowdown on top of the one the law needs."""
    if grid.length_mm <= 0.0 or grid.u.size > MAX_NODES:
        return None
    made = schedule_nodes(curve, grid, lim, rest_nodes)
    if made is None:
        return None
    rest_nodes, nodes = made
    # cells cut where the S-curve plan spends more than a few periods in one: the schedule is
    # faster, so they last no longer under it (one profile, not one a refinement)
    b_start = np.interp(nodes.s_mm, grid.s_mm, v_start) ** 2
    for _ in range(REFINE_ROUNDS):
        refined = _refined(curve, grid, nodes, b_start, lim.period_s,
                           _node_slopes(nodes.s_mm, b_start))
        if refined is None:
            break
        nodes, b_start = refined
    scale = np.ones(nodes.s_mm.size)
    b, d = _profile(curve, grid, lim, nodes, feed_at_u, scale, None)
    if not cycle_s(nodes, b, d) < min(worst_s, MAX_LAW_PERIODS * lim.period_s):
        return None
    law = sampled_law(nodes, b, d, lim.period_s)
    excess, per_cell = _cell_ratios(curve, grid, nodes, law, lim)
    best = (law.duration_s * excess, b, d, excess)
    rounds = 0
    for rounds in range(1, FIX_ROUNDS + 1):
        if excess <= 1.0 + FIX_REL:
            rounds -= 1
            break
        near = np.ones(nodes.s_mm.size)
        near[:-1] = np.maximum(near[:-1], per_cell)
        near[1:] = np.maximum(near[1:], per_cell)
        scale = scale / near
        # the last profile, lowered where the law broke a limit: one round, no growth
        b, d = _profile(curve, grid, lim, nodes, feed_at_u, scale, b, (1.0,))
        if not cycle_s(nodes, b, d) < min(worst_s, FIX_WORST * best[0]):
            break  # (a round that lowered the limits this far cannot win)
        law = sampled_law(nodes, b, d, lim.period_s)
        excess, per_cell = _cell_ratios(curve, grid, nodes, law, lim)
        if law.duration_s * excess < best[0]:
            best = (law.duration_s * excess, b, d, excess)
    _, b, d, excess = best
    excess *= slowdown
    law = sampled_law(nodes, b, d, lim.period_s, excess)
    if not np.all(np.isfinite(law.jerk_mm_s3)) or not math.isfinite(law.duration_s):
        return None
    return Schedule(law, excess, rounds, rest_nodes)


def _b_at(nodes: _Nodes, b: np.ndarray, d: np.ndarray, s_mm: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """b and b' (N,) at arc lengths s_mm (N,) of the schedule: the cubic Hermite cell through
    the nodes' b and d, b_far y^(4/3) in a cell beside a rest."""
    h, rest = nodes.h_mm, nodes.rest
    cell = np.clip(np.searchsorted(nodes.s_mm, s_mm, side="right") - 1, 0, h.size - 1)
    hc = h[cell]
    x = np.clip((s_mm - nodes.s_mm[cell]) / hc, 0.0, 1.0)
    h00, h10, h01, h11 = _hermite_basis(x)
    value = h00 * b[cell] + h10 * hc * d[cell] + h01 * b[cell + 1] + h11 * hc * d[cell + 1]
    slope = ((6 * x**2 - 6 * x) * b[cell] / hc + (3 * x**2 - 4 * x + 1) * d[cell]
             + (-6 * x**2 + 6 * x) * b[cell + 1] / hc + (3 * x**2 - 2 * x) * d[cell + 1])
    from_rest, to_rest = rest[cell], rest[cell + 1]
    y = np.where(from_rest, x, 1.0 - x)
    far = np.where(from_rest, b[np.minimum(cell + 1, b.size - 1)], b[cell])
    value = np.where(from_rest | to_rest, far * y ** (4.0 / 3.0), value)
    slope = np.where(from_rest, 4.0 / 3.0 * far * np.cbrt(y) / hc,
                     np.where(to_rest, -4.0 / 3.0 * far * np.cbrt(y) / hc, slope))
    return np.maximum(value, 0.0), slope


def sampled_law(nodes: _Nodes, b: np.ndarray, d: np.ndarray, period_s: float,
                slowdown: float = 1.0) -> TimeLaw:
    """The time law of the schedule b, d (M,) at the nodes, each stretch between rests slowed
    by `slowdown` and stretched to whole periods: the schedule's own s, v and a at
    SAMPLES_PER_PERIOD instants a period, joined by constant-jerk pieces through s and v at
    both ends of each (a cubic Hermite in time). The positions at the periods are the
    schedule's exactly; a spline through them instead rang where b'' changes from cell to cell
    (its jerk 2x the schedule's beside such a cell)."""
    cell_t = _cell_times(nodes, b, d)
    t_node = np.concatenate([[0.0], np.cumsum(cell_t)])
    rests = np.flatnonzero(nodes.rest)
    pieces: list[list[np.ndarray]] = [[] for _ in range(5)]
    key_t = [0.0]
    step = period_s / SAMPLES_PER_PERIOD
    for first, last in zip(rests[:-1], rests[1:]):
        duration = t_node[last] - t_node[first]
        periods = max(2, math.ceil(duration * slowdown / period_s * (1.0 - 1e-12)))
        t = np.arange(periods * SAMPLES_PER_PERIOD + 1) * step
        stretch = duration / t[-1]  # schedule time per law time (<= 1)
        # in chunks: _arc_at holds a few dozen numbers a sample (a 140 s stretch took 233 MB
        # at once)
        s = np.concatenate([_arc_at(nodes, b, d, t_node, cell_t,
                                    t_node[first] + t[k:k + LAW_CHUNK] * stretch)
                            for k in range(0, t.size, LAW_CHUNK)])
        s[0], s[-1] = nodes.s_mm[first], nodes.s_mm[last]
        s = np.maximum.accumulate(s)
        value, slope = _b_at(nodes, b, d, s)
        v = np.sqrt(value) * stretch
        v[0] = v[-1] = 0.0
        gain = np.diff(s)
        c2 = (3.0 * gain - step * (2.0 * v[:-1] + v[1:])) / step**2
        c3 = (-2.0 * gain + step * (v[:-1] + v[1:])) / step**3
        start = key_t[-1]
        for out, value_ in zip(pieces, (start + t[:-1], s[:-1], v[:-1], 2.0 * c2, 6.0 * c3)):
            out.append(value_)
        key_t.append(start + t[-1])
    times = np.array(key_t)
    t0, s0, v0, a0, jk = (np.concatenate(p) for p in pieces)
    return TimeLaw.from_pieces(t0, s0, v0, a0, jk, times, float(times[-1]))
