"""The path planner's schedule (`planner: optimal`, design §2e): the greatest b = v^2 the path
model's limits allow, found by a short sequence of linear programs.

Variables: the spline's coefficients (planning.cells). Each program maximises the schedule's
speed (the cycle time's linearisation, sum w_k c_k with w_k = -dT/dc_k at the last schedule)
under the rows of planning.rows, linearised at the last schedule. The rows keep the true
limits for every b (their J / sqrt(b) is a tangent below it), so every program's solution is
a schedule that keeps every limit at every cell's points, and each is at least as fast as the
last: it stops when one gains less than CONVERGED_REL. The programs are banded (a row spans
three consecutive coefficients) and solved by planning.banded_lp in O(rows) an iteration.

Only the rows that are near binding go into a program after the first: those whose left side
reaches KEEP_SHARE of their bound at the linearisation point (the last solution); after a solve
every row is evaluated at the solution, and the program is solved again with those it breaks
and their neighbours' (a cutting plane), at most CUT_ROUNDS times. What the last schedule still
breaks at the cells' points (nothing, or rounding) is taken back by a uniform slowdown
(`Schedule.slowdown`): every limit scales with a power of it; where it breaks a limit between
them, path_plan cuts those cells and plans again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.banded_lp import solve_lp
from nurbsfeed.planning.basis import (
    BETWEEN,
    G_CAP,
    G_D,
    G_K,
    G_KAPPA,
    G_KS,
    G_T,
    POINTS,
    point_weights,
)
from nurbsfeed.planning.cells import Layout
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.rows import ROWS_PER_POINT, all_rows, cell_ratios

MAX_PROGRAMS = 8
# a program shortening the cycle by less than this share is the last: the next would gain
# at most a sixth of it (measured on the benchmark curves: 0.002-0.15 of the one before)
CONVERGED_REL = 1e-2
KEEP_SHARE = 0.5  # a row whose left side is at least this share of its bound joins a program
CUT_ROUNDS = 8
# a row broken by more than this share of its bound is cut in (beyond the solver's tolerance,
# banded_lp.TOL_FEAS, and the rounding of its terms)
BROKEN_REL = 1e-6
ROUNDING_REL = 1e-12
CUT_REACH = 3  # ... with the rows of this many coefficients on either side
# a cell whose schedule breaks a limit between its points by more than this share (of the
# speed: a third of it in a jerk) is cut and the curve planned again (path_plan.RECUTS)
BETWEEN_REL = 1e-3
SCALE_FLOOR = 1e-9  # of the largest cap: the least scale a variable takes
GAUSS_X, GAUSS_W = np.polynomial.legendre.leggauss(8)


@dataclass(frozen=True, eq=False)
class Schedule:
    """The planned spline: its coefficients c (C,) on the layout, the cycle they take (s,
    before whole periods), the uniform slowdown (>= 1) the last check asked for, the
    programs solved, whether one was (if not, c is the start, slowed), and the inner cells
    (Q,) in which c breaks a limit by more than BETWEEN_REL between the points the programs
    read (at cells.BETWEEN)."""

    layout: Layout
    c: np.ndarray
    cycle_s: float
    slowdown: float
    programs: int
    solved: bool
    broken_between: np.ndarray


@jit
def static_b(geo, lim_t, jerk_n, acc_x, jerk_x, period, out):
    """Per cell point (Q, 3): b at which every limit holds with b' = b'' = 0 (a start for the
    first program's linearisation): kappa^2 b^1.5 <= J_t, |K_s + kappa^2 T| b^1.5 <= J_n, per
    axis |K_x| b <= A_x and |K_s,x| b^1.5 <= J_x, the cap, and where kappa N jumps by D, half
    of what the jump alone allows (b |D| / T <= J / 2: the rest of the jerk is the curve's)."""
    for q in range(geo.shape[0]):
        for p in range(3):
            g = geo[q, p]
            k = g[G_KAPPA]
            b = g[G_CAP]
            if k > 0.0:
                b = min(b, (lim_t / (k * k)) ** (2.0 / 3.0))
            nx = g[G_KS] + k * k * g[G_T]
            ny = g[G_KS + 1] + k * k * g[G_T + 1]
            nz = g[G_KS + 2] + k * k * g[G_T + 2]
            n = math.sqrt(nx * nx + ny * ny + nz * nz)
            if n > 0.0:
                b = min(b, (jerk_n / n) ** (2.0 / 3.0))
            for x in range(3):
                kx = abs(g[G_K + x])
                if kx > 0.0 and acc_x[x] < np.inf:
                    b = min(b, acc_x[x] / kx)
                kx = abs(g[G_KS + x])
                if kx > 0.0 and jerk_x[x] < np.inf:
                    b = min(b, (jerk_x[x] / kx) ** (2.0 / 3.0))
                if g[G_D + x] != 0.0 and jerk_x[x] < np.inf:
                    b = min(b, 0.5 * jerk_x[x] * period / abs(g[G_D + x]))
            jump = math.sqrt(g[G_D] ** 2 + g[G_D + 1] ** 2 + g[G_D + 2] ** 2)
            if jump > 0.0:
                b = min(b, 0.5 * jerk_n * period / jump)
            out[q, p] = b


@jit
def cell_times(c, cells, first, last, rest_h, times):
    """Each inner cell's duration (Q,) by Gauss-Legendre on 1 / sqrt(b) (inf where b reaches 0
    inside), and the rest cells' 3 h / sqrt(b_far) (S, 2) into times[Q:]. Returns the sum."""
    q_n = cells.shape[0]
    total = 0.0
    w = np.empty((3, 3))
    for q in range(q_n):
        i0 = int(cells[q, 0])
        h = cells[q, 4]
        t = 0.0
        for g in range(GAUSS_X.size):
            x = 0.5 * (GAUSS_X[g] + 1.0)
            point_weights(cells[q, 1], cells[q, 2], cells[q, 3], h, x, w)
            b = w[0, 0] * c[i0] + w[0, 1] * c[i0 + 1] + w[0, 2] * c[i0 + 2]
            if not b > 0.0:
                t = np.inf
                break
            t += GAUSS_W[g] / math.sqrt(b)
        t *= 0.5 * h
        times[q] = t
        total += t
    for s in range(first.size):
        for side in range(2):
            b = c[first[s]] if side == 0 else c[last[s]]
            t = 3.0 * rest_h[s, side] / math.sqrt(b) if b > 0.0 else np.inf
            times[q_n + 2 * s + side] = t
            total += t
    return total


@jit
def _time_weights(c, cells, first, last, rest_h, ratio, w_out):
    """-dT/dc (C,) at c: each inner cell's time h / sqrt(b_mid) and the rest cells' 3 h /
    sqrt(c_end), differentiated (the rest ends folded onto the coefficient after them)."""
    for i in range(w_out.size):
        w_out[i] = 0.0
    w = np.empty((3, 3))
    for q in range(cells.shape[0]):
        i0 = int(cells[q, 0])
        h = cells[q, 4]
        point_weights(cells[q, 1], cells[q, 2], cells[q, 3], h, 0.5, w)
        b = max(w[0, 0] * c[i0] + w[0, 1] * c[i0 + 1] + w[0, 2] * c[i0 + 2], 1e-12)
        g = 0.5 * h * b ** -1.5
        for j in range(3):
            w_out[i0 + j] += g * w[0, j]
    for s in range(first.size):
        for side in range(2):
            k = first[s] if side == 0 else last[s]
            w_out[k] += 1.5 * rest_h[s, side] * max(c[k], 1e-12) ** -1.5


def _fold_rests(layout: Layout, idx: np.ndarray, val: np.ndarray) -> None:
    """Rows over a stretch's end coefficient rewritten over the one beside it: the rest cell's
    C1 join makes c_end = c_inner / ratio (so that a row keeps three consecutive variables)."""
    for s in range(layout.first.size):
        for side, (end, inner, ratio) in enumerate((
                (layout.first[s], layout.first[s] + 1, layout.rest_ratio[s, 0]),
                (layout.last[s], layout.last[s] - 1, layout.rest_ratio[s, 1]))):
            if layout.is_open(s, side):
                continue
            rows = np.flatnonzero((idx <= end) & (idx + 2 >= end))
            je, ji = end - idx[rows], inner - idx[rows]
            val[rows, ji] += val[rows, je] / ratio
            val[rows, je] = 0.0


def _fix_ends(layout: Layout, idx: np.ndarray, val: np.ndarray, rhs: np.ndarray,
              slack: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """The rows with the coefficients a moving end fixes (`Layout.fixed`) moved to their right
    side, and those left without a variable dropped; also whether the fixed state itself
    breaks one of those by more than BETWEEN_REL of its bound (it is the state the chain
    starts or ends in: a schedule cannot change it). slack (share, mm): the rows within that
    distance of a moving start loosened by that share of their bound (`plan_schedule`)."""
    fixed, values = layout.fixed_index, layout.fixed_values
    if fixed.size == 0:
        return idx, val, rhs, False
    rhs = rhs.copy()
    bound = np.abs(rhs)
    if layout.moving[0] and slack[0] > 0.0:
        near = layout.xi[idx] <= layout.xi[0] + slack[1]
        rhs[near] += slack[0] * bound[near]
    for k, value in zip(fixed, values):
        rows = np.flatnonzero((idx <= k) & (idx + 2 >= k))
        j = k - idx[rows]
        rhs[rows] -= val[rows, j] * value
        val[rows, j] = 0.0
    empty = ~np.any(val != 0.0, axis=1)
    broken = bool(np.any(rhs[empty] < -BETWEEN_REL * bound[empty]))
    keep = ~empty
    return idx[keep], val[keep], rhs[keep], broken


def plan_schedule(layout: Layout, lim: Limits, start: np.ndarray | None = None,
                  seed: tuple[np.ndarray, np.ndarray] | None = None,
                  slack: tuple[float, float] = (0.0, 0.0)) -> Schedule:
    """The schedule on `layout` under `lim` (module docstring); start: coefficients (C,) to
    linearise the first program at (by default, each limit's value at b' = b'' = 0, and where
    a seed (xi (K,), c (K,)) covers the coefficients, its: the schedule a moving end's state
    comes from, whose rows hold there at its own point). slack (share, mm): every limit within
    that distance of a moving start loosened by that share (of an acceleration or a jerk), for
    a start in a state the limits there leave no way on from (planning.path_plan)."""
    acc_x = np.array(lim.axis_acc_mm_s2, dtype=float)
    vel_x = np.array(lim.axis_vel_mm_s, dtype=float)
    jerk_x = np.array(lim.axis_jerk_mm_s3, dtype=float)
    cells, geo = layout.cells, layout.geo
    n = layout.n_coefficients
    q_n = cells.shape[0]
    # each variable's size, for the solver's scaling: the speed estimate's b (no schedule is
    # faster), floored where it reaches 0 beside a rest
    scale = np.maximum(np.minimum(layout.b_estimate, layout.cap),
                       SCALE_FLOOR * float(layout.cap.max(initial=1.0)))
    if start is None:
        sb = np.empty((q_n, 3))
        static_b(geo, lim.jerk_mm_s3, lim.normal_jerk_mm_s3, acc_x, jerk_x, lim.period_s, sb)
        start = np.full(n, np.inf)
        i0 = cells[:, 0].astype(np.int64)
        for j in range(3):
            np.minimum.at(start, i0 + j, sb.min(axis=1))
        start = np.minimum(start, layout.b_estimate)
        _moving_start(layout, lim, start)
        if seed is not None:
            span = 1e-9 * max(float(layout.xi[-1]), 1.0)
            inside = (layout.xi >= seed[0][0] - span) & (layout.xi <= seed[0][-1] + span)
            start[inside] = np.interp(layout.xi[inside], *seed)
        _join_rests(layout, start)
    # the box: the caps, with each end folded onto the coefficient beside it
    upper = layout.cap.copy()
    for s in range(layout.first.size):
        f, e = layout.first[s], layout.last[s]
        if not layout.is_open(s, 0):
            upper[f + 1] = min(upper[f + 1], upper[f] * layout.rest_ratio[s, 0])
        if not layout.is_open(s, 1):
            upper[e - 1] = min(upper[e - 1], upper[e] * layout.rest_ratio[s, 1])
        upper[f] = upper[e] = 0.0
    upper[layout.fixed_index] = 0.0  # (the programs see them on their rows' right side)
    size = q_n * 3 * ROWS_PER_POINT
    idx, val, rhs = np.empty(size, dtype=np.int64), np.empty((size, 3)), np.empty(size)
    times = np.empty(q_n + 2 * layout.first.size)
    weights = np.empty(n)
    hist = np.empty((0, 5))  # (the solver's iteration record: not kept)
    c = start.copy()
    c[layout.fixed_index] = layout.fixed_values
    best_c, best_t = None, math.inf
    programs = 0
    for programs in range(1, MAX_PROGRAMS + 1):
        r = all_rows(c, cells, geo, lim.jerk_mm_s3, lim.acc_mm_s2, lim.normal_jerk_mm_s3, acc_x,
                     jerk_x, lim.period_s, idx, val, rhs)
        ri, rv, rr = idx[:r].copy(), val[:r].copy(), rhs[:r].copy()
        _fold_rests(layout, ri, rv)
        ri, rv, rr, state_breaks = _fix_ends(layout, ri, rv, rr, slack)
        if state_breaks:
            break
        r = ri.size
        _time_weights(c, cells, layout.first, layout.last, layout.rest_h, layout.rest_ratio,
                      weights)
        for s in range(layout.first.size):
            f, e = layout.first[s], layout.last[s]
            if not layout.is_open(s, 0):
                weights[f + 1] += weights[f] / layout.rest_ratio[s, 0]
            if not layout.is_open(s, 1):
                weights[e - 1] += weights[e] / layout.rest_ratio[s, 1]
            weights[f] = weights[e] = 0.0
        weights[layout.fixed_index] = 0.0
        objective = -weights / max(float(weights.max()), 1e-300)
        x_lin = np.minimum(c, upper)
        left = np.einsum("rj,rj->r", rv, x_lin[ri[:, None] + np.arange(3)])
        # the first program's linearisation point (no motion's: its slopes are 0) says nothing
        # of which rows bind: it takes them all
        keep = left >= KEEP_SHARE * rr if programs > 1 else np.ones(r, dtype=bool)
        x = x_lin
        status = 0
        broken = np.zeros(r, dtype=bool)
        for _ in range(CUT_ROUNDS + 1):
            sel = np.flatnonzero(keep)
            x, status = solve_lp(n, ri[sel], rv[sel], rr[sel], objective, upper, scale, x_lin,
                                 hist)
            if status != 0:
                break
            terms = rv * x[ri[:, None] + np.arange(3)]
            left = terms.sum(axis=1)
            broken = left - rr > (BROKEN_REL * np.abs(rr)
                                  + ROUNDING_REL * np.abs(terms).sum(axis=1))
            if not broken.any():
                break
            # the rows of the coefficients around each broken one join (a broken row's
            # neighbours are the next to break)
            near = np.zeros(n + 3, dtype=bool)
            for shift in range(-CUT_REACH, CUT_REACH + 1):
                near[np.clip(ri[broken] + shift, 0, n + 2)] = True
            keep |= near[ri]
        if status != 0 or broken.any():
            break  # (the last schedule stands: it keeps every row)
        _join_rests(layout, x)
        t = cell_times(x, cells, layout.first, layout.last, layout.rest_h, times)
        if not t < best_t:
            break
        gain = (best_t - t) / t if math.isfinite(best_t) else math.inf
        best_c, best_t = x, t
        c = x
        if gain < CONVERGED_REL:
            break
    solved = best_c is not None
    if best_c is None:  # no program solved: the start itself, slowed until it keeps the limits
        best_c = np.minimum(start, layout.cap)
        best_t = cell_times(best_c, cells, layout.first, layout.last, layout.rest_h, times)
    ratios = np.empty(q_n)
    cell_ratios(best_c, cells, geo, np.array(POINTS), lim.jerk_mm_s3, lim.acc_mm_s2,
                lim.normal_jerk_mm_s3, acc_x, vel_x, jerk_x, lim.period_s, ratios)
    _open_end_ratios(layout, lim, best_c, ratios)
    between = np.empty(q_n)
    cell_ratios(best_c, cells, layout.between, np.array(BETWEEN), lim.jerk_mm_s3, lim.acc_mm_s2,
                lim.normal_jerk_mm_s3, acc_x, vel_x, jerk_x, lim.period_s, between)
    if layout.moving[0] and slack[0] > 0.0:
        # what the slack allows is no slowdown: an acceleration's share is the square of one
        near = layout.xi[cells[:, 0].astype(np.int64)] <= layout.xi[0] + slack[1]
        for r in (ratios, between):
            r[near] /= (1.0 + slack[0]) ** 0.5
    slowdown = max(1.0, float(ratios.max(initial=0.0)))
    best_c.setflags(write=False)
    return Schedule(layout, best_c, float(best_t), slowdown, programs, solved,
                    between > 1.0 + BETWEEN_REL)


def _moving_start(layout: Layout, lim: Limits, start: np.ndarray) -> None:
    """The first program's linearisation point near a moving end: the speed estimate (no
    schedule is faster). The jerk rows' tangents are taken at it, and one taken below a third
    of the b a schedule must have there asks more than the limit allows (J (3/2 - b / (2 b0)) /
    sqrt(b0) reaches 0 at b = 3 b0): near a moving end b stays close to the b it fixes for as
    long as the jerk and acceleration limits take to change it, v (v / A + A / J) (twice that
    reach is taken)."""
    for side in range(2):
        if not layout.moving[side]:
            continue
        b_end = layout.fixed[side, 1 - side]
        v = math.sqrt(b_end)
        reach = 2.0 * v * (v / lim.acc_mm_s2 + lim.acc_mm_s2 / lim.jerk_mm_s3)
        x_end = layout.xi[0] if side == 0 else layout.xi[-1]
        near = np.abs(layout.xi - x_end) <= reach
        start[near] = np.minimum(layout.b_estimate[near], layout.cap[near])


def _open_end_ratios(layout: Layout, lim: Limits, c: np.ndarray, ratios: np.ndarray) -> None:
    """The ratios of the cells at a moving end read without the end itself: the state there is
    the one the chain was given (what it breaks, within BETWEEN_REL, `_fix_ends`, is not this
    schedule's to take back)."""
    for side, q, points in ((0, 0, (0.5, 1.0)), (1, layout.cells.shape[0] - 1, (0.0, 0.5))):
        if not layout.moving[side]:
            continue
        keep = [1, 2] if side == 0 else [0, 1]
        geo = np.ascontiguousarray(layout.geo[q:q + 1, keep])
        geo.setflags(write=False)  # as the layout's: cell_ratios compiles for one type
        out = np.empty(1)
        cell_ratios(c, layout.cells[q:q + 1], geo, np.array(points), lim.jerk_mm_s3,
                    lim.acc_mm_s2, lim.normal_jerk_mm_s3, np.array(lim.axis_acc_mm_s2, dtype=float),
                    np.array(lim.axis_vel_mm_s, dtype=float),
                    np.array(lim.axis_jerk_mm_s3, dtype=float), lim.period_s, out)
        ratios[q] = out[0]


def _join_rests(layout: Layout, c: np.ndarray) -> None:
    """Each stretch's end coefficients from the ones beside them (the rest cells' C1 join), and
    those a moving end fixes."""
    for s in range(layout.first.size):
        if not layout.is_open(s, 0):
            c[layout.first[s]] = c[layout.first[s] + 1] / layout.rest_ratio[s, 0]
        if not layout.is_open(s, 1):
            c[layout.last[s]] = c[layout.last[s] - 1] / layout.rest_ratio[s, 1]
    c[layout.fixed_index] = layout.fixed_values
