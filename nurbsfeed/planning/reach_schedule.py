"""The path planner's schedule on a layout (design §2d): per stretch, the controllable sets and
the fastest motion inside them, with floors where that motion dips (planning.reach_pass).

1. Backward pass: every knot's controllable set, linearised at the speed estimate (or at the
   schedule the layout was cut from); forward pass: the fastest motion inside them.
2. The same backward pass over the stretch reversed: the states reachable from its start. The
   highest b both reachable and controllable at a knot bounds every motion's b there.
3. Where the forward motion runs below FLOOR_SHARE of that bound (it braked as late as its
   sets allowed and then could not take its deceleration back before it came to the slow
   part, dipping far below what passing there needs), a floor at FLOOR_KEEP of the bound
   makes the sets brake earlier; both passes run again, linearised at the motion (and the
   floors), and give the schedule. Where the floors leave no motion the last one stands.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.planning.basis import BETWEEN, POINTS
from nurbsfeed.planning.cells import Layout
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.ratios import cell_ratios
from nurbsfeed.planning.reach_pass import (
    END_MOVING,
    END_MOVING_LOOSE,
    END_REST,
    controllable,
    forward,
    highest,
    motion_time,
)
from nurbsfeed.planning.reach_rows import B_FLOOR, limits_vector
from nurbsfeed.planning.reach_sets import MAX_LEVELS
from nurbsfeed.planning.schedule import BETWEEN_REL, Schedule, cell_times, static_b

STATIC_REACH = 2.0
REST_REACH = 1.5
FLOOR_SHARE = 0.9
FLOOR_KEEP = 0.95
SEED_KEEP = 0.995
# floors that leave a knot's set empty are lowered by this factor, this many times at most
FLOOR_RELAX = 0.9
FLOOR_RELAXATIONS = 4
FLOOR_WINDOW = 24
# an empty set without floors to blame: the linearisation this many knots around it (a quarter
# of them upstream) lowered by LIN_LOWER, LIN_RETRIES times at most
LIN_WINDOW = 24
LIN_LOWER = 0.25
LIN_RETRIES = 3


def _reversed_geometry(g: np.ndarray) -> np.ndarray:
    """Geometry rows read the other way along the path: T, K_s and the jump turn sign."""
    out = g[::-1].copy()
    out[:, 1:4] *= -1.0
    out[:, 7:13] *= -1.0
    return out


Arrays4 = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
End = tuple[int, float, float]  # (kind, p1, p2): planning.reach_pass's ends


def _levels(q_n: int) -> Arrays4:
    """Room for a stretch's sets: per knot (Q + 1,) the levels' accelerations, upper and lower
    boundaries (Q + 1, MAX_LEVELS) and their count."""
    n = q_n + 1
    return (np.zeros((n, MAX_LEVELS)), np.zeros((n, MAX_LEVELS)), np.zeros((n, MAX_LEVELS)),
            np.zeros(n, dtype=np.int64))


def _backward(geometry: Arrays4, lims: np.ndarray, floors: np.ndarray, lin_knot: np.ndarray,
              lin_mid: np.ndarray, focus: np.ndarray | None, end: End
              ) -> tuple[Arrays4, np.ndarray, np.ndarray, np.ndarray] | None:
    """The backward pass over a stretch (geometry = h, g0, gm, g1), with what it had to give
    up on its way: where a knot's set comes out empty, the first floors from there on (a run
    of FLOOR_WINDOW knots at most) ask more than the sets allow and are lowered (at last
    dropped); where there are none, the
    sets went too thin at low speed, where the rows' tangents to J / sqrt(b), taken far above
    the speed the motion has there, leave it too little jerk: the linearisation is lowered
    around the knot (up to LIN_RETRIES times). The pass resumes downstream of the change.
    Returns (sets, floors, lin_knot, lin_mid) as they stood when it got through, or None."""
    q_n = geometry[0].size
    sets = _levels(q_n)
    focused = focus is not None
    floors = floors.copy()
    asked = floors.copy()
    lowered = 0
    top = q_n - 1
    while True:
        empty = controllable(*geometry, lin_knot, lin_mid, floors, lims, *end,
                             focus if focused else lin_knot, focused, top, *sets)
        if empty < 0:
            return sets, floors, lin_knot, lin_mid
        start = empty
        while start <= q_n and floors[start] == 0.0:
            start += 1
        if start <= q_n:
            # the floors of the run from there, FLOOR_WINDOW knots of it at most: lowered
            run = start
            while run + 1 <= min(q_n, start + FLOOR_WINDOW) and floors[run + 1] > 0.0:
                run += 1
            lowest = asked[start] * FLOOR_RELAX ** FLOOR_RELAXATIONS
            floors[start:run + 1] *= FLOOR_RELAX if floors[start] > lowest else 0.0
            top = min(run, q_n - 1)
            continue
        if lowered == LIN_RETRIES:
            return None
        lowered += 1
        lo, hi = max(empty - LIN_WINDOW // 4, 0), min(empty + LIN_WINDOW, q_n)
        lin_knot = lin_knot.copy()
        lin_mid = lin_mid.copy()
        lin_knot[lo:hi + 1] = np.maximum(lin_knot[lo:hi + 1] * LIN_LOWER, B_FLOOR)
        lin_mid[lo:hi] = np.maximum(lin_mid[lo:hi] * LIN_LOWER, B_FLOOR)
        top = min(hi, q_n - 1)


class _Stretch:
    """One stretch's arrays for the passes (module docstring of planning.reach_pass)."""

    def __init__(self, layout: Layout, s: int, q0: int, lin: np.ndarray,
                 motion: np.ndarray, lim: Limits, seeded: np.ndarray) -> None:
        first, last = int(layout.first[s]), int(layout.last[s])
        self.first, self.last = first, last
        q_n = last - first - 1
        self.q0, self.q_n = q0, q_n
        cells = layout.cells[q0:q0 + q_n]
        self.h = np.ascontiguousarray(cells[:, 4])
        geo = layout.geo[q0:q0 + q_n]
        self.g0 = np.ascontiguousarray(geo[:, 0])
        self.gm = np.ascontiguousarray(geo[:, 1])
        self.g1 = np.ascontiguousarray(geo[:, 2])
        kw = layout.knot_w[first:first + q_n + 1]
        c = lin[first:last + 1]
        self.lin_knot = np.maximum(kw * c[:-1] + (1.0 - kw) * c[1:], B_FLOOR)
        # b at each cell's middle (basis.point_weights at 0.5, for all cells at once)
        g0, g1, w0, hh = cells[:, 1], cells[:, 2], cells[:, 3], cells[:, 4]
        s0 = (c[1:-1] - c[:-2]) / g0
        s1 = (c[2:] - c[1:-1]) / g1
        xs = 0.5 * hh
        mid = w0 * c[:-2] + (1.0 - w0) * c[1:-1] + s0 * xs + 0.5 * (s1 - s0) / hh * xs * xs
        self.lin_mid = np.maximum(mid, B_FLOOR)
        # the acceleration the linearisation has at each knot (b' / 2, the polygon's slope
        # there), where it comes from a motion (a seed) rather than an estimate: NaN elsewhere
        slope = np.diff(c) / np.diff(layout.xi[first:last + 1])
        known = motion[first:last] & motion[first + 1:last + 1]
        self.lin_focus = np.where(known, 0.5 * slope, np.nan)
        # a seed is the plan this one takes over from: at least SEED_KEEP of its b where the
        # two overlap, so that a motion handed on does not fall behind the one it continues
        on_seed = seeded[first:last] & seeded[first + 1:last + 1]
        self.seed_floor = np.where(on_seed, SEED_KEEP * self.lin_knot, 0.0)
        self.start = (END_REST, float(layout.rest_h[s, 0]), float(layout.cap[first]))
        self.end = (END_REST, float(layout.rest_h[s, 1]), float(layout.cap[last]))
        knot_s = np.concatenate(([0.0], np.cumsum(self.h)))
        for side in range(2):
            if not layout.is_open(s, side):
                continue
            if side == 0:
                b, c1 = layout.fixed[0]
                a = (c1 - b) / self.h[0]
                self.start = (END_MOVING, float(b), float(a))
                near = knot_s <= _moving_reach(b, lim)
            else:
                c0, b = layout.fixed[1]
                a = (b - c0) / self.h[-1]
                self.end = (END_MOVING, float(b), float(a))
                near = knot_s >= knot_s[-1] - _moving_reach(b, lim)
            # where nothing is known of the motion, it stays near the state it is given for
            # a while: the sets are probed closely around that acceleration there
            self.lin_focus = np.where(near & np.isnan(self.lin_focus), a, self.lin_focus)

    def plan(self, lims: np.ndarray, floors: np.ndarray, lin_knot: np.ndarray,
             lin_mid: np.ndarray, focus: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, Arrays4] | None:
        """Backward and forward pass: the motion (b, a) at the knots and the sets; None where
        a set came out empty or the forward pass found no way on. focus: the acceleration
        (Q + 1,) of a motion found before, where the sets are probed closely."""
        geometry = (self.h, self.g0, self.gm, self.g1)
        made = _backward(geometry, lims, floors, lin_knot, lin_mid, focus, self.end)
        if made is None:
            return None
        sets, floors, lin_knot, lin_mid = made
        b = np.empty(self.q_n + 1)
        a = np.empty(self.q_n + 1)
        if forward(*geometry, lin_knot, lin_mid, floors, lims, *self.start, *self.end, *sets,
                   b, a) >= 0:
            return None
        return b, a, sets

    def reachable(self, lims: np.ndarray, lin_knot: np.ndarray, lin_mid: np.ndarray
                  ) -> Arrays4 | None:
        """The sets of the stretch run backwards: the states reachable from its start."""
        end: End = self.start if self.start[0] == END_REST else (
            END_MOVING_LOOSE, self.start[1], -self.start[2])
        geometry = (np.ascontiguousarray(self.h[::-1]), _reversed_geometry(self.g1),
                    _reversed_geometry(self.gm), _reversed_geometry(self.g0))
        made = _backward(geometry, np.ascontiguousarray(lims[::-1]), np.zeros(self.q_n + 1),
                         np.ascontiguousarray(lin_knot[::-1]),
                         np.ascontiguousarray(lin_mid[::-1]), None, end)
        return None if made is None else made[0]

    def time(self, b: np.ndarray, a: np.ndarray) -> float:
        start_h = self.start[1] if self.start[0] == END_REST else 0.0
        end_h = self.end[1] if self.end[0] == END_REST else 0.0
        return float(motion_time(self.h, b, a, start_h, end_h))

    def coefficients(self, b: np.ndarray, a: np.ndarray, c: np.ndarray) -> None:
        """The motion as the stretch's spline coefficients: b at its first and last knot, and
        each cell's middle coefficient b_j + h_j a_j (its quadratic's control point)."""
        c[self.first] = b[0]
        c[self.first + 1:self.last] = b[:-1] + self.h * a[:-1]
        c[self.last] = b[-1]


