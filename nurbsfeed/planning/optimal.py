"""The optimal planner (profile key `planner: optimal`, design §2d): the squared speed b = v^2
over arc length, made as large as the path model's limits allow by sequential linear
programming, then sampled into a time law.

Why: the paper's planner holds a = j = 0 at every key point, so it passes a curvature peak at
its static limit, kappa^2 v^3 <= J_t. The motion a machine can run lets the law's own jerk j
follow kappa^2 v^3 there, which cancels it in the tangential component j - kappa^2 v^3 (the
speed is at a minimum); no S-curve with one jerk per phase can do that.

The schedule. Nodes s_0 .. s_M-1 (the base plan's grid, refined where a cell lasts longer than
REFINE_PERIODS periods) carry b_i, the only variables. Between two nodes b is the cubic Hermite
interpolant of b_i, b_i+1 and slopes d_i, d_i+1, each the three-point difference of the b's
around its node (exact for a quadratic): b is C1, so the acceleration a = b'/2 is continuous,
and the law's jerk j = sqrt(b) b''/2 is bounded. A cell beside a rest (an end, a corner, a cusp)
is b = b_far y^(4/3), y the distance to the rest over the cell: constant jerk from rest, the
shape of the time-optimal start (a Hermite cell from b = 0 would never leave it); its far node's
slope is then 4/3 b_far / h, so the next cell joins it C1.

The constraints hold at each cell's start, middle and end (a rest cell: its middle and far end),
where b, b' and b'' are linear in the node b's. Along C(s), with K = kappa N and K_s = dK/ds,

    velocity = sqrt(b) T,  acceleration = b'/2 T + b K,  jerk = sqrt(b) (b''/2 T + 3/2 b' K + b K_s)

- b <= cap^2: the chord error, the normal acceleration, the feed, each axis's velocity and, at a
  knot where kappa N jumps, `path_model.jump_limits`;
- |b'| <= 2 A_t and each axis's acceleration;
- sqrt(b) |L(b)| <= J for the jerk's tangential, normal and binormal components (normal and
  binormal each within J_n: together within sqrt(2) J_n, and the check below holds their norm)
  and each axis's jerk, L linear.

Sequential linear programming. J / sqrt(b) is convex in b, so its tangent at the iterate b_k
lies below it: L(b) + J b / (2 b_k^1.5) <= 3 J / (2 sqrt(b_k)) implies sqrt(b) L(b) <= J (a
convex-concave step). Each linear program (scipy's HiGHS) maximises sum w_i b_i / b_k,i^1.5, the
cycle time's linearisation, under these rows: every iterate keeps every constraint, and a step
that does not shorten the cycle is halved. The first iterate comes from the base plan's law.

The law. The machine sees positions only at the periods: the schedule's s(t) (Hermite cells by
Gauss-Legendre and Newton, rest cells in closed form, s = h (t / t_c)^3) is sampled
SAMPLES_PER_PERIOD times a period, each stretch between rests stretched to a whole number of
periods, and a cubic spline in t through the samples, with v = a = 0 at both ends, gives the
constant-jerk pieces of a `TimeLaw`.

Verification. The law is sampled twice a period and every path-model quantity measured
(`path_check.law_ratios`). Where one exceeds its limit (between constraint points, or where the
spline departs from the schedule), the limits of that cell and its neighbours are lowered by the
ratio and the programs run again (FIX_ROUNDS), keeping the plan that is fastest after the uniform
slowdown it still needs. The base plan stays where the optimiser cannot help: a program that
fails, a plan no faster, a grid above MAX_NODES.

Independent of `analysis.bound` (the reference `plan --reference` compares with): that one's
variables are b and b' on cells of its own with b quadratic on each; nothing is shared but the
`Limits` record and the curve.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.grid import Grid
from nurbsfeed.planning.limits import Limits, speed_limit
from nurbsfeed.planning.path_check import arc_parameters, law_ratios
from nurbsfeed.planning.path_model import Frames, frames, jump_speeds, kappa_n_jumps
from nurbsfeed.planning.timelaw import TimeLaw

REFINE_PERIODS = 4.0  # a cell lasting longer than this many periods is split
REFINE_ROUNDS = 3
MAX_NODES = 40_000  # above this the base plan stays (a linear program's cost grows ~ M^2)
MIN_CELL_REL = 1e-9  # of the curve's length: nodes closer than this are merged
MIN_STRETCH_CELLS = 4  # a stretch between rests has at least this many cells
REST_CELL_SHARE = 0.05  # of A^3 / (6 J^2): the first cell beside a rest at most ...
REST_CELLS_PER_STRETCH = 32  # ... and at most this share of half its stretch
MAX_ITERATIONS = 30  # linear programs per round
CONVERGED_REL = 5e-4  # a step shortening the cycle by less than this (relative): converged
STEP_SHARES = (1.0, 0.5, 0.25, 0.125)  # of a step, tried in turn until one shortens the cycle
FLOOR_SHARE = 1e-8  # of feed^2: the smallest b a linearisation takes
LP_NUMERICAL_TROUBLE = 4  # linprog's status when HiGHS stops on numerical difficulties: a helix
# (tau != 0) did so on its first program, and solved with its rows scaled
FIX_ROUNDS = 3  # rounds that lower the limits where the law exceeds them
FIX_REL = 0.02  # ... while it does so by more than this
SAMPLES_PER_PERIOD = 2  # of the schedule, for the law's spline
NEWTON_STEPS = 12
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_POINT_X = (0.0, 0.5, 1.0)  # where a Hermite cell is constrained, as a share of its length
_REST_Y = (0.5, 1.0)  # where a rest cell is, as a share of the distance from its rest


def _hermite_basis(x: np.ndarray | float) -> np.ndarray:
    """The cubic Hermite basis (h00, h10, h01, h11) at x in [0, 1]: (4,) or (4, N)."""
    return np.array([2 * x**3 - 3 * x**2 + 1, x**3 - 2 * x**2 + x, -2 * x**3 + 3 * x**2,
                     x**3 - x**2])


def _hermite(x: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`_hermite_basis` at x and its first and second derivatives in x: three (4,) arrays."""
    return (_hermite_basis(x),
            np.array([6 * x**2 - 6 * x, 3 * x**2 - 4 * x + 1, -6 * x**2 + 6 * x,
                      3 * x**2 - 2 * x]),
            np.array([12 * x - 6, 6 * x - 4, -12 * x + 6, 6 * x - 2]))


