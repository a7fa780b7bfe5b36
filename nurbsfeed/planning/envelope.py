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
from nurbsfeed.planning.envelope_law import sampled_law
from nurbsfeed.planning.envelope_passes import (
    _convex_pass,
    _lift_pass,
    _rest_pass,
    _round_pass,
    _row_pass,
    _slope_passes,
)
from nurbsfeed.planning.envelope_rows import (
    ROWS,
    _caps,
    _cell_rows,
    _coefficient_caps,
    _geometry,
    _node_slopes,
    _rest_caps,
    _slope_rows,
    _Spline,
)
from nurbsfeed.planning.grid import Grid
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.optimal import (
    Schedule,
    _cell_ratios,
    _jumps,
    _Nodes,
    _refined,
    cycle_s,
    schedule_nodes,
)
from nurbsfeed.planning.path_check import arc_parameters
from nurbsfeed.planning.path_model import frames, static_limit

# each round raises the last round's profile by this factor (of b) at most, then lowers it to
# what the limits allow with their terms frozen at the raised one: the factors fall to 1 so
# that the last rounds' frozen terms are within a per cent of the profile they shape
GROWTH = (2.0, 1.5, 1.5, 1.3, 1.3, 1.2, 1.1, 1.05, 1.03, 1.02, 1.01, 1.0)
INNER_ROUNDS = 60  # cap, slope and curvature passes of the last round, at most
EARLY_ROUNDS = 10  # ... of the rounds before it, which only shape the terms to freeze
CONVERGED_REL = 1e-4  # a pass lowering no b by more than this share of it: converged
FIX_ROUNDS = 16  # rounds that lower the limits where the law exceeds them
FIX_REL = 0.01  # ... while it does so by more than this
FIX_WORST = 1.5  # ... and while their profile lasts less than this times the best plan's
# a profile whose growth a share of coefficients above this took in full in the last round that
# grew (no bound lowered them: the growth, not the limits, held them) grows again from where it
# ended, REGROW_ROUNDS times at most: a stretch the first round's frozen terms pulled far below
# its limits (a 3 mm star's arms between near-cusps) rises by the product of GROWTH a time
REGROW_SHARE = 0.02
REGROW_ROUNDS = 3
# the rounds of growth on the nodes refined after the first profile
REFINED_GROWTH = GROWTH[6:]
REFINE_ROUNDS = 2  # times cells lasting longer than the optimal planner's limit are split
# the law has a piece a sample: past this many periods a curve keeps the S-curve plan, whose
# pieces do not grow with its duration (a two-hour curve's law would take 1.2 GB)
MAX_LAW_PERIODS = 1_000_000