def _mid_values(h: np.ndarray, b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """b at each cell's middle of the motion (b, a) at the knots."""
    u = np.diff(a) / h
    return b[:-1] + h * a[:-1] + 0.25 * h * h * u


def _plan_stretch(st: _Stretch, lims: np.ndarray) -> tuple[np.ndarray, np.ndarray, int] | None:
    """The motion of one stretch (module docstring): (b, a) at its knots and the passes run."""
    no_floor = np.zeros(st.q_n + 1)
    known = np.any(st.lin_focus == st.lin_focus)
    first = st.plan(lims, no_floor, st.lin_knot, st.lin_mid, st.lin_focus if known else None)
    if first is None:
        return None
    b1, a1, k_sets = first
    passes = 2
    floors = st.seed_floor.copy()
    r_sets = st.reachable(lims, st.lin_knot, st.lin_mid)
    if r_sets is not None:
        passes += 1
        bound = np.empty(st.q_n + 1)
        highest(*k_sets, *r_sets, bound)
        floors = np.maximum(floors, np.where(b1 < FLOOR_SHARE * bound, FLOOR_KEEP * bound, 0.0))
    floors[0] = floors[-1] = 0.0
    lin_knot = np.maximum(np.maximum(b1, floors), B_FLOOR)
    lin_mid = np.maximum(np.maximum(_mid_values(st.h, b1, a1),
                                    0.5 * (floors[1:] + floors[:-1])), B_FLOOR)
    best = (b1, a1, st.time(b1, a1))
    # probed around the first motion, and around a seed's (the plan this one takes over
    # from) where there is one: the motion it continues rides those boundaries; where the
    # floors leave no motion, the pass runs again without them
    focus = np.where(np.isnan(st.lin_focus), a1, st.lin_focus)
    for f in ((floors, no_floor) if floors.any() else (no_floor,)):
        passes += 2
        again = st.plan(lims, f, lin_knot, lin_mid, focus)
        if again is None:
            continue
        t = st.time(again[0], again[1])
        if t < best[2]:
            best = (again[0], again[1], t)
        break
    return best[0], best[1], passes


def _moving_reach(b: float, lim: Limits) -> float:
    """How far a motion in state b stays near it: v (v / A + A / J), braking from v."""
    v = math.sqrt(max(b, 0.0))
    return v * (v / lim.acc_mm_s2 + lim.acc_mm_s2 / lim.jerk_mm_s3)


def _estimate(layout: Layout, lim: Limits) -> np.ndarray:
    """The first linearisation point (C,): the speed estimate (no motion is faster), but at most
    STATIC_REACH times each point's static limit (b' = b'' = 0: a curvature peak, where the
    jerk-limited motion runs far below the estimate and a tangent taken there would cut the
    jerk it may use to a fraction)."""
    acc_x = np.array(lim.axis_acc_mm_s2, dtype=float)
    jerk_x = np.array(lim.axis_jerk_mm_s3, dtype=float)
    sb = np.empty((layout.cells.shape[0], 3))
    static_b(layout.geo, lim.jerk_mm_s3, lim.normal_jerk_mm_s3, acc_x, jerk_x, lim.period_s, sb)
    static = np.full(layout.n_coefficients, np.inf)
    i0 = layout.cells[:, 0].astype(np.int64)
    for j in range(3):
        np.minimum.at(static, i0 + j, sb.min(axis=1))
    # beside a rest the motion leaves (reaches) it with the jerk limit: v = (J / 2) t^2 at s =
    # J t^3 / 6, v = 0.5 (6 s)^(2/3) J^(1/3), far below the acceleration-limited estimate
    rest_s = layout.s_mm[layout.rest]
    if layout.moving[0]:
        rest_s = rest_s[1:]
    if layout.moving[1]:
        rest_s = rest_s[:-1]
    lin = np.minimum(np.minimum(layout.b_estimate, layout.cap), STATIC_REACH * static)
    if rest_s.size:
        gap = np.min(np.abs(layout.xi[:, None] - rest_s[None, :]), axis=1)
        start = (0.5 * (6.0 * gap) ** (2.0 / 3.0) * lim.jerk_mm_s3 ** (1.0 / 3.0)) ** 2
        lin = np.minimum(lin, REST_REACH * start)
    # a moving end's own state: the motion stays near it for as long as the limits take to
    # change it, v (v / A + A / J)
    for side in range(2):
        if layout.moving[side]:
            b_end = layout.fixed[side, 1 - side]
            x_end = layout.xi[0] if side == 0 else layout.xi[-1]
            near = np.abs(layout.xi - x_end) <= _moving_reach(b_end, lim)
            lin[near] = np.maximum(lin[near], b_end)
    return lin


def plan_schedule(layout: Layout, lim: Limits, start: np.ndarray | None = None,
                   seed: tuple[np.ndarray, np.ndarray] | None = None,
                   slack: tuple[float, float] = (0.0, 0.0)) -> Schedule:
    """The schedule on `layout` under `lim` (module docstring): linearised first at start
    (coefficients (C,); by default the speed estimate, and where a seed (xi (K,), c (K,))
    covers the coefficients, its). slack (share, mm): every limit within that distance of a
    moving end loosened by that share, for an end in a state the limits there leave no way
    on from (or to) (planning.path_plan)."""
    lin = _estimate(layout, lim) if start is None else np.array(start)
    motion = np.full(lin.size, start is not None)
    seeded = np.zeros(lin.size, dtype=bool)
    if seed is not None:
        span = 1e-9 * max(float(layout.xi[-1]), 1.0)
        inside = (layout.xi >= seed[0][0] - span) & (layout.xi <= seed[0][-1] + span)
        lin[inside] = np.interp(layout.xi[inside], *seed)
        motion |= inside
        seeded = inside
    # a moving end's state is the linearisation's there too
    lin[layout.fixed_index] = layout.fixed_values
    motion[layout.fixed_index] = True
    limits = limits_vector(lim)
    near = np.zeros(layout.cells.shape[0], dtype=bool)
    if slack[0] > 0.0:
        at = layout.s_mm[layout.cell_node]
        if layout.moving[0]:
            near |= at <= layout.s_mm[0] + slack[1]
        if layout.moving[1]:
            near |= at >= layout.s_mm[-1] - slack[1]
    lims = np.repeat(limits[None, :], layout.cells.shape[0], axis=0)
    lims[near, :3] *= 1.0 + slack[0]
    lims[near, 4:] *= 1.0 + slack[0]
    c = np.minimum(lin, layout.cap).astype(float)
    solved = True
    passes = 0
    q0 = 0
    for s in range(layout.first.size):
        st = _Stretch(layout, s, q0, lin, motion, lim, seeded)
        q0 += st.q_n
        made = _plan_stretch(st, np.ascontiguousarray(lims[q0 - st.q_n:q0]))
        if made is None:
            solved = False
            continue
        st.coefficients(made[0], made[1], c)
        passes += made[2]
    c[layout.fixed_index] = layout.fixed_values
    return _schedule(layout, lim, c, passes, solved, near, slack[0])


def _schedule(layout: Layout, lim: Limits, c: np.ndarray, passes: int, solved: bool,
              near: np.ndarray, slack_rel: float) -> Schedule:
    """The coefficients c as a Schedule: their cycle, the slowdown their exact check at every
    cell's points asks, the cells they break a limit in between those points."""
    acc_x = np.array(lim.axis_acc_mm_s2, dtype=float)
    vel_x = np.array(lim.axis_vel_mm_s, dtype=float)
    jerk_x = np.array(lim.axis_jerk_mm_s3, dtype=float)
    q_n = layout.cells.shape[0]
    times = np.empty(q_n + 2 * layout.first.size)
    cycle = cell_times(c, layout.cells, layout.first, layout.last, layout.rest_h, times)
    ratios = np.empty(q_n)
    cell_ratios(c, layout.cells, layout.geo, np.array(POINTS), lim.jerk_mm_s3, lim.acc_mm_s2,
                lim.normal_jerk_mm_s3, acc_x, vel_x, jerk_x, lim.period_s, ratios)
    between = np.empty(q_n)
    cell_ratios(c, layout.cells, layout.between, np.array(BETWEEN), lim.jerk_mm_s3,
                lim.acc_mm_s2, lim.normal_jerk_mm_s3, acc_x, vel_x, jerk_x, lim.period_s,
                between)
    # what the slack near a moving end allows is no slowdown: an acceleration's share is the
    # square of one
    for r in (ratios, between):
        r[near] /= (1.0 + slack_rel) ** 0.5
    slowdown = max(1.0, float(ratios.max(initial=0.0)))
    if not math.isfinite(cycle):
        solved = False
    c.setflags(write=False)
    return Schedule(layout, c, float(cycle), slowdown, passes, solved,
                    between > 1.0 + BETWEEN_REL)