@dataclass(frozen=True, eq=False)
class _Nodes:
    """The schedule's nodes (M,): arc length, parameter, rest flags."""

    s_mm: np.ndarray
    u: np.ndarray
    rest: np.ndarray

    @property
    def h_mm(self) -> np.ndarray:
        return np.diff(self.s_mm)

    @cached_property
    def slopes(self) -> Any:
        """The slope matrix (M, M), scipy.sparse.csr_matrix: d = slopes @ b (`_slope_matrix`).
        Made when first asked for: the envelope planner gives its own slopes and runs without
        scipy."""
        return _slope_matrix(self.s_mm, self.rest)


def _slope_matrix(s_mm: np.ndarray, rest: np.ndarray) -> Any:
    """d_i as a linear map of the b's: the three-point difference on the uneven grid, 4/3 b_i / h
    (with the sign of the direction away from the rest) beside a rest, 0 at a rest."""
    import scipy.sparse as sp

    m = s_mm.size
    h = np.diff(s_mm)
    i = np.arange(1, m - 1)
    h0, h1 = h[:-1], h[1:]
    after = rest[i - 1] & ~rest[i]
    before = rest[i + 1] & ~rest[i] & ~after
    inner = ~rest[i] & ~after & ~before
    rows = [i[inner]] * 3 + [i[after], i[before]]
    cols = [i[inner] - 1, i[inner], i[inner] + 1, i[after], i[before]]
    vals = [(-h1 / (h0 * (h0 + h1)))[inner], ((h1 - h0) / (h0 * h1))[inner],
            (h0 / (h1 * (h0 + h1)))[inner], 4.0 / 3.0 / h0[after], -4.0 / 3.0 / h1[before]]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(m, m))


