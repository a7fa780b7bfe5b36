"""The path model's pointwise limit at the grid's nodes and its check of a time law (design
§2b): `path_limit` (the static terms and the jumps of kappa N at knots), `least_cycle_s` (a
lower bound on any plan's cycle, to refuse a curve planned for hours before planning it), and
`law_ratios` / `path_excess`, which sample a law twice a period, each sample's parameter from
its arc length (`arc_parameters`), and measure every path-model quantity against its limit.
Their work per node or sample is compiled (the grid's C and C' at its nodes read, not evaluated
again); numpy keeps the cube roots and the sums, whose rounding the kernels would not share."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry.arclength import gauss_lengths
from nurbsfeed.geometry.kernel import find_span, point_d3
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.geometry.peaks import first_above
from nurbsfeed.jit import jit
from nurbsfeed.planning.grid import ZERO_SPEED_REL, Grid
from nurbsfeed.planning.limits import (
    L_AXIS_VEL,
    L_FEED,
    Limits,
    least,
    limit_values,
    most,
)
from nurbsfeed.planning.path_model import (
    frame,
    frames,
    jump_speed,
    kappa_n_jump,
    kernel_array,
    motion_ratio,
    static_terms,
    with_roots,
)
from nurbsfeed.planning.timelaw import TimeLaw

# the path model's own minima of the limit that become key points (`path_limit`)
MINIMUM_WINDOW = 3  # nodes on each side
MINIMUM_RISE = 2.0  # the rise of the limit within them, on both sides (or to a neighbour)


def least_cycle_s(curve: NurbsCurve, grid: Grid, lim: Limits, fcap: np.ndarray) -> float:
    """A lower bound on the cycle of any motion along the curve that keeps the feed and every
    axis's velocity limit: each grid interval lasts at least its arc over the larger feed cap
    at its ends, and each axis's travel across it over that axis's limit.

    The path model checks it against max_curve_time_s before its fix rounds, which sample the
    law twice a period: a quarter circle under max_vel_x_mm_s 0.001 (10 mm of X travel, at
    least 10,000 s) took 53 s of CPU to be refused at 3,600 s."""
    least_s = np.empty(grid.u.size - 1)
    _least_interval_s(grid.points_mm, grid.s_mm, kernel_array(fcap),
                      limit_values(lim), least_s)
    return float(np.sum(least_s))


@jit
def _least_interval_s(points, s_mm, fcap, lims, out):
    """`least_cycle_s`'s bound per grid interval into out (M - 1,)."""
    for i in range(out.size):
        axis_s = -math.inf
        for x in range(3):
            axis_s = most(axis_s, abs(points[i + 1, x] - points[i, x]) / lims[L_AXIS_VEL + x])
        cap = least(most(fcap[i], fcap[i + 1]), lims[L_FEED])
        out[i] = most((s_mm[i + 1] - s_mm[i]) / cap, axis_s)


def axis_capped(curve: NurbsCurve, grid: Grid, lim: Limits, cap: np.ndarray) -> np.ndarray:
    """The speed caps cap (M,) at the grid's nodes lowered by each axis's velocity limit."""
    out = np.empty(grid.u.size)
    _axis_capped(grid.d1_mm, kernel_array(cap), limit_values(lim), out)
    return out


@jit
def _axis_capped(d1, cap, lims, out):
    """`axis_capped` node by node: the unit tangent from C' as `path_model.frame` takes it."""
    for i in range(out.size):
        speed = math.sqrt(d1[i, 0] * d1[i, 0] + d1[i, 1] * d1[i, 1] + d1[i, 2] * d1[i, 2])
        v = least(cap[i], lims[L_FEED])
        if speed > 0.0:
            for x in range(3):
                along = abs(d1[i, x] / speed)
                v = least(v, lims[L_AXIS_VEL + x] / along if along > 0.0 else math.inf)
        out[i] = v


