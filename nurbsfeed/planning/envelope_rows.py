"""The envelope planner's bounds (planning.envelope, design §2e): the geometry and caps at the
nodes, the quadratic spline whose coefficients the passes lower, and the rows each pass holds,
with sqrt(b) and the terms that tighten a bound frozen where the profile asks."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.optimal import _caps as optimal_caps
from nurbsfeed.planning.optimal import _Nodes
from nurbsfeed.planning.path_model import Frames

TINY = 1e-12


def _geometry(f: Frames) -> np.ndarray:
    """Per point (N,) of the frames f: kappa, dkappa/ds, T (3), K = kappa N (3), K_s (3), tau,
    as (N, 12)."""
    k = f.kappa[:, None]
    k_s = (-(f.kappa**2)[:, None] * f.tangent + f.dkappa_ds[:, None] * f.normal
           + (f.kappa * f.torsion)[:, None] * f.binormal)
    return np.ascontiguousarray(np.column_stack([f.kappa, f.dkappa_ds, f.tangent, k * f.normal,
                                                 k_s, f.torsion]))


def _caps(lim: Limits, f: Frames, jumps: np.ndarray, feed_mm_s: np.ndarray) -> np.ndarray:
    """The speed limit (N,) where b' and b'' play no part, at points with frames f, jumps
    (N, 3) of kappa N (`optimal._jumps`) and programmed feed (N,): the optimal planner's caps
    (`limits.speed_limit`, the axis velocities, the jumps read over a period), the binormal
    jerk sqrt(b) kappa tau b <= J_n, and where the path is straight (kappa = 0) the normal jerk
    kappa' v^3 <= J_n."""
    cap = optimal_caps(lim, f, jumps, feed_mm_s)
    with np.errstate(divide="ignore"):
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