def _nodes(curve: NurbsCurve, grid: Grid, lim: Limits, s_mm: np.ndarray, u: np.ndarray,
           rest: np.ndarray, v_limit: np.ndarray | None = None) -> _Nodes:
    """Nodes from arc lengths: those closer than MIN_CELL_REL of the length to the last one kept
    merged (a rest is always kept); a stretch between rests cut into at least MIN_STRETCH_CELLS
    cells (a node between two rest cells would join two slopes of opposite signs); and beside
    each rest nodes at h, 2h, 4h ... from it, h = REST_CELL_SHARE of the distance a constant-jerk
    start takes to reach the acceleration limit, or of half the stretch if that is shorter (a rest
    cell runs at constant jerk all along: a long one is a slow start), and with v_limit (N,), a
    speed no motion exceeds at the nodes, no longer than constant jerk from the rest takes to
    reach it at the node beside the rest (a cell sized for full speed took 0.6 s to leave a rest
    at a programmed 0.1 mm/s, where 2 ms do)."""
    floor = MIN_CELL_REL * max(float(s_mm[-1]), 1e-300)
    keep = np.ones(s_mm.size, dtype=bool)
    kept = 0
    for k in range(1, s_mm.size):
        if s_mm[k] - s_mm[kept] >= floor:
            kept = k
        elif (k == s_mm.size - 1 or rest[k]) and kept > 0 and not rest[kept]:
            keep[kept] = False  # a rest and the end stay: the node before them goes
            kept = k
        else:
            keep[k] = False
    s_mm, u, rest = s_mm[keep], u[keep], rest[keep]
    v = np.full(s_mm.size, np.inf) if v_limit is None else np.asarray(v_limit, dtype=float)[keep]
    rest_index = np.flatnonzero(rest)
    extra = [np.linspace(s_mm[a], s_mm[b], MIN_STRETCH_CELLS + 1)[1:-1]
             for a, b in zip(rest_index[:-1], rest_index[1:]) if b - a < MIN_STRETCH_CELLS]
    # the axes the curve moves: a still axis's limits shape no start (a Z at 0.001 mm/s^2 put
    # nodes 1e-20 mm apart, which the end's arc length could not tell apart)
    moving = np.ptp(curve.points, axis=0) > 0.0
    acc = min([lim.acc_mm_s2] + [a for a, m in zip(lim.axis_acc_mm_s2, moving)
                                 if m and math.isfinite(a)])
    jerk = min([lim.jerk_mm_s3] + [j for j, m in zip(lim.axis_jerk_mm_s3, moving)
                                   if m and math.isfinite(j)])
    first = REST_CELL_SHARE * acc**3 / (6.0 * jerk**2)
    for a, b in zip(rest_index[:-1], rest_index[1:]):
        half = (s_mm[b] - s_mm[a]) / 2
        doubling = 2.0 ** np.arange(64)
        # each end's nodes within its own first interval: where the other end's is short, the
        # long one kept no node and the profile crept up over all of it (a 23 mm curve at a
        # programmed 0.1 mm/s took 1.2 mm and 10 s to reach it, fuzz seed 58)
        for at, side, inner in ((a, 1.0, a + 1), (b, -1.0, b - 1)):
            step = abs(s_mm[inner] - s_mm[at])
            # constant jerk from rest reaches the limit beside it after (2 v)^1.5 / (6 sqrt(J))
            reach = (2.0 * v[inner]) ** 1.5 / (6.0 * math.sqrt(jerk))
            near = min(first, half / REST_CELLS_PER_STRETCH, reach) * doubling
            near = near[(near < min(half / 2, step)) & (near >= floor)]
            extra.append(s_mm[at] + side * near)
    if extra:
        more = np.setdiff1d(np.concatenate(extra), s_mm)
        s_all = np.concatenate([s_mm, more])
        order = np.argsort(s_all, kind="stable")
        u = np.concatenate([u, arc_parameters(curve, grid, more)])[order]
        rest = np.concatenate([rest, np.zeros(more.size, dtype=bool)])[order]
        s_mm = s_all[order]
    return _Nodes(s_mm, u, rest)


@dataclass(frozen=True, eq=False)
class _Points:
    """The P constraint points: the cell each lies in, its parameter, and b, b', b'' there as
    sparse (P, M) maps of the node b's."""

    cell: np.ndarray
    u: np.ndarray
    b: Any  # scipy.sparse.csr_matrix (P, M)
    d: Any
    dd: Any