def _profile(curve: NurbsCurve, grid: Grid, lim: Limits, nodes: _Nodes,
             feed_at_u: Callable[[np.ndarray], np.ndarray], scale: np.ndarray,
             start: np.ndarray | None, growth_rounds: tuple[float, ...] = GROWTH
             ) -> tuple[np.ndarray, np.ndarray, float]:
    """The greatest spline the passes find on these nodes, as b and b' (M,) at the nodes, and
    the share of coefficients that took the last growing round's growth in full; the
    limits scaled per node by scale (M,) (FIX_ROUNDS lower it where the law exceeded a limit):
    a speed by scale, an acceleration by scale^2, a jerk by scale^3.

    The rounds grow b from a profile that keeps the static limits (a = j = 0: kappa^2 v^3 <=
    J_t ...), by at most GROWTH a round: the terms frozen at the last round's profile stay
    near the new one, so the passes never act on a b far above the profile they shape (a
    curvature bound frozen at the caps asks b'' > 0 over whole stretches and drives b to 0).
    start: b (M,) at the nodes to grow from instead (a profile planned before, on other
    nodes or limits), growth_rounds the factors of the rounds (GROWTH)."""
    spline = _Spline(nodes)
    s = nodes.s_mm
    m = s.size
    node_frames = frames(curve, nodes.u)
    geo = _geometry(node_frames)
    # a cell's end read from inside it: at a knot kappa' (through C''') jumps, and the span
    # before the knot is the cell's
    before = np.maximum(np.nextafter(nodes.u, -np.inf), np.concatenate([[nodes.u[0]],
                                                                        nodes.u[:-1]]))
    geo_end = _geometry(frames(curve, before))
    mid_u = arc_parameters(curve, grid, 0.5 * (s[:-1] + s[1:]))
    mid_frames = frames(curve, mid_u)
    geo_mid = _geometry(mid_frames)
    mid_scale = np.minimum(scale[:-1], scale[1:])
    node_jumps = _jumps(curve, nodes.u)
    node_cap = (_caps(lim, node_frames, node_jumps, feed_at_u(nodes.u)) * scale) ** 2
    mid_cap = (_caps(lim, mid_frames, _jumps(curve, mid_u), feed_at_u(mid_u)) * mid_scale) ** 2
    rest_cap = _rest_caps(lim, nodes, geo, scale)
    cap = _coefficient_caps(spline, node_cap, mid_cap, rest_cap)
    jump = np.abs(node_jumps)
    knot_geo = np.ascontiguousarray(geo[spline.knot])
    knot_scale = np.ascontiguousarray(scale[spline.knot])
    axis_acc = np.array(lim.axis_acc_mm_s2, dtype=float)
    n = spline.xi.size
    rows = np.empty((n, ROWS, 4))
    phi = np.empty(n)
    hull = np.empty(n, dtype=np.int64)
    if start is None:
        static = _coefficient_caps(
            spline, np.minimum(node_cap, (static_limit(node_frames, lim) * scale) ** 2),
            np.minimum(mid_cap, (static_limit(mid_frames, lim) * mid_scale) ** 2),
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
    held_by_growth = 0.0
    for index, growth in enumerate(growth_rounds):
        last_round = index == len(growth_rounds) - 1
        grown = c.copy()
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
        for inner in range(INNER_ROUNDS if last_round else EARLY_ROUNDS):
            change = 0.0
            for (first, last), ratio in zip(spline.ranges, spline.ratio):
                change = max(change, _slope_passes(spline.xi, c, spline.w, rows, first,
                                                   last))
                change = max(change, _convex_pass(spline.xi, c, spline.width, lo_hull, first,
                                                  last, phi, hull))
                change = max(change, _lift_pass(spline.xi, c, spline.width, no_axes, kappa2,
                                                lim.jerk_mm_s3 * scale3, first, last))
                # the row pass's sweeps in turn forward first and backward first: in one
                # order alone the side of a valley the motion comes down sank (the 60 mm
                # star's into each near cusp, 8 % below the reference where the side it
                # climbs was within 0.5 %; the curve reversed, the other side)
                change = max(change, _row_pass(c, rows3, first, last, inner % 2 == 1))
                change = max(change, _round_pass(spline.xi, c, spline.width, hi, first, last))
                change = max(change, _rest_pass(c, ratio, first, last))
            if change <= CONVERGED_REL:
                break
        if index > 0 and growth_rounds[index - 1] > 1.0:  # this round started from a growth
            held_by_growth = float(np.mean((c >= grown) & (grown < cap)))
        frozen_b, frozen_d, frozen_dd = spline.at_nodes(c)
        c = np.minimum(cap, growth * c)
    return frozen_b, frozen_d, held_by_growth


def _coefficients_follow(spline: _Spline) -> bool:
    """Whether each stretch's coefficients follow one another (not so where a single node lies
    between two rests, or nodes coincide: no slope between them)."""
    return all(bool(np.all(np.diff(spline.xi[first:last + 1]) > 0.0))
               for first, last in spline.ranges)


def envelope_schedule(curve: NurbsCurve, grid: Grid, lim: Limits, rest_nodes: np.ndarray,
                      v_limit: np.ndarray, feed_at_u: Callable[[np.ndarray], np.ndarray],
                      slowdown: float = 1.0) -> Schedule | None:
    """The schedule of `curve` under `lim` (path model) resting at grid nodes rest_nodes: the
    ends, corners and cusps. v_limit (M,): the pointwise speed limit at the grid's nodes, no
    lower than any speed a schedule reaches there. feed_at_u: parameters (N,) -> programmed
    feed (N,). slowdown: a uniform slowdown on top of the one the law needs. None where it
    cannot plan (a profile of b = 0 inside a stretch: a motion that never arrives; a stretch
    whose coefficients coincide), where its schedule would last longer than MAX_LAW_PERIODS,
    or on a grid of more than MAX_NODES nodes (each takes about 2.5 kB of rows: a two-hour
    curve's 200,000 took 750 MB)."""
    made = schedule_nodes(curve, grid, lim, rest_nodes, v_limit)
    if made is None:
        return None
    rest_nodes, nodes = made
    # cells cut where even the limit spends more than a few periods in one (no schedule is
    # faster), then again where the first profile does
    b_start = np.interp(nodes.s_mm, grid.s_mm, v_limit) ** 2
    for _ in range(REFINE_ROUNDS):
        refined = _refined(curve, grid, nodes, b_start, lim.period_s,
                           _node_slopes(nodes.s_mm, b_start))
        if refined is None:
            break
        nodes, b_start = refined
    spline = _Spline(nodes)
    if not _coefficients_follow(spline):
        return None
    scale = np.ones(nodes.s_mm.size)
    b, d, held = _profile(curve, grid, lim, nodes, feed_at_u, scale, None)
    refined = _refined(curve, grid, nodes, b, lim.period_s, d)
    if refined is not None:
        # on the finer nodes the profile grows from where it is by the last rounds' factors
        nodes, b = refined
        spline = _Spline(nodes)
        if not _coefficients_follow(spline):
            return None
        scale = np.ones(nodes.s_mm.size)
        b, d, held = _profile(curve, grid, lim, nodes, feed_at_u, scale, b, REFINED_GROWTH)
    for _ in range(REGROW_ROUNDS):
        if held <= REGROW_SHARE:
            break
        b_more, d_more, held = _profile(curve, grid, lim, nodes, feed_at_u, scale, b)
        if not cycle_s(nodes, b_more, d_more) < cycle_s(nodes, b, d):
            break
        b, d = b_more, d_more
    if not cycle_s(nodes, b, d) < MAX_LAW_PERIODS * lim.period_s:
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
        b, d, _ = _profile(curve, grid, lim, nodes, feed_at_u, scale, b, (1.0,))
        if not cycle_s(nodes, b, d) < FIX_WORST * best[0]:
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