def path_limit(curve: NurbsCurve, grid: Grid, lim: Limits, raw_limit: np.ndarray,
                caps: np.ndarray | None = None):
    """The path model's pointwise limit at the nodes (the static terms, `path_model.
    static_limit`, the speed at knots where kappa N jumps, and caps (M,) from `path_excess`),
    and the nodes that become key points (the law passes them at zero acceleration, at a speed
    no higher than their limit): the knots where that jump sets the limit, and the limit's own
    minima. The paper's limit is lowest at curvature peaks, which are key points; the path
    model's has lows of its own (kappa' and the per-axis terms), and one between two key points
    left the fix rounds to cap the whole segment at it, or to slow the whole curve: a curve
    reached a step from 24.7 to 0.55 mm/s at 3.4 mm/s (kappa' jumps at a cubic's knots with its
    third derivative) and was slowed 6.3 times (13 s for the paper model's 1.6 s). Shallower
    lows are left to the fix rounds and the shoulders: a key point holds the acceleration at
    zero, and one at every 2 % low made the dense test curves up to 20 % slower.

    Where C' = 0 (a removable zero the grid passes at speed) the frame is rounding noise
    (kappa 2e30 at a knot of |C'| 5e-14 once planned a curve at 3e20 s): a node there takes the
    lower of its neighbours' static limits, as the grid takes kappa there from inside."""
    knots, coef, degree = curve.knots, curve.span_polynomials, curve.degree
    lims = limit_values(lim)
    low = np.empty(grid.u.size)
    roots = np.empty((5, grid.u.size))
    _node_static_terms(knots, coef, degree, grid.u, lims, low, roots)
    static = with_roots(low, roots)
    speed = grid.speed_mm
    if caps is not None:
        static = np.minimum(static, caps)
    limit = np.empty(grid.u.size)
    keys = _limit_and_keys(knots, coef, degree, curve.span_breaks, grid.u, static,
                           kernel_array(raw_limit), speed,
                           ZERO_SPEED_REL * float(speed.mean()), lims, limit)
    return limit, keys


@jit
def _node_static_terms(knots, coef, degree, u, lims, low, roots):
    """`path_model.static_terms` at every node into low (M,) and roots (5, M)."""
    span = degree
    for i in range(u.size):
        span = find_span(knots, degree, coef.shape[0], u[i], span)
        c = point_d3(knots, coef, degree, span, u[i])
        f = frame(c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10], c[11])
        low[i] = static_terms(lims, f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9],
                              f[10], f[11], roots, i)


