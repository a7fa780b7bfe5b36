"""The schedule's nodes (design §2d): where the cells of planning.cells begin and end along one
curve, the speed estimate that sizes them, and the cuts where a schedule needs finer ones.

Nodes: the planning grid's (samples at most two full-speed steps apart, curvature peaks,
knots where kappa jumps, stops), then beside each rest at h, 2h, 4h ... (h from how fast
constant jerk leaves a rest), then every cell in which the pointwise speed limit would spend
more than CELL_PERIODS periods cut into pieces that do not: no motion is faster than that
limit, so no cell lasts longer.
A chain that starts or ends moving (basis.ChainEnds) has no rest cell at that end and no nodes
beside it but one near enough that the state's slope cannot take b to 0 in the first cell;
where the plan the state comes from overlaps this one, its nodes are this one's there (`seed_s`).
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.jit import jit
from nurbsfeed.planning.basis import AT_REST, ChainEnds
from nurbsfeed.planning.cells import Layout
from nurbsfeed.planning.grid import Grid
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.path_check import arc_parameters

CELL_PERIODS = 4.0  # a cell lasting longer at the speed estimate is cut
RECUT_SLACK = 2.0  # ... and one the schedule spends over this many times as long in, again
MAX_CUT = 64  # pieces a cell is cut into at most in one go
# a grid node closer than this many periods (at the speed estimate, or the jerk's speed through
# the curvature where that is lower) to the last one kept goes
# (curvature maxima, knots, stops and the ends always stay): cells far shorter than a period
# are finer than anything the machine's positions show, they make rows that ask u to follow
# kappa^2 b to a millionth (a 3 um near cusp), and each costs the passes as much as a long one
MIN_CELL_PERIODS = 2.0
# ... unless the curvature across the merged cell changes by more than this factor (kappa
# below kappa_0, where it sets no limit, counts as kappa_0): in a valley the rows must see the
# curvature change to plan its bottom
MERGE_KAPPA_RATIO = 1.25
# ... and where the speed cells are sized at changes by more than this factor across it (the
# motion speeds up or brakes there), nodes stay BRAKE_CELL_PERIODS apart: the jerk-limited motion
# changes its jerk within a few periods there, and the quadratic a longer cell holds cuts
# those corners (the short legs of a 3 mm star, 1.1 % slower with two-period cells)
MERGE_SPEED_RATIO = 1.1
BRAKE_CELL_PERIODS = 1.0
# Where the motion cruises at the programmed feed nothing changes from one node to the next
# (b stays at the feed's, which a quadratic holds exactly): nodes merge up to this many periods
# apart there, and only cells longer than CRUISE_CUT_PERIODS are cut. The speed estimate knows
# no jerk, so a node cruises only where the estimate and the pointwise limit (a = j = 0) are at
# the feed within CRUISE_MARGIN times the distance the feed covers in A / J (what jerk adds to
# a braking) either side: 1 was too close (a LinuxCNC sample 0.6 % slower under
# paper-table1's limits); at 2, the benchmark's curves plan on 13 % fewer cells and every
# sample and dense curve in the same cycle (within 0.05 %)
CRUISE_CELL_PERIODS = 4.0
CRUISE_MARGIN = 2.0
CRUISE_CUT_PERIODS = 8.0
MIN_CELL_REL = 1e-6  # of the curve's length: nodes closer than this are one
MIN_STRETCH_CELLS = 4  # a stretch between rests has at least this many cells
REST_CELL_SHARE = 0.05  # of A^3 / (6 J^2): the first cell beside a rest at most ...
REST_CELLS_PER_STRETCH = 32  # ... and at most this share of half its stretch


def speed_estimate(s_mm: np.ndarray, cap_mm_s: np.ndarray, acc_mm_s2: float,
                   rest: np.ndarray, ends: ChainEnds = AT_REST) -> np.ndarray:
    """The fastest speed (N,) at the points s_mm (N,) under the caps cap_mm_s (N,) and one
    acceleration limit, at rest where rest (N,) but at a moving end (`ends`, its speed): the
    forward and backward passes of time-optimal path parametrisation, b' <= 2 A. No motion
    that keeps the limits is faster (jerk only slows it), which sizes the cells."""
    b = np.where(rest, 0.0, np.minimum(cap_mm_s, 1e300) ** 2)
    for i, state in ((0, ends.start), (-1, ends.end)):
        if state is not None:
            b[i] = state.b
    _topp_passes(b, np.diff(s_mm), 2.0 * acc_mm_s2)
    return np.sqrt(b)


@jit
def _topp_passes(b, h, slope):
    for i in range(1, b.size):
        b[i] = min(b[i], b[i - 1] + slope * h[i - 1])
    for i in range(b.size - 2, -1, -1):
        b[i] = min(b[i], b[i + 1] + slope * h[i])


def _cruising(s_mm: np.ndarray, sizing: np.ndarray, cruise_mm_s: np.ndarray,
              rest: np.ndarray, margin_s: float) -> np.ndarray:
    """Which nodes (N,) cruise (CRUISE_CELL_PERIODS): the speed cells are sized at (N,) is
    the cruise speed (N,; NaN: none) there and at every node within margin_s mm, and no rest
    is."""
    at_feed = (sizing >= cruise_mm_s * (1.0 - 1e-9)) & ~rest
    off = s_mm[~at_feed]
    if off.size == 0:
        return at_feed
    return at_feed & (_distance_to(off, s_mm) > margin_s)


def _distance_to(points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The distance from each of x to the nearest of points (ascending, at least one)."""
    after = np.minimum(np.searchsorted(points, x), points.size - 1)
    before = np.maximum(after - 1, 0)
    return np.minimum(np.abs(x - points[before]), np.abs(points[after] - x))


