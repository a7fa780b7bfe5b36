"""The schedule's cells (design §2d): where b = v^2 is planned along one curve, and what the
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

so b, b' and b'' anywhere on a cell are linear in its three coefficients (`point_weights`):
the planner's motion (b and a = b'/2 at every knot, planning.reach_schedule) is these
coefficients, and the exact check reads every cell through them (planning.ratios). A rest cell's
b = c y^(4/3) has every quantity proportional to a power of its far coefficient c, so its
limits are a cap on c (`rest_caps`), and its C1 join with the spline fixes the coefficient
after c: c_1 = c_0 (1 + 2/3 h_1 / h_rest).

A chain that starts (ends) moving in a given state (basis.ChainEnds) has no rest cell there:
its spline's first (last) knot is that end, and the state's b and b' fix the two coefficients
beside it, c_0 = b, c_1 = b + g_0 b' (`end_coefficients`).

Where the nodes lie is planning.nodes'.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.basis import (
    AT_REST,
    BETWEEN,
    G_CAP,
    ChainEnds,
)
from nurbsfeed.planning.grid import Grid
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.path_check import arc_parameters
from nurbsfeed.planning.path_model import geometry_rows
from nurbsfeed.planning.ratios import point_ratio

REST_POINTS = (0.25, 0.5, 1.0)  # where a rest cell's limits are read, as y
REST_BISECTIONS = 60
# a node this close to an interior knot (a share of the parameter range) is on it (_knot_index)
KNOT_NEAR_REL = 1e-6


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
    # (2,): whether the chain starts (ends) moving; fixed (2, 2): then the coefficients that
    # state fixes, (c_0, c_1) at the start and (c_C-2, c_C-1) at the end (`end_coefficients`)
    moving: np.ndarray
    fixed: np.ndarray

    @property
    def n_coefficients(self) -> int:
        return self.xi.size

    def is_open(self, stretch: int, side: int) -> bool:
        """Whether that end of the stretch is the chain's moving end (no rest cell there)."""
        last = self.first.size - 1
        return bool(self.moving[side]) and stretch == (0 if side == 0 else last)

    @property
    def fixed_index(self) -> np.ndarray:
        """The coefficients (F,) the moving ends fix, and their values (F,) (`fixed`)."""
        idx = [np.array([0, 1])] if self.moving[0] else []
        if self.moving[1]:
            idx.append(np.array([self.xi.size - 2, self.xi.size - 1]))
        return np.concatenate(idx) if idx else np.empty(0, dtype=np.int64)

    @property
    def fixed_values(self) -> np.ndarray:
        rows = [self.fixed[side] for side in range(2) if self.moving[side]]
        return np.concatenate(rows) if rows else np.empty(0)


def point_geometry(curve: NurbsCurve, lim: Limits, u: np.ndarray, feed_mm_s: np.ndarray,
                   at_knot: np.ndarray) -> np.ndarray:
    """The geometry rows (N, G_SIZE) at parameters u (N,) (module docstring of `Layout`): the
    jump of kappa N where at_knot (N,) names the knot's index into curve.span_breaks (-1
    elsewhere), and the squared speed cap: the chord error and normal acceleration limit
    (`limits.speed_limit`), the programmed feed feed_mm_s (N,), each axis's velocity
    (`path_model.geometry_rows`, one compiled pass)."""
    return geometry_rows(curve, lim, u, feed_mm_s, at_knot)