@jit
def _limit_and_keys(knots, coef, degree, breaks, u, static, raw_limit, speed, zero_speed, lims,
                    limit):
    """`path_limit` from the static limit (M,) at the nodes u (M,): the limit into limit (M,),
    and the key nodes (K,), ascending."""
    size = u.size
    zero = np.empty(size, dtype=np.bool_)
    n_zero = 0
    for i in range(size):
        zero[i] = speed[i] <= zero_speed
        n_zero += zero[i]
    for i in range(size):
        limit[i] = least(raw_limit[i], static[i])
    if 0 < n_zero < size:
        moving = -1  # the last node with a frame so far
        before = np.empty(size, dtype=np.int64)
        for i in range(size):
            if not zero[i]:
                moving = i
            before[i] = moving
        moving = size  # the next node with a frame, from the end
        for i in range(size - 1, -1, -1):
            if not zero[i]:
                moving = i
            else:
                side = static[before[i]] if before[i] >= 0 else math.inf
                other = static[moving] if moving < size else math.inf
                limit[i] = least(raw_limit[i], least(side, other))
    key = np.empty(size, dtype=np.bool_)
    for i in range(size):
        key[i] = False
    q = 0
    for b in range(1, breaks.size - 1):  # the knots on nodes (both ascending)
        while q < size and u[q] < breaks[b]:
            q += 1
        if q < size and u[q] == breaks[b]:
            jx, jy, jz = kappa_n_jump(knots, coef, degree, breaks[b], zero_speed)
            at_jump = jump_speed(jx, jy, jz, lims)
            if at_jump < limit[q]:
                limit[q] = at_jump
                key[q] = True
    # the path model's own lows (`path_limit`): a node where its terms set the limit (below the
    # paper's raw limit), the lowest of MINIMUM_WINDOW nodes on each side (stops, limit 0,
    # aside) with the limit rising to MINIMUM_RISE times it on both sides within them, or the
    # low side of a step (a neighbour MINIMUM_RISE times it); never an end
    w = MINIMUM_WINDOW
    last = size - 1
    for i in range(1, last):
        here = limit[i]
        if not (here < raw_limit[i] and here > 0.0 and math.isfinite(here)):
            continue
        rise = MINIMUM_RISE * here
        if limit[i - 1] >= rise or limit[i + 1] >= rise:
            key[i] = True
            continue
        # the windows beside the node, their ends held at the curve's ends
        left_min = right_min = math.inf  # of the limit, where above 0
        left_max = limit[max(i - w, 0)]
        right_max = limit[min(i + 1, last)]
        for j in range(1, w + 1):
            before = limit[max(i - j, 0)]
            after = limit[min(i + j, last)]
            left_min = least(left_min, before if before > 0.0 else math.inf)
            right_min = least(right_min, after if after > 0.0 else math.inf)
            left_max = most(left_max, before)
            right_max = most(right_max, after)
        if left_min > here and right_min >= here and left_max >= rise and right_max >= rise:
            key[i] = True
    n_keys = 0
    for i in range(size):
        n_keys += key[i]
    keys = np.empty(n_keys, dtype=np.int64)
    n_keys = 0
    for i in range(size):
        if key[i]:
            keys[n_keys] = i
            n_keys += 1
    return keys


PATH_SAMPLES_PER_PERIOD = 2  # the path model's final check samples the law this densely
PATH_CHUNK = 1 << 16  # samples per chunk of that check: memory stays bounded on long curves
ARC_GAUSS_POINTS = 8  # of the arc length inside one grid interval
UNEVEN_SPEED = 1.5  # |C'| changing by more than this across a grid interval: u(s) is not linear
ARC_BISECTIONS = 60


def arc_parameters(curve: NurbsCurve, grid: Grid, s_mm: np.ndarray) -> np.ndarray:
    """u at arc lengths s_mm (N,) on the grid: linear between nodes where |C'| is even across
    the interval; elsewhere (beside a zero of C', a stop or an end, where s grows like a power of
    u - u0 and a linear guess lands orders of magnitude closer to the zero, where kappa is
    rounding noise) by bisection on the arc length, integrated from the interval's first node."""
    s_at = kernel_array(np.ravel(s_mm))
    u = np.empty(s_at.size)
    interval = np.empty(s_at.size, dtype=np.int64)
    is_uneven = np.empty(s_at.size, dtype=np.bool_)
    if not _linear_parameters(grid.s_mm, grid.u, grid.speed_mm, s_at, u, interval, is_uneven):
        return u
    uneven = np.flatnonzero(is_uneven)
    first = interval[uneven]
    lo, hi = grid.u[first].copy(), grid.u[first + 1].copy()
    target = s_at[uneven] - grid.s_mm[first]
    start = grid.u[first]
    for _ in range(ARC_BISECTIONS):
        mid = 0.5 * (lo + hi)
        arc = gauss_lengths(curve.speed, start, mid, ARC_GAUSS_POINTS)
        below = arc < target
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    u[uneven] = 0.5 * (lo + hi)
    return u