@jit
def _merge(s_mm, period_mm, kappa, essential, rest, floor, keep, cruise):
    """Which grid nodes stay (keep (N,), all True on entry): the rules of MIN_CELL_PERIODS and
    the two after it, and CRUISE_CELL_PERIODS between two nodes that cruise (N,); period_mm
    (N,): the length of a period at the speed cells are sized at."""
    kept = 0
    lo_k = hi_k = kappa[0]
    lo_v = hi_v = period_mm[0]
    for k in range(1, s_mm.size):
        gap = s_mm[k] - s_mm[kept]
        lo_k, hi_k = min(lo_k, kappa[k]), max(hi_k, kappa[k])
        lo_v, hi_v = min(lo_v, period_mm[k]), max(hi_v, period_mm[k])
        periods = gap / max(min(period_mm[k], period_mm[kept]), 1e-300)
        least = CRUISE_CELL_PERIODS if cruise[k] and cruise[kept] else MIN_CELL_PERIODS
        if gap >= floor and (essential[k] or periods >= least
                             or hi_k > MERGE_KAPPA_RATIO * lo_k
                             or (periods >= BRAKE_CELL_PERIODS
                                 and hi_v > MERGE_SPEED_RATIO * lo_v)):
            kept = k
            lo_k = hi_k = kappa[k]
            lo_v = hi_v = period_mm[k]
        elif (k == s_mm.size - 1 or rest[k]) and kept > 0 and not rest[kept]:
            keep[kept] = False  # a rest and the end stay: the node before them goes
            kept = k
            lo_k = hi_k = kappa[k]
            lo_v = hi_v = period_mm[k]
        else:
            keep[k] = False


