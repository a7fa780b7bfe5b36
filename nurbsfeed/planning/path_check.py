"""The path model's pointwise limit at the grid's nodes and its check of a time law (design
§2b): `path_limit` (the static terms and the jumps of kappa N at knots), `least_cycle_s` (a
lower bound on any plan's cycle, to refuse a curve planned for hours before planning it), and
`law_ratios` / `path_excess`, which sample a law twice a period, each sample's parameter from
its arc length (`arc_parameters`), and measure every path-model quantity against its limit."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry.arclength import gauss_lengths
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.grid import ZERO_SPEED_REL, Grid
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.path_model import frames, jump_limits, motion_ratio, static_limit
from nurbsfeed.planning.timelaw import TimeLaw

# the path model's own minima of the limit that become key points (`_binding_minima`)
MINIMUM_WINDOW = 3  # nodes on each side
MINIMUM_RISE = 2.0  # the rise of the limit within them, on both sides (or to a neighbour)


def least_cycle_s(curve: NurbsCurve, grid: Grid, lim: Limits, fcap: np.ndarray) -> float:
    """A lower bound on the cycle of any motion along the curve that keeps the feed and every
    axis's velocity limit: each grid interval lasts at least its arc over the larger feed cap
    at its ends, and each axis's travel across it over that axis's limit.

    The path model checks it against max_curve_time_s before its fix rounds, which sample the
    law twice a period: a quarter circle under max_vel_x_mm_s 0.001 (10 mm of X travel, at
    least 10,000 s) took 53 s of CPU to be refused at 3,600 s."""
    travel = np.abs(np.diff(curve.point(grid.u), axis=0))
    axis_s = np.max(travel / np.asarray(lim.axis_vel_mm_s), axis=1)
    cap = np.minimum(np.maximum(fcap[:-1], fcap[1:]), lim.feed_mm_s)
    return float(np.sum(np.maximum(np.diff(grid.s_mm) / cap, axis_s)))


def axis_capped(curve: NurbsCurve, grid: Grid, lim: Limits, cap: np.ndarray) -> np.ndarray:
    """The speed caps cap (M,) at the grid's nodes lowered by each axis's velocity limit."""
    tangent = frames(curve, grid.u).tangent
    out = np.minimum(np.asarray(cap, dtype=float), lim.feed_mm_s)
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(tangent[:, x])
            out = np.minimum(out, np.where(tx > 0.0, lim.axis_vel_mm_s[x]
                                           / np.where(tx > 0.0, tx, 1.0), np.inf))
    return out


def _binding_minima(limit: np.ndarray, raw_limit: np.ndarray) -> np.ndarray:
    """Nodes where the path model's own terms set the limit (below the paper's raw limit) and
    it is low: the lowest of MINIMUM_WINDOW nodes on each side (stops, limit 0, aside), with
    the limit rising to MINIMUM_RISE times it on both sides within them (a minimum), or the low
    side of a step (a neighbour's limit MINIMUM_RISE times it: kappa' jumps at a cubic's knots
    with its third derivative). The paper's limit is lowest at curvature peaks, which are key
    points; the path model's has lows of its own (kappa' and the per-axis terms), and one
    between two key points left the fix rounds to cap the whole segment at it, or to slow the
    whole curve: a curve reached a step from 24.7 to 0.55 mm/s at 3.4 mm/s and was slowed 6.3
    times (13 s for the paper model's 1.6 s). Shallower lows are left to the fix rounds and the
    shoulders: a key point holds the acceleration at zero, and one at every 2 % low made the
    dense test curves up to 20 % slower."""
    w = MINIMUM_WINDOW
    floor = np.where(limit > 0.0, limit, np.inf)
    padded_min = np.pad(floor, w, mode="edge")
    padded_max = np.pad(limit, w, mode="edge")
    windows_min = np.lib.stride_tricks.sliding_window_view(padded_min, 2 * w + 1)
    windows_max = np.lib.stride_tricks.sliding_window_view(padded_max, 2 * w + 1)
    left_min = windows_min[:, :w].min(axis=1)
    right_min = windows_min[:, w + 1:].min(axis=1)
    rise = MINIMUM_RISE * limit
    binding = (limit < raw_limit) & (limit > 0.0) & np.isfinite(limit)
    minimum = ((left_min > limit) & (right_min >= limit)
               & (windows_max[:, :w].max(axis=1) >= rise)
               & (windows_max[:, w + 1:].max(axis=1) >= rise))
    step = (windows_max[:, w - 1] >= rise) | (windows_max[:, w + 1] >= rise)
    keys = binding & (minimum | step)
    keys[[0, -1]] = False
    return np.flatnonzero(keys)


def path_limit(curve: NurbsCurve, grid: Grid, lim: Limits, raw_limit: np.ndarray,
                caps: np.ndarray | None = None):
    """The path model's pointwise limit at the nodes (the static terms, `path_model.
    static_limit`, the speed at knots where kappa N jumps, and caps (M,) from `path_excess`),
    and the nodes that become key points (the law passes them at zero acceleration, at a speed
    no higher than their limit): the knots where that jump sets the limit, and the limit's own
    minima (`_binding_minima`)."""
    static = static_limit(frames(curve, grid.u), lim)
    if caps is not None:
        static = np.minimum(static, caps)
    # where C' = 0 (a removable zero the grid passes at speed) the frame is rounding noise
    # (kappa 2e30 at a knot of |C'| 5e-14 once planned a curve at 3e20 s): the lower of the
    # neighbours' limits, as the grid takes kappa there from inside
    speed = curve.speed(grid.u)
    zero = speed <= ZERO_SPEED_REL * speed.mean()
    if zero.any() and not zero.all():
        index = np.arange(static.size)
        before = np.maximum.accumulate(np.where(zero, -1, index))  # last node with a frame
        after = np.minimum.accumulate(np.where(zero, static.size, index)[::-1])[::-1]
        padded = np.concatenate([static, [np.inf, np.inf]])  # indices -1 and M read inf
        static = np.where(zero, np.minimum(padded[before], padded[after]), static)
    limit = np.minimum(raw_limit, static)
    breaks = curve.span_breaks[1:-1]
    nodes = np.searchsorted(grid.u, breaks)
    inside = nodes < grid.u.size
    nodes, breaks = nodes[inside], breaks[inside]
    on_node = grid.u[nodes] == breaks
    nodes, breaks = nodes[on_node], breaks[on_node]
    at_jump = jump_limits(curve, breaks, lim, ZERO_SPEED_REL * float(speed.mean()))
    lower = at_jump < limit[nodes]
    limit[nodes[lower]] = at_jump[lower]
    keys = np.union1d(nodes[lower], _binding_minima(limit, raw_limit))
    return limit, keys.astype(np.int64)


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
    u = np.interp(s_mm, grid.s_mm, grid.u)
    speed = curve.speed(grid.u)
    interval = np.clip(np.searchsorted(grid.s_mm, s_mm, side="right") - 1, 0, grid.u.size - 2)
    low_speed = np.minimum(speed[interval], speed[interval + 1])
    high_speed = np.maximum(speed[interval], speed[interval + 1])
    uneven = np.flatnonzero(high_speed > UNEVEN_SPEED * low_speed)
    if uneven.size == 0:
        return u
    first = interval[uneven]
    lo, hi = grid.u[first].copy(), grid.u[first + 1].copy()
    target = s_mm[uneven] - grid.s_mm[first]
    start = grid.u[first]
    for _ in range(ARC_BISECTIONS):
        mid = 0.5 * (lo + hi)
        arc = gauss_lengths(curve.speed, start, mid, ARC_GAUSS_POINTS)
        below = arc < target
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    u[uneven] = 0.5 * (lo + hi)
    return u


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