def _points(curve: NurbsCurve, grid: Grid, nodes: _Nodes) -> _Points:
    import scipy.sparse as sp

    m = nodes.s_mm.size
    h = nodes.h_mm
    rest = nodes.rest
    eye = sp.identity(m, format="csr")
    cells = np.arange(m - 1)
    hermite = ~(rest[:-1] | rest[1:])
    c = cells[hermite]
    hc = h[c]
    start, end, s_start, s_end = eye[c], eye[c + 1], nodes.slopes[c], nodes.slopes[c + 1]
    cell, share, b, d, dd = [], [], [], [], []
    for x in _POINT_X:
        h0, h1, h2 = _hermite(x)
        diag = sp.diags
        b.append(diag(np.full(c.size, h0[0])) @ start + diag(h0[1] * hc) @ s_start
                 + diag(np.full(c.size, h0[2])) @ end + diag(h0[3] * hc) @ s_end)
        d.append(diag(h1[0] / hc) @ start + diag(np.full(c.size, h1[1])) @ s_start
                 + diag(h1[2] / hc) @ end + diag(np.full(c.size, h1[3])) @ s_end)
        dd.append(diag(h2[0] / hc**2) @ start + diag(h2[1] / hc) @ s_start
                  + diag(h2[2] / hc**2) @ end + diag(h2[3] / hc) @ s_end)
        cell.append(c)
        share.append(np.full(c.size, x))
    for from_rest in (True, False):
        c = np.flatnonzero(rest[:-1] & ~rest[1:]) if from_rest else np.flatnonzero(
            rest[1:] & ~rest[:-1])
        far = eye[c + 1] if from_rest else eye[c]
        hc = h[c]
        sign = 1.0 if from_rest else -1.0
        for y in _REST_Y:
            b.append(sp.diags(np.full(c.size, y ** (4 / 3))) @ far)
            d.append(sp.diags(sign * 4 / 3 * y ** (1 / 3) / hc) @ far)
            dd.append(sp.diags(4 / 9 * y ** (-2 / 3) / hc**2) @ far)
            cell.append(c)
            share.append(np.full(c.size, y if from_rest else 1.0 - y))
    cell_all = np.concatenate(cell)
    share_all = np.concatenate(share)
    u = np.empty(cell_all.size)
    at_start = share_all == 0.0
    at_end = share_all == 1.0
    inside = ~at_start & ~at_end
    u[at_start] = nodes.u[cell_all[at_start]]
    # a cell's end is read from inside the cell: at a knot, the span before it
    u[at_end] = np.nextafter(nodes.u[cell_all[at_end] + 1], -np.inf)
    u[at_end] = np.maximum(u[at_end], nodes.u[cell_all[at_end]])
    u[inside] = arc_parameters(curve, grid, nodes.s_mm[cell_all[inside]]
                               + share_all[inside] * h[cell_all[inside]])
    return _Points(cell_all, u, sp.vstack(b).tocsr(), sp.vstack(d).tocsr(),
                   sp.vstack(dd).tocsr())