def schedule_nodes(curve: NurbsCurve, grid: Grid, lim: Limits, rest_nodes: np.ndarray,
                   cap_mm_s: np.ndarray, kappa_floor: float,
                   keep_u: np.ndarray = np.empty(0), max_nodes: int = 2**62,
                   ends: ChainEnds = AT_REST, seed_s: np.ndarray = np.empty(0),
                   cruise_mm_s: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The nodes (s_mm, u, rest) (M,) of the schedule from the grid's, resting at grid nodes
    rest_nodes (R,) (the ends first and last); cap_mm_s (N,): the speed caps at the grid's
    nodes; kappa_floor: the curvature below which the caps do not depend on it (kappa_0);
    keep_u: parameters whose nodes stay (where the programmed feed changes) (module docstring);
    ends: a moving end has no rest cell, so none of the nodes beside a rest, but one close
    enough that the state's slope cannot take b to 0 within the first cell (`_open_end_nodes`);
    seed_s: nodes (ascending) that replace every node between the first and the last of them
    (the nodes of the plan a moving end's state comes from, where the two overlap);
    cruise_mm_s (N,): the speed the motion may cruise at at the grid's nodes (NaN: none; None:
    no cruise anywhere), CRUISE_CELL_PERIODS.
    Also the speed estimate (M,) at the nodes (`speed_estimate`). None past max_nodes nodes."""
    s_mm, u = np.asarray(grid.s_mm, dtype=float), np.asarray(grid.u, dtype=float)
    rest = np.zeros(s_mm.size, dtype=bool)
    rest[rest_nodes] = True
    acc, jerk = _moving_limits(curve, lim)
    v_limit = speed_estimate(s_mm, np.asarray(cap_mm_s, dtype=float), acc, rest, ends)
    v_limit = np.maximum(v_limit, np.where(rest, 0.0, 1e-300))
    essential = rest.copy()
    essential[grid.peak_index] = True
    essential[np.isin(u, curve.span_breaks)] = True
    essential[np.isin(u, keep_u)] = True
    floor = MIN_CELL_REL * max(float(s_mm[-1]), 1e-300)
    kappa = np.maximum(np.nan_to_num(grid.kappa_1_mm, posinf=1e300), kappa_floor)
    keep = np.ones(s_mm.size, dtype=bool)
    # cells are sized at the speed estimate, but at most at the speed whose pass through the
    # curvature turns the velocity with the jerk limit (|r'''| >= v^3 kappa^2 at constant
    # speed): the estimate knows no jerk, and at a slow tip its periods would be several of
    # the motion's
    kappa_1 = np.minimum(np.nan_to_num(grid.kappa_1_mm, posinf=1e150), 1e150)
    turn = (jerk / np.maximum(kappa_1, 1e-150) ** 2) ** (1.0 / 3.0)
    sizing = np.minimum(np.asarray(v_limit, dtype=float), turn)
    cruise = np.zeros(s_mm.size, dtype=bool)
    if cruise_mm_s is not None and np.isfinite(cruise_mm_s).any():
        feed = float(np.nanmax(cruise_mm_s))
        cruise = _cruising(s_mm, sizing, cruise_mm_s, rest, CRUISE_MARGIN * feed * acc / jerk)
    _merge(s_mm, sizing * lim.period_s, kappa, essential, rest, floor, keep, cruise)
    grid_s, grid_cruise = s_mm, cruise.astype(float)
    s_mm, u, rest, v = s_mm[keep], u[keep], rest[keep], np.asarray(v_limit, dtype=float)[keep]
    rests = np.flatnonzero(rest)
    extra = [np.linspace(s_mm[a], s_mm[b], MIN_STRETCH_CELLS + 1)[1:-1]
             for a, b in zip(rests[:-1], rests[1:]) if b - a < MIN_STRETCH_CELLS]
    first_h = REST_CELL_SHARE * acc**3 / (6.0 * jerk**2)
    doubling = 2.0 ** np.arange(64)
    last_stretch = rests.size - 2
    for stretch, (a, b) in enumerate(zip(rests[:-1], rests[1:])):
        half = (s_mm[b] - s_mm[a]) / 2
        # each end's nodes within its own first interval: where the other end's is short, the
        # long one would keep no node and the profile creep up over all of it
        for at, side, inner in ((a, 1.0, a + 1), (b, -1.0, b - 1)):
            step = abs(s_mm[inner] - s_mm[at])
            state = (ends.start if stretch == 0 and side > 0 else
                     ends.end if stretch == last_stretch and side < 0 else None)
            if state is not None:
                extra.append(_open_end_nodes(s_mm[at], side, step, state, floor))
                continue
            # constant jerk from rest reaches the limit beside it after (2 v)^1.5 / (6 sqrt J)
            reach = (2.0 * v[inner]) ** 1.5 / (6.0 * math.sqrt(jerk))
            near = min(first_h, half / REST_CELLS_PER_STRETCH, reach) * doubling
            near = near[(near < min(half / 2, step)) & (near >= floor)]
            extra.append(s_mm[at] + side * near)
    s_mm, u, rest, v = _insert(curve, grid, s_mm, u, rest, v, extra)
    # a node inserted between two rests with no grid node between them took 0 by interpolation,
    # and its cells would be cut past any count (two cusps 5 um apart, a stretch of its own):
    # there the speed constant jerk reaches from the nearer rest, 0.5 (6 d)^(2/3) J^(1/3), which
    # no motion between the two rests passes
    still = ~rest & ~(v > 0.0)
    if still.any():
        d = _distance_to(s_mm[rest], s_mm)
        v = np.where(still, 0.5 * (6.0 * d) ** (2.0 / 3.0) * jerk ** (1.0 / 3.0), v)
    # cells in which even the limit spends more than CELL_PERIODS periods are cut (a cruise's,
    # CRUISE_CUT_PERIODS: between two nodes that cruise, all do)
    h = np.diff(s_mm)
    speed = np.maximum(np.minimum(v[:-1], v[1:]), 1e-300)
    cruising = np.interp(s_mm, grid_s, grid_cruise) >= 1.0
    periods = np.where(cruising[:-1] & cruising[1:], CRUISE_CUT_PERIODS, CELL_PERIODS)
    parts = np.ceil(h / (periods * lim.period_s * speed))
    closed = rest.copy()  # the rests with a rest cell beside them
    closed[[0, -1]] &= ~np.array(ends.moving)
    long = (parts > 1.0) & ~closed[:-1] & ~closed[1:]
    if s_mm.size + np.sum(parts[long] - 1.0) > max_nodes:
        return None
    if long.any():
        cut = [s_mm[i] + h[i] * np.arange(1, n) / n
               for i, n in zip(np.flatnonzero(long), parts[long].astype(np.int64))]
        s_mm, u, rest, v = _insert(curve, grid, s_mm, u, rest, v, cut)
    if seed_s.size:
        s_mm, u, rest, v = _seeded(curve, grid, s_mm, u, rest, v, seed_s, floor)
    # the estimate again on the nodes (inserted ones took theirs by interpolation)
    cap = np.interp(s_mm, grid.s_mm, np.asarray(cap_mm_s, dtype=float))
    return s_mm, u, rest, speed_estimate(s_mm, cap, acc, rest, ends)


def _seeded(curve: NurbsCurve, grid: Grid, s_mm: np.ndarray, u: np.ndarray, rest: np.ndarray,
            v: np.ndarray, seed_s: np.ndarray, floor: float) -> tuple[np.ndarray, ...]:
    """The nodes with those strictly between seed_s's first and last (rests aside) replaced
    by seed_s (within floor of a node kept: that node)."""
    lo, hi = float(seed_s[0]), float(seed_s[-1])
    keep = (s_mm < lo - floor) | (s_mm > hi + floor) | rest
    s_mm, u, rest, v = s_mm[keep], u[keep], rest[keep], v[keep]
    far = _distance_to(s_mm, seed_s) >= floor
    more = seed_s[far]
    order = np.argsort(np.concatenate([s_mm, more]), kind="stable")
    return (np.concatenate([s_mm, more])[order],
            np.concatenate([u, arc_parameters(curve, grid, more)])[order],
            np.concatenate([rest, np.zeros(more.size, dtype=bool)])[order],
            np.concatenate([v, np.interp(more, s_mm, v)])[order])


def _open_end_nodes(s_end: float, side: float, step: float, state, floor: float) -> np.ndarray:
    """A node beside a moving end where its slope would take b from the end's b to half of it
    (b' towards the inside, side = +1 at the start, -1 at the end) within the first cell: the
    spline's second coefficient there is b + g b' (g half the cell), which must stay > 0."""
    slope = side * state.db_ds
    if slope >= 0.0:
        return np.empty(0)
    reach = 0.5 * state.b / -slope
    if not floor <= reach < step:
        return np.empty(0)
    return np.array([s_end + side * reach])


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
    more = more[_distance_to(s_mm, more) >= floor]
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
