"""The schedule's cells (design §2e): where b = v^2 is planned along one curve, and what the
limits read there.

A *stretch* runs from one rest to the next (the curve's ends, its corners, cusps and
reversals). On it, b is a quadratic spline in arc length whose knots are the stretch's nodes
but the two beside the rests, C1 everywhere; each cell beside a rest is b = b_far y^(4/3), y
the distance to the rest over the cell's length: constant jerk from rest, the shape of the
time-optimal start (a quadratic would never leave b = 0).

The spline is kept as its control polygon (`Layout`): coefficient k sits at the Greville
abscissa xi_k (the first knot, each inner cell's middle, the last knot), so that with
g_k = xi_k+1 - xi_k

    b'(knot k)      = (c_k+1 - c_k) / g_k               (the polygon's slope)
    b(knot k)       = w_k c_k + (1 - w_k) c_k+1
    b'' (inner cell between knots k-1 and k, the coefficient k's) = (slope_k - slope_k-1) / h

so b, b' and b'' anywhere on a cell are linear in its three coefficients (`point_weights`),
and the limits become rows over three consecutive variables (planning.rows). A rest cell's
b = c y^(4/3) has every quantity proportional to a power of its far coefficient c, so its
limits are a cap on c (`rest_caps`), and its C1 join with the spline fixes the coefficient
after c: c_1 = c_0 (1 + 2/3 h_1 / h_rest).

Nodes: the planning grid's (samples at most two full-speed steps apart, curvature peaks,
knots where kappa jumps, stops), then beside each rest at h, 2h, 4h ... (h from how fast
constant jerk leaves a rest), then every cell in which the pointwise speed limit would spend
more than CELL_PERIODS periods cut into pieces that do not: no motion is faster than that
limit, so no cell lasts longer.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.jit import jit
from nurbsfeed.planning.basis import BETWEEN, G_CAP, G_D, G_K, G_KAPPA, G_KS, G_SIZE, G_T
from nurbsfeed.planning.grid import Grid
from nurbsfeed.planning.limits import Limits, speed_limit
from nurbsfeed.planning.path_check import arc_parameters
from nurbsfeed.planning.path_model import frames, kappa_n_jumps
from nurbsfeed.planning.rows import point_ratio

CELL_PERIODS = 4.0  # a cell lasting longer at the speed estimate is cut
RECUT_SLACK = 2.0  # ... and one the schedule spends over this many times as long in, again
MAX_CUT = 64  # pieces a cell is cut into at most in one go
# a grid node closer than this many periods at the speed estimate to the last one kept goes
# (curvature maxima, knots, stops and the ends always stay): cells far shorter than a period
# are finer than anything the machine's positions show, they make rows that ask b'' to
# follow 2 kappa^2 b to a millionth (a 3 um near cusp), beyond what the programs resolve, and
# each costs the programs as much as a long one
MIN_CELL_PERIODS = 1.0
# ... unless the curvature across the merged cell changes by more than this factor (kappa
# below kappa_0, where it sets no limit, counts as kappa_0): in a valley the rows must see the
# curvature change to plan its bottom
MERGE_KAPPA_RATIO = 1.25
MIN_CELL_REL = 1e-6  # of the curve's length: nodes closer than this are one
MIN_STRETCH_CELLS = 4  # a stretch between rests has at least this many cells
REST_CELL_SHARE = 0.05  # of A^3 / (6 J^2): the first cell beside a rest at most ...
REST_CELLS_PER_STRETCH = 32  # ... and at most this share of half its stretch
REST_POINTS = (0.25, 0.5, 1.0)  # where a rest cell's limits are read, as y
REST_BISECTIONS = 60


@dataclass(frozen=True, eq=False)
class Layout:
    """The cells of one curve (module docstring). Nodes (M,): s_mm, u, rest. Coefficients (C,)
    of all stretches one after another: xi, knot_w (b at the knot after coefficient k is
    knot_w_k c_k + (1 - knot_w_k) c_k+1), width (the length of the inner cell whose b'' the
    coefficient shapes; 1 at a stretch's ends), cap (b). Stretches (S,): first and last
    coefficient, the rest cells' lengths and the C1 join ratios. Inner cells (Q,): cells (Q, 5)
    = (first coefficient i0, g0 = xi[i0+1] - xi[i0], g1 = xi[i0+2] - xi[i0+1], knot_w[i0], h),
    their first node, and geo (Q, 3, G_SIZE): at each of POINTS kappa, T, K = kappa N,
    K_s = dK/ds, the jump D of kappa N (at a knot) and the speed cap squared; between (Q, 2,
    G_SIZE) the same at BETWEEN, where the schedule is checked but not planned."""

    s_mm: np.ndarray
    u: np.ndarray
    rest: np.ndarray
    xi: np.ndarray
    knot_w: np.ndarray
    width: np.ndarray
    cap: np.ndarray
    b_estimate: np.ndarray  # (C,) b of the speed estimate (no schedule is faster): a scale
    first: np.ndarray
    last: np.ndarray
    rest_h: np.ndarray  # (S, 2)
    rest_ratio: np.ndarray  # (S, 2)
    cells: np.ndarray
    cell_node: np.ndarray
    geo: np.ndarray
    between: np.ndarray

    @property
    def n_coefficients(self) -> int:
        return self.xi.size


def speed_estimate(s_mm: np.ndarray, cap_mm_s: np.ndarray, acc_mm_s2: float,
                   rest: np.ndarray) -> np.ndarray:
    """The fastest speed (N,) at the points s_mm (N,) under the caps cap_mm_s (N,) and one
    acceleration limit, at rest where rest (N,): the forward and backward passes of
    time-optimal path parametrisation, b' <= 2 A. No motion that keeps the limits is faster
    (jerk only slows it), which sizes the cells."""
    b = np.where(rest, 0.0, np.minimum(cap_mm_s, 1e300) ** 2)
    _topp_passes(b, np.diff(s_mm), 2.0 * acc_mm_s2)
    return np.sqrt(b)


@jit
def _topp_passes(b, h, slope):
    for i in range(1, b.size):
        b[i] = min(b[i], b[i - 1] + slope * h[i - 1])
    for i in range(b.size - 2, -1, -1):
        b[i] = min(b[i], b[i + 1] + slope * h[i])


def schedule_nodes(curve: NurbsCurve, grid: Grid, lim: Limits, rest_nodes: np.ndarray,
                   cap_mm_s: np.ndarray, kappa_floor: float,
                   keep_u: np.ndarray = np.empty(0), max_nodes: int = 2**62
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The nodes (s_mm, u, rest) (M,) of the schedule from the grid's, resting at grid nodes
    rest_nodes (R,) (the ends first and last); cap_mm_s (N,): the speed caps at the grid's
    nodes; kappa_floor: the curvature below which the caps do not depend on it (kappa_0);
    keep_u: parameters whose nodes stay (where the programmed feed changes) (module docstring).
    Also the speed estimate (M,) at the nodes (`speed_estimate`). None past max_nodes nodes."""
    s_mm, u = np.asarray(grid.s_mm, dtype=float), np.asarray(grid.u, dtype=float)
    rest = np.zeros(s_mm.size, dtype=bool)
    rest[rest_nodes] = True
    v_limit = speed_estimate(s_mm, np.asarray(cap_mm_s, dtype=float),
                             _moving_limits(curve, lim)[0], rest)
    v_limit = np.maximum(v_limit, np.where(rest, 0.0, 1e-300))
    essential = rest.copy()
    essential[grid.peak_index] = True
    essential[np.isin(u, curve.span_breaks)] = True
    essential[np.isin(u, keep_u)] = True
    floor = MIN_CELL_REL * max(float(s_mm[-1]), 1e-300)
    short = np.maximum(MIN_CELL_PERIODS * lim.period_s * np.asarray(v_limit, dtype=float), floor)
    kappa = np.maximum(np.nan_to_num(grid.kappa_1_mm, posinf=1e300), kappa_floor)
    keep = np.ones(s_mm.size, dtype=bool)
    kept = 0
    lo_k = hi_k = kappa[0]
    for k in range(1, s_mm.size):
        gap = s_mm[k] - s_mm[kept]
        lo_k, hi_k = min(lo_k, kappa[k]), max(hi_k, kappa[k])
        if gap >= floor and (essential[k] or gap >= min(short[k], short[kept])
                             or hi_k > MERGE_KAPPA_RATIO * lo_k):
            kept = k
            lo_k = hi_k = kappa[k]
        elif (k == s_mm.size - 1 or rest[k]) and kept > 0 and not rest[kept]:
            keep[kept] = False  # a rest and the end stay: the node before them goes
            kept = k
        else:
            keep[k] = False
    s_mm, u, rest, v = s_mm[keep], u[keep], rest[keep], np.asarray(v_limit, dtype=float)[keep]
    rests = np.flatnonzero(rest)
    extra = [np.linspace(s_mm[a], s_mm[b], MIN_STRETCH_CELLS + 1)[1:-1]
             for a, b in zip(rests[:-1], rests[1:]) if b - a < MIN_STRETCH_CELLS]
    acc, jerk = _moving_limits(curve, lim)
    first_h = REST_CELL_SHARE * acc**3 / (6.0 * jerk**2)
    doubling = 2.0 ** np.arange(64)
    for a, b in zip(rests[:-1], rests[1:]):
        half = (s_mm[b] - s_mm[a]) / 2
        # each end's nodes within its own first interval: where the other end's is short, the
        # long one would keep no node and the profile creep up over all of it
        for at, side, inner in ((a, 1.0, a + 1), (b, -1.0, b - 1)):
            step = abs(s_mm[inner] - s_mm[at])
            # constant jerk from rest reaches the limit beside it after (2 v)^1.5 / (6 sqrt J)
            reach = (2.0 * v[inner]) ** 1.5 / (6.0 * math.sqrt(jerk))
            near = min(first_h, half / REST_CELLS_PER_STRETCH, reach) * doubling
            near = near[(near < min(half / 2, step)) & (near >= floor)]
            extra.append(s_mm[at] + side * near)
    s_mm, u, rest, v = _insert(curve, grid, s_mm, u, rest, v, extra)
    # cells in which even the limit spends more than CELL_PERIODS periods are cut
    h = np.diff(s_mm)
    speed = np.maximum(np.minimum(v[:-1], v[1:]), 1e-300)
    parts = np.ceil(h / (CELL_PERIODS * lim.period_s * speed))
    long = (parts > 1.0) & ~rest[:-1] & ~rest[1:]
    if s_mm.size + np.sum(parts[long] - 1.0) > max_nodes:
        return None
    if long.any():
        cut = [s_mm[i] + h[i] * np.arange(1, n) / n
               for i, n in zip(np.flatnonzero(long), parts[long].astype(np.int64))]
        s_mm, u, rest, v = _insert(curve, grid, s_mm, u, rest, v, cut)
    # the estimate again on the nodes (inserted ones took theirs by interpolation)
    cap = np.interp(s_mm, grid.s_mm, np.asarray(cap_mm_s, dtype=float))
    return s_mm, u, rest, speed_estimate(s_mm, cap, _moving_limits(curve, lim)[0], rest)


def cut_cells(curve: NurbsCurve, grid: Grid, lim: Limits, layout: Layout, times: np.ndarray,
              broken: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The nodes of `layout` with each inner cell whose schedule spends times[q] (Q,) over
    CELL_PERIODS * RECUT_SLACK periods in it cut into pieces of CELL_PERIODS (the estimate
    sized them without jerk, which slows the motion in tight turns far below it), and each
    whose schedule breaks a limit BETWEEN its points (broken (Q,)) cut in two at least; and
    the speed estimate then. None where no cell is either."""
    parts = np.maximum(np.ceil(times / (CELL_PERIODS * lim.period_s)), np.where(broken, 2, 1))
    long = np.flatnonzero((times > CELL_PERIODS * RECUT_SLACK * lim.period_s) | broken)
    if long.size == 0:
        return None
    s_mm, node = layout.s_mm, layout.cell_node
    h = s_mm[node[long] + 1] - s_mm[node[long]]
    cut = [s_mm[i] + hq * np.arange(1, n) / n
           for i, hq, n in zip(node[long], h, np.minimum(parts[long], MAX_CUT).astype(np.int64))]
    v = np.sqrt(np.interp(s_mm, layout.xi, layout.b_estimate))
    s_mm, u, rest, v = _insert(curve, grid, s_mm, layout.u, layout.rest, v, cut)
    return s_mm, u, rest, v


def _insert(curve: NurbsCurve, grid: Grid, s_mm: np.ndarray, u: np.ndarray, rest: np.ndarray,
            v: np.ndarray, extra: list[np.ndarray]) -> tuple[np.ndarray, ...]:
    """The nodes with those at arc lengths `extra` added (their u from the grid), but those
    within MIN_CELL_REL of the curve's length from a node or from one added before them: a
    cell of a rounding's length has a b'' its rows cannot hold."""
    if not extra:
        return s_mm, u, rest, v
    floor = MIN_CELL_REL * max(float(s_mm[-1]), 1e-300)
    more = np.unique(np.concatenate(extra))
    at = np.clip(np.searchsorted(s_mm, more), 1, s_mm.size - 1)
    near = np.minimum(np.abs(more - s_mm[at - 1]), np.abs(s_mm[at] - more))
    more = more[near >= floor]
    if more.size > 1:
        more = more[np.concatenate(([True], np.diff(more) >= floor))]
    if more.size == 0:
        return s_mm, u, rest, v
    order = np.argsort(np.concatenate([s_mm, more]), kind="stable")
    u_more = arc_parameters(curve, grid, more)
    v_more = np.interp(more, s_mm, v)
    return (np.concatenate([s_mm, more])[order], np.concatenate([u, u_more])[order],
            np.concatenate([rest, np.zeros(more.size, dtype=bool)])[order],
            np.concatenate([v, v_more])[order])


def _moving_limits(curve: NurbsCurve, lim: Limits) -> tuple[float, float]:
    """The least acceleration and jerk limit among the tangential ones and those of the axes the
    curve moves (a still axis's limits shape no start)."""
    moving = np.ptp(curve.points, axis=0) > 0.0
    acc = min([lim.acc_mm_s2] + [a for a, m in zip(lim.axis_acc_mm_s2, moving)
                                 if m and math.isfinite(a)])
    jerk = min([lim.jerk_mm_s3] + [j for j, m in zip(lim.axis_jerk_mm_s3, moving)
                                   if m and math.isfinite(j)])
    return acc, jerk


def point_geometry(curve: NurbsCurve, lim: Limits, u: np.ndarray, feed_mm_s: np.ndarray,
                   at_knot: np.ndarray) -> np.ndarray:
    """The geometry rows (N, G_SIZE) at parameters u (N,) (module docstring of `Layout`): the
    jump of kappa N where at_knot (N,) names the knot's index into curve.span_breaks (-1
    elsewhere), and the squared speed cap: the chord error and normal acceleration limit
    (`limits.speed_limit`), the programmed feed feed_mm_s (N,), each axis's velocity."""
    f = frames(curve, u)
    out = np.zeros((u.size, G_SIZE))
    k = f.kappa
    out[:, G_KAPPA] = k
    out[:, G_T:G_T + 3] = f.tangent
    out[:, G_K:G_K + 3] = k[:, None] * f.normal
    out[:, G_KS:G_KS + 3] = (-(k**2)[:, None] * f.tangent + f.dkappa_ds[:, None] * f.normal
                            + (k * f.torsion)[:, None] * f.binormal)
    knot = at_knot >= 0
    if knot.any():
        out[knot, G_D:G_D + 3] = kappa_n_jumps(curve, curve.span_breaks[at_knot[knot]])
    cap = np.minimum(speed_limit(k, lim, feed_mm_s), lim.feed_mm_s)
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(f.tangent[:, x])
            cap = np.minimum(cap, np.where(tx > 0.0, lim.axis_vel_mm_s[x]
                                           / np.where(tx > 0.0, tx, 1.0), np.inf))
    out[:, G_CAP] = cap**2
    return out


def _knot_index(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    """Per parameter (N,): the index of the interior knot it lies on (within rounding), -1."""
    breaks = curve.span_breaks[1:-1]
    out = np.full(u.size, -1, dtype=np.int64)
    if breaks.size == 0:
        return out
    near = np.clip(np.searchsorted(breaks, u), 0, breaks.size - 1)
    for cand in (near - 1, near):
        ok = cand >= 0
        c = np.where(ok, cand, 0)
        hit = ok & (np.abs(u - breaks[c]) <= 4 * np.spacing(np.abs(breaks[c]) + 1.0))
        out[hit] = c[hit] + 1  # index into span_breaks
    return out


def build_layout(curve: NurbsCurve, grid: Grid, lim: Limits, s_mm: np.ndarray, u: np.ndarray,
                 rest: np.ndarray, v_estimate: np.ndarray,
                 feed_at_u: Callable[[np.ndarray], np.ndarray]) -> Layout:
    """The layout of nodes (s_mm, u, rest) (M,) (`schedule_nodes`, with its speed estimate
    v_estimate (M,)): the spline's coefficients, its inner cells and the geometry at their
    points, the caps on the coefficients."""
    rests = np.flatnonzero(rest)
    xi, kw, width, first, last, rest_h, ratio = [], [], [], [], [], [], []
    cells, cell_node = [], []
    offset = 0
    for a, e in zip(rests[:-1], rests[1:]):
        knots = np.arange(a + 1, e)  # (K,) the spline's knots
        h = np.diff(s_mm[knots])
        xi.append(np.concatenate([[s_mm[a + 1]], 0.5 * (s_mm[knots[:-1]] + s_mm[knots[1:]]),
                                  [s_mm[e - 1]]]))
        inner = h[1:] / (h[:-1] + h[1:])
        kw.append(np.concatenate([[1.0], inner, [0.0], [0.5]]))  # the last has no interval
        width.append(np.concatenate([[1.0], h, [1.0]]))
        hr = (s_mm[a + 1] - s_mm[a], s_mm[e] - s_mm[e - 1])
        rest_h.append(hr)
        ratio.append((1.0 + 2.0 / 3.0 * h[0] / hr[0], 1.0 + 2.0 / 3.0 * h[-1] / hr[1]))
        first.append(offset)
        last.append(offset + knots.size)
        for j in range(knots.size - 1):
            cells.append((offset + j, 0.0, 0.0, 0.0, h[j]))
            cell_node.append(knots[j])
        offset += knots.size + 1
    xi_all = np.concatenate(xi)
    kw_all = np.concatenate(kw)
    cells_arr = np.array(cells, dtype=float).reshape(-1, 5)
    i0 = cells_arr[:, 0].astype(np.int64)
    cells_arr[:, 1] = xi_all[i0 + 1] - xi_all[i0]
    cells_arr[:, 2] = xi_all[i0 + 2] - xi_all[i0 + 1]
    cells_arr[:, 3] = kw_all[i0]
    node = np.array(cell_node, dtype=np.int64)
    # each cell's points: its start (on its own span), middle, end (at a knot one ulp below
    # it, on the span before it; elsewhere the next cell's start itself, so that rows.all_rows
    # sees the two are one point)
    u0 = u[node]
    end_knot = _knot_index(curve, u[node + 1])
    u1 = np.where(end_knot >= 0, np.maximum(np.nextafter(u[node + 1], -np.inf), u0),
                  u[node + 1])
    um = arc_parameters(curve, grid, 0.5 * (s_mm[node] + s_mm[node + 1]))
    pts_u = np.concatenate([u0, um, u1])
    at_knot = np.concatenate([_knot_index(curve, u0), np.full(um.size, -1), end_knot])
    geo = point_geometry(curve, lim, pts_u, feed_at_u(pts_u), at_knot)
    q = node.size
    geo3 = np.ascontiguousarray(np.stack([geo[:q], geo[q:2 * q], geo[2 * q:]], axis=1))
    h_node = s_mm[node + 1] - s_mm[node]
    mid_u = arc_parameters(curve, grid, np.concatenate([s_mm[node] + x * h_node
                                                        for x in BETWEEN]))
    mid = point_geometry(curve, lim, mid_u, feed_at_u(mid_u), np.full(mid_u.size, -1))
    between = np.ascontiguousarray(np.stack([mid[:q], mid[q:]], axis=1))
    first_a, last_a = np.array(first, dtype=np.int64), np.array(last, dtype=np.int64)
    ratio_a, rest_h_a = np.array(ratio), np.array(rest_h)
    cap = _coefficient_caps(xi_all.size, i0, geo3[:, :, G_CAP].min(axis=1))
    rc = rest_caps(curve, grid, lim, s_mm, rests, feed_at_u)
    for s in range(first_a.size):
        cap[first_a[s]] = min(cap[first_a[s]], rc[s, 0], cap[first_a[s] + 1] / ratio_a[s, 0])
        cap[last_a[s]] = min(cap[last_a[s]], rc[s, 1], cap[last_a[s] - 1] / ratio_a[s, 1])
    b_estimate = np.minimum(np.interp(xi_all, s_mm, np.asarray(v_estimate, dtype=float) ** 2),
                            cap)
    arrays = (s_mm, u, rest, xi_all, kw_all, np.concatenate(width), cap, b_estimate, first_a,
              last_a, rest_h_a, ratio_a, cells_arr, node, geo3, between)
    for arr in arrays:
        arr.setflags(write=False)
    return Layout(*arrays)


def _coefficient_caps(n: int, i0: np.ndarray, cell_cap: np.ndarray) -> np.ndarray:
    """Caps (C,) on the coefficients: b on a cell is a convex combination of its three, so each
    coefficient takes the lowest cap of the cells it shapes."""
    cap = np.full(n, np.inf)
    for j in range(3):
        np.minimum.at(cap, i0 + j, cell_cap)
    return np.maximum(cap, 0.0)


def rest_caps(curve: NurbsCurve, grid: Grid, lim: Limits, s_mm: np.ndarray, rests: np.ndarray,
              feed_at_u: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Per stretch (S, 2): the greatest far value b_far of each rest cell at which every limit
    holds at REST_POINTS of it (b = b_far y^(4/3), b' = 4/3 b_far y^(1/3) / h, b'' = 4/9 b_far
    y^(-2/3) / h^2 towards the rest; found by bisection: every quantity grows with b_far)."""

    out = np.empty((rests.size - 1, 2))
    ys = np.array(REST_POINTS)
    lim_arrays = (np.array(lim.axis_acc_mm_s2, dtype=float),
                  np.array(lim.axis_vel_mm_s, dtype=float),
                  np.array(lim.axis_jerk_mm_s3, dtype=float))
    for s, (a, e) in enumerate(zip(rests[:-1], rests[1:])):
        for side, (r, far) in enumerate(((a, a + 1), (e, e - 1))):
            h = abs(s_mm[far] - s_mm[r])
            sign = 1.0 if far > r else -1.0
            where = s_mm[r] + sign * ys * h
            uu = arc_parameters(curve, grid, where)
            geo = point_geometry(curve, lim, uu, feed_at_u(uu), np.full(uu.size, -1))
            geo.setflags(write=False)  # as the layout's: point_ratio compiles for one type
            best = lim.feed_mm_s**2
            for g, y in zip(geo, ys):
                b = y ** (4 / 3)
                d, dd = sign * 4 / 3 * y ** (1 / 3) / h, 4 / 9 * y ** (-2 / 3) / h**2
                best = min(best, _largest_scale(g, b, d, dd, lim, *lim_arrays, best))
            out[s, side] = best
    return out


def _largest_scale(g: np.ndarray, b: float, d: float, dd: float, lim: Limits,
                   acc_x: np.ndarray, vel_x: np.ndarray, jerk_x: np.ndarray,
                   top: float) -> float:
    """The greatest x <= top with (x b, x b', x b'') within every limit at geometry g."""

    def ok(x: float) -> bool:
        return point_ratio(g, x * b, x * d, x * dd, lim.jerk_mm_s3, lim.acc_mm_s2,
                           lim.normal_jerk_mm_s3, acc_x, vel_x, jerk_x, lim.period_s) <= 1.0

    if ok(top):
        return top
    low, high = 0.0, top
    for _ in range(REST_BISECTIONS):
        mid = 0.5 * (low + high)
        if ok(mid):
            low = mid
        else:
            high = mid
    return low