def _jumps(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    """The jump D (P, 3) of kappa N at points u (P,) that lie on an interior knot, from either
    side (a cell's end is read one ulp below it); 0 elsewhere (`path_model.kappa_n_jumps`)."""
    breaks = curve.span_breaks[1:-1]
    out = np.zeros((u.size, 3))
    if breaks.size == 0:
        return out
    near = np.searchsorted(breaks, u)
    for side in (near - 1, near):
        ok = (side >= 0) & (side < breaks.size)
        at = np.zeros(u.size, dtype=bool)
        at[ok] = np.abs(u[ok] - breaks[side[ok]]) <= 4 * np.spacing(np.abs(breaks[side[ok]]))
        if at.any():
            out[at] = kappa_n_jumps(curve, breaks[side[at]])
    return out


def _caps(lim: Limits, f: Frames, jumps: np.ndarray, feed_mm_s: np.ndarray) -> np.ndarray:
    """The speed limit (P,): `limits.speed_limit`, each axis's velocity and, where kappa N jumps
    by D, `path_model.jump_speeds`."""
    cap = np.minimum(speed_limit(f.kappa, lim, feed_mm_s), jump_speeds(jumps, lim))
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(f.tangent[:, x])
            cap = np.minimum(cap, np.where(tx > 0.0, lim.axis_vel_mm_s[x]
                                           / np.where(tx > 0.0, tx, 1.0), np.inf))
    return cap


def _solve_lp(objective: np.ndarray, matrix: Any, bound: np.ndarray, box: np.ndarray
              ) -> np.ndarray | None:
    """min objective . x under matrix x <= bound and box (scipy's HiGHS); None if it fails."""
    import scipy.sparse as sp
    from scipy.optimize import linprog

    if not (np.all(np.isfinite(matrix.data)) and np.all(np.isfinite(bound))
            and np.all(np.isfinite(objective))):
        return None
    res = linprog(objective, A_ub=matrix, b_ub=bound, bounds=box, method="highs")
    if res.status == LP_NUMERICAL_TROUBLE:
        # rows scaled to a largest coefficient of 1 (slower as a rule: not the first try)
        scale = 1.0 / np.maximum(abs(matrix).max(axis=1).toarray().ravel(), 1e-300)
        res = linprog(objective, A_ub=sp.diags(scale) @ matrix, b_ub=bound * scale,
                      bounds=box, method="highs")
    if res.status != 0 or not np.all(np.isfinite(res.x)):
        return None
    return np.asarray(res.x)


class _Problem:
    """The linear rows of one round: fixed ones (speed caps, accelerations) and the jerk
    families (coefficient map, per-point limit), each point's limits scaled by its cell's
    factor (FIX_ROUNDS lower it where the law exceeded a limit)."""

    def __init__(self, curve: NurbsCurve, grid: Grid, lim: Limits, nodes: _Nodes,
                 feed_at_u: Callable[[np.ndarray], np.ndarray], cell_scale: np.ndarray) -> None:
        import scipy.sparse as sp

        self.lim = lim
        self.nodes = nodes
        pts = _points(curve, grid, nodes)
        self.points = pts
        f = frames(curve, pts.u)
        jumps = _jumps(curve, pts.u)
        scale = cell_scale[pts.cell]
        diag = sp.diags
        k, ks, tau = f.kappa, f.dkappa_ds, f.torsion
        cap = np.minimum(_caps(lim, f, jumps, feed_at_u(pts.u)), lim.feed_mm_s) * scale
        self.cap2 = cap**2
        acc2 = 2.0 * lim.acc_mm_s2 * scale**2
        rows = [pts.b, pts.d, -pts.d, -pts.b]
        limits = [self.cap2, acc2, acc2, np.zeros(k.size)]
        # (coefficients of L, limit J, jump term |D| / T): sqrt(b) |L| + b |D| / T <= J; at a
        # knot where kappa N jumps, the jump read over one period adds to the jerk around it
        period = lim.period_s
        size = np.linalg.norm(jumps, axis=1) / period
        self.jerk: list[tuple[Any, np.ndarray, np.ndarray]] = [
            (0.5 * pts.dd - diag(k**2) @ pts.b, lim.jerk_mm_s3 * scale**3, np.zeros(k.size)),
            (1.5 * diag(k) @ pts.d + diag(ks) @ pts.b, lim.normal_jerk_mm_s3 * scale**3, size)]
        if np.any(k * tau != 0.0):
            self.jerk.append((diag(k * tau) @ pts.b, lim.normal_jerk_mm_s3 * scale**3, size))
        for x in range(3):
            t_x, n_x, b_x = f.tangent[:, x], f.normal[:, x], f.binormal[:, x]
            if math.isfinite(lim.axis_acc_mm_s2[x]):
                row = diag(k * n_x) @ pts.b + 0.5 * diag(t_x) @ pts.d
                rows += [row, -row]
                limits += [lim.axis_acc_mm_s2[x] * scale**2] * 2
            if math.isfinite(lim.axis_jerk_mm_s3[x]):
                ks_x = -(k**2) * t_x + ks * n_x + k * tau * b_x
                self.jerk.append((0.5 * diag(t_x) @ pts.dd + 1.5 * diag(k * n_x) @ pts.d
                                  + diag(ks_x) @ pts.b, lim.axis_jerk_mm_s3[x] * scale**3,
                                  np.abs(jumps[:, x]) / period))
        self.fixed = sp.vstack(rows).tocsr()
        self.fixed_limit = np.concatenate(limits)
        h = nodes.h_mm
        self.weight = np.zeros(nodes.s_mm.size)
        self.weight[:-1] += h / 2
        self.weight[1:] += h / 2
        self.upper = np.where(nodes.rest, 0.0, lim.feed_mm_s**2)

    def step(self, b: np.ndarray) -> np.ndarray | None:
        """One linear program linearised at b (M,): its solution, or None if it failed."""
        import scipy.sparse as sp

        floor = FLOOR_SHARE * self.lim.feed_mm_s**2
        # any b > 0 is a valid point of tangency; one above the cap would let a jump term make
        # b = 0 infeasible
        at = np.clip(self.points.b @ b, floor, np.maximum(self.cap2, floor))
        root = np.sqrt(at)
        rows, limits = [self.fixed], [self.fixed_limit]
        for coef, limit, jump in self.jerk:
            # J / sqrt(b) - jump sqrt(b) is convex: its tangent at `at` lies below it
            slope = sp.diags(limit / (2.0 * at * root) + jump / (2.0 * root)) @ self.points.b
            for sign in (1.0, -1.0):
                rows.append(sign * coef + slope)
                limits.append(1.5 * limit / root - 0.5 * jump * root)
        slowness = self.weight / np.maximum(b, floor) ** 1.5
        objective = -slowness / slowness.sum()
        matrix, bound = sp.vstack(rows).tocsr(), np.concatenate(limits)
        box = np.stack([np.zeros(b.size), self.upper], axis=1)
        x = _solve_lp(objective, matrix, bound, box)
        return None if x is None else np.minimum(np.maximum(x, 0.0), self.upper)

    def improve(self, b: np.ndarray) -> np.ndarray | None:
        """Convex-concave steps from b until the cycle stops shortening; None if the first
        program fails (b itself may break the rows: the first solution is taken as it is)."""
        first = self.step(b)
        if first is None:
            return None
        b = first
        cycle = cycle_s(self.nodes, b)
        for _ in range(MAX_ITERATIONS - 1):
            proposed = self.step(b)
            if proposed is None:
                break
            for share in STEP_SHARES:
                candidate = b + share * (proposed - b)
                shorter = cycle_s(self.nodes, candidate)
                if shorter < cycle:
                    break
            else:
                break
            gain = cycle - shorter
            b, cycle = candidate, shorter
            if gain < CONVERGED_REL * cycle:
                break
        return b


def _hermite_b(nodes: _Nodes, b: np.ndarray, d: np.ndarray, cell: np.ndarray,
               x: np.ndarray) -> np.ndarray:
    """b inside Hermite cells (N,) at shares x (N,) of their lengths."""
    h = nodes.h_mm[cell]
    h00, h10, h01, h11 = _hermite_basis(x)
    return h00 * b[cell] + h10 * h * d[cell] + h01 * b[cell + 1] + h11 * h * d[cell + 1]


def _cell_times(nodes: _Nodes, b: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Each cell's duration (M-1,): Gauss-Legendre on 1 / sqrt(b) in a Hermite cell, 3 h /
    sqrt(b_far) in a rest cell (inf where b reaches 0 inside a cell)."""
    h = nodes.h_mm
    cell = np.repeat(np.arange(h.size), _GL_X.size)
    x = np.tile((_GL_X + 1) / 2, h.size)
    inside = _hermite_b(nodes, b, d, cell, x).reshape(h.size, _GL_X.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        quad = h / 2 * (np.where(inside > 0.0, 1.0 / np.sqrt(np.maximum(inside, 0.0)), np.inf)
                        @ _GL_W)
        rest = nodes.rest
        return np.where(rest[:-1], 3 * h / np.sqrt(b[1:]),
                        np.where(rest[1:], 3 * h / np.sqrt(b[:-1]), quad))


def cycle_s(nodes: _Nodes, b: np.ndarray, d: np.ndarray | None = None) -> float:
    """The schedule's duration: b (M,) at the nodes, with slopes d (M,) there (the three-point
    differences of b when None)."""
    total = float(_cell_times(nodes, b, nodes.slopes @ b if d is None else d).sum())
    return total if math.isfinite(total) else math.inf


def _arc_at(nodes: _Nodes, b: np.ndarray, d: np.ndarray, t_node: np.ndarray,
            cell_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """s (N,) at times t (N,) of the schedule: closed form in a rest cell, Newton on the
    Gauss-Legendre time in a Hermite cell."""
    h, rest, s = nodes.h_mm, nodes.rest, nodes.s_mm
    cell = np.clip(np.searchsorted(t_node, t, side="right") - 1, 0, h.size - 1)
    tau = np.clip(t - t_node[cell], 0.0, cell_t[cell])
    out = np.empty(t.size)
    from_rest, to_rest = rest[cell], rest[cell + 1]
    out[from_rest] = s[cell[from_rest]] + h[cell[from_rest]] * (
        tau[from_rest] / cell_t[cell[from_rest]]) ** 3
    out[to_rest] = s[cell[to_rest] + 1] - h[cell[to_rest]] * (
        1.0 - tau[to_rest] / cell_t[cell[to_rest]]) ** 3
    inner = ~from_rest & ~to_rest
    c, want = cell[inner], tau[inner]
    x = want / cell_t[c]
    # a sample Newton has brought to its fixed point (a step that no longer moves it) stays
    # there: only the others step again
    live = np.arange(x.size)
    for _ in range(NEWTON_STEPS):
        cl, xl = c[live], x[live]
        q = (xl[:, None] / 2) * (_GL_X[None, :] + 1)
        inside = _hermite_b(nodes, b, d, np.repeat(cl, _GL_X.size), q.ravel()).reshape(q.shape)
        have = h[cl] * xl / 2 * (1.0 / np.sqrt(np.maximum(inside, 1e-300)) @ _GL_W)
        speed = np.sqrt(np.maximum(_hermite_b(nodes, b, d, cl, xl), 1e-300)) / h[cl]
        stepped = np.clip(xl - (have - want[live]) * speed, 0.0, 1.0)
        x[live] = stepped
        live = live[stepped != xl]
        if live.size == 0:
            break
    out[inner] = s[c] + x * h[c]
    return out


def schedule_law(nodes: _Nodes, b: np.ndarray, period_s: float, slowdown: float = 1.0,
                 d: np.ndarray | None = None) -> TimeLaw:
    """The time law of the schedule b (M,) with slopes d (M,) at the nodes (the three-point
    differences of b when None), each stretch between rests slowed by `slowdown` and stretched
    to whole periods (module docstring). Key times: the rests'."""
    from scipy.interpolate import PPoly, make_interp_spline

    if d is None:
        d = nodes.slopes @ b
    cell_t = _cell_times(nodes, b, d)
    t_node = np.concatenate([[0.0], np.cumsum(cell_t)])
    rests = np.flatnonzero(nodes.rest)
    pieces: list[list[np.ndarray]] = [[] for _ in range(5)]
    key_t = [0.0]
    for first, last in zip(rests[:-1], rests[1:]):
        duration = t_node[last] - t_node[first]
        periods = max(2, math.ceil(duration * slowdown / period_s * (1.0 - 1e-12)))
        step = period_s / SAMPLES_PER_PERIOD
        t = np.arange(periods * SAMPLES_PER_PERIOD + 1) * step
        s = _arc_at(nodes, b, d, t_node, cell_t, t_node[first] + t * duration / t[-1])
        s[0], s[-1] = nodes.s_mm[first], nodes.s_mm[last]
        # v = a = 0 at both ends: two knots more than the samples ask, half a step inside
        inner = np.concatenate([[step / 2], t[1:-1], [t[-1] - step / 2]])
        knots = np.concatenate([[0.0] * 4, inner, [t[-1]] * 4])
        spline = make_interp_spline(t, s, k=3, t=knots,
                                    bc_type=([(1, 0.0), (2, 0.0)], [(1, 0.0), (2, 0.0)]))
        poly = PPoly.from_spline(spline)
        real = np.diff(poly.x) > 0.0
        start = key_t[-1]
        for out, value in zip(pieces, (start + poly.x[:-1][real], poly.c[3][real],
                                       poly.c[2][real], 2.0 * poly.c[1][real],
                                       6.0 * poly.c[0][real])):
            out.append(value)
        key_t.append(start + t[-1])
    times = np.array(key_t)
    t0, s0, v0, a0, jk = (np.concatenate(p) for p in pieces)
    return TimeLaw.from_pieces(t0, s0, v0, a0, jk, times, float(times[-1]))


def _refined(curve: NurbsCurve, grid: Grid, nodes: _Nodes, b: np.ndarray,
             period_s: float, d: np.ndarray | None = None) -> tuple[_Nodes, np.ndarray] | None:
    """Cells lasting longer than REFINE_PERIODS periods cut into pieces that do not, and b
    interpolated on the new nodes; None if none does. d: the slopes at the nodes (the
    three-point differences of b when None)."""
    cell_t = _cell_times(nodes, b, nodes.slopes @ b if d is None else d)
    long = (cell_t > REFINE_PERIODS * period_s) & ~nodes.rest[:-1] & ~nodes.rest[1:]
    long &= np.isfinite(cell_t)
    if not long.any():
        return None
    parts = np.ceil(cell_t[long] / (REFINE_PERIODS * period_s)).astype(np.int64)
    if nodes.s_mm.size + int(parts.sum()) > MAX_NODES:
        return None
    s, h = nodes.s_mm, nodes.h_mm
    more = np.concatenate([s[i] + h[i] * np.arange(1, n) / n
                           for i, n in zip(np.flatnonzero(long), parts)])
    s_all = np.concatenate([s, more])
    order = np.argsort(s_all, kind="stable")
    u = np.concatenate([nodes.u, arc_parameters(curve, grid, more)])[order]
    rest = np.concatenate([nodes.rest, np.zeros(more.size, dtype=bool)])[order]
    b_all = np.concatenate([b, np.interp(more, s, b)])[order]
    s_all = s_all[order]
    return _Nodes(s_all, u, rest), b_all


def _cell_ratios(curve: NurbsCurve, grid: Grid, nodes: _Nodes, law: TimeLaw,
                 lim: Limits) -> tuple[float, np.ndarray]:
    """The law's largest motion ratio (at least 1), and per cell (M-1,) the largest of the
    samples inside it (`path_check.law_ratios`)."""
    worst = 1.0
    per_cell = np.zeros(nodes.h_mm.size)
    for s_mm, ratio, _ in law_ratios(curve, grid, law, lim):
        worst = max(worst, float(ratio.max(initial=0.0)))
        cell = np.clip(np.searchsorted(nodes.s_mm, s_mm, side="right") - 1, 0,
                       per_cell.size - 1)
        np.maximum.at(per_cell, cell, ratio)
    return worst, per_cell


@dataclass(frozen=True, eq=False)
class Schedule:
    """What the optimiser found: the law (whole periods per stretch, the slowdown applied),
    the slowdown (>= 1) and the rounds it took."""

    law: TimeLaw
    slowdown: float
    rounds: int
    rest_nodes: np.ndarray  # (K,) the grid nodes it rests at, one per key time of the law


def schedule_nodes(curve: NurbsCurve, grid: Grid, lim: Limits, rest_nodes: np.ndarray,
                   v_limit: np.ndarray | None = None) -> tuple[np.ndarray, _Nodes] | None:
    """The rests (the grid nodes rest_nodes (R,), those closer than the nodes' merging distance
    taken as one: a stretch of no length) and a schedule's nodes on the grid (`_nodes`, v_limit
    (M,) a speed no motion exceeds at the grid's nodes); None
    on a curve of no length, a grid above MAX_NODES, or where a rest merged into another
    (which the merging here prevents)."""
    if grid.u.size > MAX_NODES or grid.length_mm <= 0.0:
        return None
    floor = MIN_CELL_REL * float(grid.s_mm[-1])
    rest_nodes = rest_nodes[np.concatenate([[True], np.diff(grid.s_mm[rest_nodes]) >= floor])]
    rest_nodes[-1] = grid.u.size - 1
    rest = np.zeros(grid.u.size, dtype=bool)
    rest[rest_nodes] = True
    nodes = _nodes(curve, grid, lim, np.asarray(grid.s_mm, dtype=float), np.asarray(grid.u),
                   rest, v_limit)
    if int(nodes.rest.sum()) != rest_nodes.size:
        return None
    return rest_nodes, nodes


def optimal_schedule(curve: NurbsCurve, grid: Grid, lim: Limits, rest_nodes: np.ndarray,
                     v_start: np.ndarray, feed_at_u: Callable[[np.ndarray], np.ndarray]
                     ) -> Schedule | None:
    """The schedule of `curve` under `lim` (path model), starting from speeds v_start (M,) at the
    grid's nodes (the base plan's, slowed as it runs), resting at grid nodes rest_nodes (R,):
    the ends, corners and cusps. feed_at_u: parameters (N,) -> programmed feed (N,). None
    where the optimiser cannot help (module docstring)."""
    made = schedule_nodes(curve, grid, lim, rest_nodes)
    if made is None:
        return None
    rest_nodes, nodes = made
    b = np.interp(nodes.s_mm, grid.s_mm, v_start) ** 2
    b[nodes.rest] = 0.0
    scale = np.ones(nodes.h_mm.size)
    for _ in range(REFINE_ROUNDS + 1):
        improved = _Problem(curve, grid, lim, nodes, feed_at_u, scale).improve(b)
        if improved is None or not math.isfinite(cycle_s(nodes, improved)):
            return None  # (b = 0 inside a cell: a motion that never arrives)
        b = improved
        refined = _refined(curve, grid, nodes, b, lim.period_s)
        if refined is None:
            break
        nodes, b = refined
        scale = np.ones(nodes.h_mm.size)
    law = schedule_law(nodes, b, lim.period_s)
    excess, per_cell = _cell_ratios(curve, grid, nodes, law, lim)
    best = (law.duration_s * excess, b, excess)
    rounds = 0
    for rounds in range(1, FIX_ROUNDS + 1):
        if excess <= 1.0 + FIX_REL:
            rounds -= 1
            break
        near = per_cell.copy()
        near[1:] = np.maximum(near[1:], per_cell[:-1])
        near[:-1] = np.maximum(near[:-1], per_cell[1:])
        scale = scale / np.maximum(near, 1.0)
        improved = _Problem(curve, grid, lim, nodes, feed_at_u, scale).improve(b)
        if improved is None or not math.isfinite(cycle_s(nodes, improved)):
            break
        b = improved
        law = schedule_law(nodes, b, lim.period_s)
        excess, per_cell = _cell_ratios(curve, grid, nodes, law, lim)
        if law.duration_s * excess < best[0]:
            best = (law.duration_s * excess, b, excess)
    _, b, excess = best
    law = schedule_law(nodes, b, lim.period_s, excess)
    if not np.all(np.isfinite(law.jerk_mm_s3)) or not math.isfinite(law.duration_s):
        return None
    return Schedule(law, excess, rounds, rest_nodes)