def _knot_index(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    """Per parameter (N,): the index of the interior knot it lies on, -1. On it within
    KNOT_NEAR_REL of the parameter range: a node the knot's own merged into (nodes.py keeps
    none closer than a millionth of the length; a chain's joint feed step puts one 1e-9 of the
    range before it) stands for the knot, and its jump of kappa N, which the points one period
    apart read wherever in the period it falls, joins that node's rows."""
    breaks = curve.span_breaks[1:-1]
    out = np.full(u.size, -1, dtype=np.int64)
    if breaks.size == 0:
        return out
    near_u = KNOT_NEAR_REL * float(curve.span_breaks[-1] - curve.span_breaks[0])
    near = np.clip(np.searchsorted(breaks, u), 0, breaks.size - 1)
    for cand in (near - 1, near):
        ok = cand >= 0
        c = np.where(ok, cand, 0)
        hit = ok & (np.abs(u - breaks[c]) <= np.maximum(
            near_u, 4 * np.spacing(np.abs(breaks[c]) + 1.0)))
        out[hit] = c[hit] + 1  # index into span_breaks
    return out


def build_layout(curve: NurbsCurve, grid: Grid, lim: Limits, s_mm: np.ndarray, u: np.ndarray,
                 rest: np.ndarray, v_estimate: np.ndarray,
                 feed_at_u: Callable[[np.ndarray], np.ndarray],
                 ends: ChainEnds = AT_REST) -> Layout:
    """The layout of nodes (s_mm, u, rest) (M,) (`schedule_nodes`, with its speed estimate
    v_estimate (M,)): the spline's coefficients, its inner cells and the geometry at their
    points, the caps on the coefficients. A moving end of the chain (`ends`) has no rest cell:
    the spline's first (last) knot is the end itself, and the state there fixes the two
    coefficients beside it (`Layout.fixed`)."""
    rests = np.flatnonzero(rest)
    xi, kw, width, first, last, rest_h, ratio = [], [], [], [], [], [], []
    cells, cell_node = [], []
    offset = 0
    n_stretches = rests.size - 1
    for stretch, (a, e) in enumerate(zip(rests[:-1], rests[1:])):
        open_start = stretch == 0 and ends.start is not None
        open_end = stretch == n_stretches - 1 and ends.end is not None
        knots = np.arange(a if open_start else a + 1, e + 1 if open_end else e)  # (K,)
        h = np.diff(s_mm[knots])
        xi.append(np.concatenate([[s_mm[knots[0]]],
                                  0.5 * (s_mm[knots[:-1]] + s_mm[knots[1:]]),
                                  [s_mm[knots[-1]]]]))
        inner = h[1:] / (h[:-1] + h[1:])
        kw.append(np.concatenate([[1.0], inner, [0.0], [0.5]]))  # the last has no interval
        width.append(np.concatenate([[1.0], h, [1.0]]))
        hr = (0.0 if open_start else s_mm[a + 1] - s_mm[a],
              0.0 if open_end else s_mm[e] - s_mm[e - 1])
        rest_h.append(hr)
        ratio.append((1.0 if open_start else 1.0 + 2.0 / 3.0 * h[0] / hr[0],
                      1.0 if open_end else 1.0 + 2.0 / 3.0 * h[-1] / hr[1]))
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
    open_sides = np.zeros((first_a.size, 2), dtype=bool)
    open_sides[0, 0], open_sides[-1, 1] = ends.moving
    rc = rest_caps(curve, grid, lim, s_mm, rests, feed_at_u, open_sides)
    for s in range(first_a.size):
        if not open_sides[s, 0]:
            cap[first_a[s]] = min(cap[first_a[s]], rc[s, 0],
                                  cap[first_a[s] + 1] / ratio_a[s, 0])
        if not open_sides[s, 1]:
            cap[last_a[s]] = min(cap[last_a[s]], rc[s, 1], cap[last_a[s] - 1] / ratio_a[s, 1])
    b_estimate = np.minimum(np.interp(xi_all, s_mm, np.asarray(v_estimate, dtype=float) ** 2),
                            cap)
    arrays = (s_mm, u, rest, xi_all, kw_all, np.concatenate(width), cap, b_estimate, first_a,
              last_a, rest_h_a, ratio_a, cells_arr, node, geo3, between,
              np.array(ends.moving), end_coefficients(xi_all, ends))
    for arr in arrays:
        arr.setflags(write=False)
    return Layout(*arrays)


def end_coefficients(xi: np.ndarray, ends: ChainEnds) -> np.ndarray:
    """The coefficients (2, 2) a moving end fixes: b and b' there are the first (last)
    coefficient and the polygon's first (last) slope, so c_0 = b, c_1 = b + g_0 b' at the
    start and c_C-1 = b, c_C-2 = b - g_C-2 b' at the end (0 where the chain rests)."""
    out = np.zeros((2, 2))
    if ends.start is not None:
        out[0] = ends.start.b, ends.start.b + (xi[1] - xi[0]) * ends.start.db_ds
    if ends.end is not None:
        out[1] = ends.end.b - (xi[-1] - xi[-2]) * ends.end.db_ds, ends.end.b
    return out


def _coefficient_caps(n: int, i0: np.ndarray, cell_cap: np.ndarray) -> np.ndarray:
    """Caps (C,) on the coefficients: b on a cell is a convex combination of its three, so each
    coefficient takes the lowest cap of the cells it shapes."""
    cap = np.full(n, np.inf)
    for j in range(3):
        np.minimum.at(cap, i0 + j, cell_cap)
    return np.maximum(cap, 0.0)


def rest_caps(curve: NurbsCurve, grid: Grid, lim: Limits, s_mm: np.ndarray, rests: np.ndarray,
              feed_at_u: Callable[[np.ndarray], np.ndarray],
              open_sides: np.ndarray | None = None) -> np.ndarray:
    """Per stretch (S, 2): the greatest far value b_far of each rest cell at which every limit
    holds at REST_POINTS of it (b = b_far y^(4/3), b' = 4/3 b_far y^(1/3) / h, b'' = 4/9 b_far
    y^(-2/3) / h^2 towards the rest; found by bisection: every quantity grows with b_far);
    inf at the open sides (S, 2) (a moving end has no rest cell)."""

    out = np.empty((rests.size - 1, 2))
    ys = np.array(REST_POINTS)
    lim_arrays = (np.array(lim.axis_acc_mm_s2, dtype=float),
                  np.array(lim.axis_vel_mm_s, dtype=float),
                  np.array(lim.axis_jerk_mm_s3, dtype=float))
    for s, (a, e) in enumerate(zip(rests[:-1], rests[1:])):
        for side, (r, far) in enumerate(((a, a + 1), (e, e - 1))):
            if open_sides is not None and open_sides[s, side]:
                out[s, side] = np.inf
                continue
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
