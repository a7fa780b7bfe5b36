"""The reference schedule's method (analysis.bound): sequential linear programming over the grid's
b and b', scipy's HiGHS solving each LP (`jerk_limited_schedule`, what `plan --reference` calls).
The only module of analysis.bound that imports scipy: the command line imports it to learn
whether the `reference` extra is installed.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from nurbsfeed.analysis.bound.constraints import constraint_points, families, worst_ratios
from nurbsfeed.analysis.bound.grid import build_grid
from nurbsfeed.analysis.bound.schedule import BoundSchedule, cell_times
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.limits import Limits

MAX_ITERATIONS = 40  # of the first phase
CONVERGED_REL = 2e-5  # a convex-concave step gaining less than this (relative): converged
# HiGHS's choice first; where it ends in an unknown status (the figure-eight under the default
# profile: "model_status is Unknown"), its interior point, then its dual simplex
LP_METHODS = ("highs", "highs-ipm", "highs-ds")
TRUST_START, TRUST_SWITCH, TRUST_MAX = 0.5, 0.2, 4.0
MAX_TANGENT_ITERATIONS = 4  # how far b may grow, relative to itself
START_SHARE = 0.25  # of the acceleration-limited b: the first linearisation point
FLOOR_SHARE = 1e-8  # of feed^2: the smallest b a linearisation point takes


def _acc_limited(cap: np.ndarray, h: np.ndarray, acc: float) -> np.ndarray:
    """b at the nodes under the speed caps and |a| <= A alone (two passes): the start of the
    iteration, scaled down."""
    b = cap**2
    for i in range(1, b.size):
        b[i] = min(b[i], b[i - 1] + 2 * acc * h[i - 1])
    for i in range(b.size - 2, -1, -1):
        b[i] = min(b[i], b[i + 1] + 2 * acc * h[i])
    return b


def jerk_limited_schedule(curve: NurbsCurve, limits: Limits,
                          feed_u: np.ndarray | None = None, feed_mm_s: np.ndarray | None = None
                          ) -> BoundSchedule:
    """The jerk-limited time-optimal schedule of `curve` from rest to rest (module docstring),
    under `limits` and its jerk model.

    feed_u / feed_mm_s: a programmed feed, a step function of the curve's u (as
    `CurveBlock.feed_u`), capping v beside limits.feed_mm_s.
    """
    feed_u = np.empty(0) if feed_u is None else np.asarray(feed_u, dtype=float)
    feed_mm_s = np.empty(0) if feed_mm_s is None else np.asarray(feed_mm_s, dtype=float)
    grid = build_grid(curve, limits, feed_u)
    pts = constraint_points(grid, limits, feed_u, feed_mm_s)
    fams, normal = families(limits, pts.geo, pts.jump)
    m = grid.u.size
    h = np.diff(grid.s_mm)
    rest_left, rest_right = grid.rest[:-1], grid.rest[1:]

    # equalities: a quadratic cell's b1 - b0 - h (d0 + d1) / 2 = 0; a rest cell's far slope
    # +-(4/3) b_far / h
    rows = np.arange(m - 1)
    eq = sp.coo_matrix(
        (np.concatenate([-np.ones(m - 1), np.ones(m - 1), -h / 2, -h / 2]),
         (np.tile(rows, 4), np.concatenate([rows, rows + 1, m + rows, m + rows + 1]))),
        shape=(m - 1, 2 * m)).tocsr()
    quadratic = ~(rest_left | rest_right)
    eq_rest_left = sp.coo_matrix(
        (np.concatenate([np.ones(rest_left.sum()), -4 / 3 / h[rest_left]]),
         (np.tile(np.arange(rest_left.sum()), 2),
          np.concatenate([m + rows[rest_left] + 1, rows[rest_left] + 1]))),
        shape=(int(rest_left.sum()), 2 * m))
    eq_rest_right = sp.coo_matrix(
        (np.concatenate([np.ones(rest_right.sum()), 4 / 3 / h[rest_right]]),
         (np.tile(np.arange(rest_right.sum()), 2),
          np.concatenate([m + rows[rest_right], rows[rest_right]]))),
        shape=(int(rest_right.sum()), 2 * m))
    a_eq = sp.vstack([eq[quadratic], eq_rest_left, eq_rest_right]).tocsr()
    b_eq = np.zeros(a_eq.shape[0])

    node_cap = np.zeros(m)
    start = pts.sigma_mm == 0
    node_cap[:] = np.inf
    np.minimum.at(node_cap, pts.cell[start], pts.speed_cap_mm_s[start])
    end = pts.sigma_mm == h[pts.cell]
    np.minimum.at(node_cap, pts.cell[end] + 1, pts.speed_cap_mm_s[end])
    node_cap[grid.rest] = 0.0
    node_cap = np.where(np.isfinite(node_cap), node_cap, limits.feed_mm_s)

    n_pts = pts.cell.size
    point_rows = np.repeat(np.arange(n_pts), 3)

    def rows_of(coef: np.ndarray, scale: np.ndarray) -> sp.csr_matrix:
        return sp.coo_matrix(((coef * scale[:, None]).ravel(), (point_rows, pts.cols.ravel())),
                             shape=(n_pts, 2 * m)).tocsr()

    weight = np.zeros(m)
    weight[:-1] += h / 2
    weight[1:] += h / 2
    d_cap = np.where(grid.rest, 0.0, 2 * limits.acc_mm_s2)
    # the linear rows that do not depend on the iterate: speed caps at every point, b >= 0,
    # per-axis accelerations
    fixed_rows = [rows_of(pts.b, np.ones(n_pts)), rows_of(pts.b, -np.ones(n_pts))]
    fixed_rhs = [pts.speed_cap_mm_s**2, np.zeros(n_pts)]
    jerk_coefs = []
    for fam in fams:
        coef = (fam.coef_b[:, None] * pts.b + fam.coef_d[:, None] * pts.d
                + fam.coef_dd[:, None] * pts.dd)
        signs = (1.0,) if fam.name == "normal jerk polygon" else (1.0, -1.0)
        for sign in signs:
            if fam.power == 2:
                fixed_rows.append(rows_of(coef, sign * np.ones(n_pts)))
                fixed_rhs.append(np.full(n_pts, fam.limit))
            else:
                jump = np.zeros(n_pts) if fam.jump is None else fam.jump
                jerk_coefs.append((sign * coef, fam.limit, jump))

    def solve(slowness: np.ndarray, a_ub: sp.csr_matrix, b_ub: np.ndarray, high: np.ndarray
              ) -> tuple[np.ndarray, float, float]:
        """One LP: maximise the slowness-weighted b under the rows, b <= high; the solution,
        the time scaling lambda that makes it feasible and its scaled cycle."""
        objective = -np.concatenate([slowness / slowness.sum(), np.zeros(m)])
        bounds = np.concatenate([np.stack([np.zeros(m), high], axis=1),
                                 np.stack([-d_cap, d_cap], axis=1)])
        for method in LP_METHODS:
            res = linprog(objective, A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=b_eq, bounds=bounds,
                          method=method)
            if res.status == 0:
                break
        else:
            raise RuntimeError(f"the reference schedule's linear program failed: {res.message}")
        lam = max(1.0, max(worst_ratios(pts, limits, fams, normal, res.x).values()))
        return res.x, lam, lam * _cycle(res.x, h, m, rest_left, rest_right)

    floor_b = FLOOR_SHARE * limits.feed_mm_s**2
    x_best = np.concatenate([START_SHARE * _acc_limited(node_cap.copy(), h, limits.acc_mm_s2),
                             np.zeros(m)])
    best_scaled, best_lambda = math.inf, 1.0
    x_lin = x_best
    trust = TRUST_START
    iterations = 0
    for _ in range(MAX_ITERATIONS):
        iterations += 1
        b_lin = np.maximum(x_lin[:m], floor_b)
        root = np.sqrt(np.maximum(pts.value(pts.b, x_lin), 0.0))
        # (a jump's b |D| / T is linear in b as it is)
        a_ub = sp.vstack(fixed_rows + [rows_of(coef * root[:, None] + jump[:, None] * pts.b,
                                               np.ones(n_pts))
                                       for coef, _, jump in jerk_coefs]).tocsr()
        b_ub = np.concatenate(fixed_rhs + [np.full(n_pts, lim) for _, lim, _ in jerk_coefs])
        # the cycle time sum w / sqrt(b), linearised: a node where b is small weighs in as
        # much as the time it costs
        slowness = weight / b_lin**1.5
        # only growth is bounded: where b falls below the linearisation point, sqrt(b_lin) |L|
        # bounds the true sqrt(b) |L|, and the jerk rows are conservative
        high = np.minimum(node_cap**2, b_lin + trust * np.maximum(b_lin, 1e-3 * node_cap**2))
        x, lam, scaled = solve(slowness, a_ub, b_ub, high)
        if scaled < best_scaled:
            x_best, best_scaled, best_lambda = x, scaled, lam
            x_lin = x
            trust = min(trust * 1.5, TRUST_MAX)
        else:
            # the step went too far for the linearisation: back to the best, a smaller step
            x_lin = x_best
            trust /= 2
            if trust < TRUST_SWITCH:
                break
    # phase 2, from the best iterate made feasible: L <= J / sqrt(b), whose right side is
    # convex in b, so its tangent at b_lin lies below it and L <= J (3 - b / b_lin) /
    # (2 sqrt(b_lin)) keeps the true constraint (a convex-concave step): every iterate is
    # feasible at the constraint points, each at least as fast as the last, and the tangent is
    # exact at the fixed point
    x = x_best / best_lambda**2
    best_scaled = _cycle(x, h, m, rest_left, rest_right)
    x_best, best_lambda = x, 1.0
    for _ in range(MAX_TANGENT_ITERATIONS):
        iterations += 1
        lin_nodes = np.maximum(x[:m], floor_b)
        lin_points = np.maximum(pts.value(pts.b, x), floor_b)
        jerk_rows, bounds = [], []
        for coef, lim, jump in jerk_coefs:
            # L <= J / sqrt(b) - jump sqrt(b), convex in b: its tangent, where a jump is, at b
            # or at the jump's own limit J / jump, the lower (beyond it the tangent cuts 0)
            with np.errstate(divide="ignore"):
                at = np.where(jump > 0.0, np.minimum(lin_points, lim / np.where(
                    jump > 0.0, jump, 1.0)), lin_points)
            root_at = np.sqrt(at)
            slope = 0.5 * lim / (at * root_at) + 0.5 * jump / root_at
            jerk_rows.append(rows_of(coef + slope[:, None] * pts.b, np.ones(n_pts)))
            bounds.append(1.5 * lim / root_at - 0.5 * jump * root_at)
        a_ub = sp.vstack(fixed_rows + jerk_rows)
        b_ub = np.concatenate(fixed_rhs + bounds)
        x, lam, scaled = solve(weight / lin_nodes**1.5, a_ub.tocsr(), b_ub, node_cap**2)
        if scaled < best_scaled:
            gain = best_scaled - scaled
            x_best, best_scaled, best_lambda = x, scaled, lam
            if gain < CONVERGED_REL * scaled:
                break
        else:
            break
    x = x_best.copy()
    x[:m] /= best_lambda**2
    x[m:] /= best_lambda**2
    x[:m] = np.maximum(x[:m], 0.0)
    b, d = x[:m], x[m:]
    times = cell_times(b[:-1], b[1:], d[:-1], d[1:], h, rest_left, rest_right)
    t_nodes = np.concatenate([[0.0], np.cumsum(times)])
    mid = pts.sigma_mm > 0
    mid &= pts.sigma_mm < h[pts.cell]
    jerk_mid = np.zeros(m - 1)
    jerk_mid[pts.cell[mid]] = (np.sqrt(np.maximum(pts.value(pts.b, x), 0)) * 0.5
                               * pts.value(pts.dd, x))[mid]
    return BoundSchedule(curve, limits, float(t_nodes[-1]), grid.u, grid.s_mm, np.sqrt(b), d / 2,
                         jerk_mid, t_nodes, grid.rest, best_lambda, iterations,
                         worst_ratios(pts, limits, fams, normal, x))


def _cycle(x: np.ndarray, h: np.ndarray, m: int, rest_left: np.ndarray, rest_right: np.ndarray
           ) -> float:
    b, d = np.maximum(x[:m], 0.0), x[m:]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cell_times(b[:-1], b[1:], d[:-1], d[1:], h, rest_left, rest_right)
    return float(np.sum(t)) if np.all(np.isfinite(t)) else math.inf