@jit
def _linear_parameters(s_nodes, u_nodes, speed, s_mm, u, interval, uneven):
    """`arc_parameters`' linear part: u at s_mm (N,) by np.interp's arithmetic on the nodes
    (s_nodes, u_nodes (M,)), each one's interval (its first node, within 0 .. M - 2) and whether
    |C'| (speed (M,) at the nodes) changes across it by more than UNEVEN_SPEED; into u,
    interval, uneven (N,). Returns whether any is uneven."""
    size = s_nodes.size
    j = 0  # the last node at or below the last s: the next one's search starts there
    any_uneven = False
    for i in range(s_mm.size):
        x = s_mm[i]
        if x != x:
            j = size - 1  # NaN sorts last
        elif not (0 <= j < size and s_nodes[j] <= x and (j == size - 1 or x < s_nodes[j + 1])):
            j = first_above(s_nodes, x) - 1
        if x != x:
            u[i] = x
        elif j < 0:
            u[i] = u_nodes[0]
        elif j == size - 1 or s_nodes[j] == x:
            u[i] = u_nodes[j]
        else:
            slope = (u_nodes[j + 1] - u_nodes[j]) / (s_nodes[j + 1] - s_nodes[j])
            u[i] = slope * (x - s_nodes[j]) + u_nodes[j]
            if u[i] != u[i]:  # as np.interp: the other end, then a flat piece's value
                u[i] = slope * (x - s_nodes[j + 1]) + u_nodes[j + 1]
                if u[i] != u[i] and u_nodes[j] == u_nodes[j + 1]:
                    u[i] = u_nodes[j]
        q = min(max(j, 0), size - 2)
        interval[i] = q
        uneven[i] = (most(speed[q], speed[q + 1])
                     > UNEVEN_SPEED * least(speed[q], speed[q + 1]))
        any_uneven = any_uneven or uneven[i]
    return any_uneven


def law_ratios(curve: NurbsCurve, grid: Grid, law: TimeLaw, lim: Limits):
    """The law sampled PATH_SAMPLES_PER_PERIOD times a period, PATH_CHUNK samples at a time:
    per chunk, each sample's arc length, `path_model.motion_ratio` and v, three (N,) arrays.
    Each sample's parameter comes from its arc length on the grid (`arc_parameters`); at a
    zero of C' (a rest, or a removable zero) the frame is rounding noise and the ratio 0."""
    if law.duration_s <= 0.0:
        return
    n = max(2, int(math.ceil(law.duration_s / lim.period_s * PATH_SAMPLES_PER_PERIOD)) + 1)
    zero_speed = ZERO_SPEED_REL * float(curve.speed(grid.u).mean())
    for start in range(0, n, PATH_CHUNK):
        t = np.arange(start, min(n, start + PATH_CHUNK)) * (law.duration_s / (n - 1))
        piece, local, v, a, j = law.sample(t)
        s_mm = law.s0_mm[piece] + local
        u = arc_parameters(curve, grid, s_mm)
        ratio = motion_ratio(frames(curve, u), v, a, j, lim)
        ratio[curve.speed(u) <= zero_speed] = 0.0
        yield s_mm, ratio, v


def path_excess(curve: NurbsCurve, grid: Grid, law: TimeLaw,
                lim: Limits) -> tuple[float, np.ndarray]:
    """Where the law breaks a path-model limit: the uniform slowdown (>= 1) that would keep
    them all, and per node (M,) the speed that would keep them where the law passes next to it
    (inf elsewhere), from `law_ratios`: a sample too fast by lambda asks v / lambda of both
    nodes around it. The key points and the fix rounds keep the static terms; this covers what
    the S-curve's own acceleration and jerk add (3 kappa v a across the path, -kappa^2 v^3 + j
    along it, a T_x per axis)."""
    worst = 1.0
    caps = np.full(grid.u.size, np.inf)
    for s_mm, ratio, v in law_ratios(curve, grid, law, lim):
        worst = max(worst, float(np.max(ratio)))
        bad = np.flatnonzero(ratio > 1.0)
        if bad.size:
            node = np.clip(np.searchsorted(grid.s_mm, s_mm[bad], side="right") - 1, 0,
                           grid.u.size - 2)
            ask = v[bad] / ratio[bad]
            np.minimum.at(caps, node, ask)
            np.minimum.at(caps, node + 1, ask)
    return worst, caps
