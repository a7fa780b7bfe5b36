"""The reach planner's kernels (planning.reach_rows, reach_bounds, reach_sets, reach_pass):
the chains' level intervals and the pruned bounds against brute force; a real stretch's
controllable sets against linear programs over the same rows (HiGHS: every state inside a set
has a way on, and little above a set has one); the forward pass's motion against its rows, its
sets and its ends; the highest state two sets share against every candidate point; the folded
end rows against the end they stand for; a motion's time against quadrature; the jerk rows'
tangent against its limit."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.optimize import linprog

from nurbsfeed.analysis.bound.solve import jerk_limited_schedule
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine
from nurbsfeed.planning import path_plan
from nurbsfeed.planning import reach_schedule as rs
from nurbsfeed.planning.basis import G_CAP, G_KS, G_SIZE, G_T
from nurbsfeed.planning.cells import Layout
from nurbsfeed.planning.plan import KIND_CUSP
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.planning.reach_bounds import LOOSE_END_REL, MOVING_END_REL, fold_end, prune
from nurbsfeed.planning.reach_pass import (
    END_MOVING,
    END_MOVING_LOOSE,
    END_REST,
    controllable,
    forward,
    highest,
    level_interval,
    motion_time,
)
from nurbsfeed.planning.reach_rows import B_FLOOR, ROWS_PER_CELL, cell_rows, jerk_tangent
from tests.bench.dense_curves import axis_bend, axis_toolpaths
from tests.conftest import ROOT

DEFAULT = load_machine("default")
# a cubic out of the plane (the normal jerk's polygon rows), 30 mm: 114 cells under the default
CURVE = NurbsCurve.build(3, [0, 0, 0, 0, 1, 1, 1, 1],
                         [[0, 0, 0], [10, 5, 2], [20, -5, -2], [30, 0, 3]], None, "bent-cubic")
# 40 mm along X, a bend of about 1 mm radius, 40 mm along Y: at 100 mm/s the motion cruises on
# both legs and slows for the bend
BEND = axis_bend()
ROW_REL = 1e-6  # of a row's terms: what the passes' own tolerances (1e-7 at most) may break it by
SET_REL = 1e-6  # of b: how far outside a set the forward pass may stand (its start check's)


# ---- the chains' level intervals and the pruned bounds -----------------------------------------

@st.composite
def chains(draw):
    """(a1 (n,), concave (n,), convex (n,)): strictly, over steps of 0.05 to 1."""
    n = draw(st.integers(1, 10))
    steps = np.array(draw(st.lists(st.floats(0.05, 1.0), min_size=n - 1, max_size=n - 1)))
    x = draw(st.floats(-5.0, 5.0)) + np.concatenate([[0.0], np.cumsum(steps)])
    shape = []
    for order in (-1, 1):  # slopes falling: concave; rising: convex
        slopes = np.sort(draw(st.lists(st.floats(-20.0, 20.0), min_size=n - 1, max_size=n - 1,
                                       unique=True)))[::order]
        shape.append(draw(st.floats(-5.0, 5.0))
                     + np.concatenate([[0.0], np.cumsum(slopes * steps)]))
    return x, shape[0], shape[1]


def interval_at_least(x: np.ndarray, y: np.ndarray, c: float) -> tuple[float, float]:
    """Where the piecewise linear (x, y) is >= c, from every point and every crossing of c."""
    keep = [float(x[k]) for k in range(x.size) if y[k] >= c]
    for k in range(x.size - 1):
        if (y[k] - c) * (y[k + 1] - c) < 0.0:
            keep.append(x[k] + (c - y[k]) * (x[k + 1] - x[k]) / (y[k + 1] - y[k]))
    return (min(keep), max(keep)) if keep else (1.0, -1.0)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(chains(), st.lists(st.integers(-3, 13), min_size=4, max_size=4))
def test_a_chains_level_interval_is_where_it_is_above_or_below_the_level(chain_xy, warm) -> None:
    """level_interval, sign 1 (-1): [lo, hi] is where the concave (convex) chain is >= c (<= c), its
    ends where the chain crosses c, exactly the peak's a1 at c on the peak, empty above it; dlo /
    dc and dhi / dc are the central differences of the brute force's ends (c nowhere near a
    point's value); and where the last searches ended (idx, any values) changes nothing."""
    x, cave, vex = chain_xy
    n = x.size
    chain = np.ascontiguousarray(np.vstack([x, cave, vex]))
    peak, valley = int(np.argmax(cave)), int(np.argmin(vex))
    delta = 1e-6
    for row, sign, top in ((1, 1.0, peak), (2, -1.0, valley)):
        y = sign * chain[row]
        levels = [y[top] - t * (y[top] - y.min() + 1.0) for t in (0.0, 0.1, 0.37, 0.5, 0.9, 1.0)]
        for c in [*levels, *y]:
            args = (chain, row, n, top, sign * c, sign)
            lo, hi, dlo, dhi = level_interval(*args, np.array([top] * 4, dtype=np.int64))
            for start in (np.array(warm, dtype=np.int64), np.zeros(4, dtype=np.int64)):
                assert level_interval(*args, start) == (lo, hi, dlo, dhi)
            want = interval_at_least(x, y, c)
            assert (lo, hi) == pytest.approx(want, rel=1e-12, abs=1e-12)
            if c == y[top] and np.sum(y == c) == 1:  # a strict peak
                assert lo == hi == x[top]
            if np.min(np.abs(y - c)) > 10.0 * delta:
                up = interval_at_least(x, y, c + delta)
                down = interval_at_least(x, y, c - delta)
                for d_kernel, k in ((dlo, 0), (dhi, 1)):
                    fd = sign * (up[k] - down[k]) / (2.0 * delta)
                    assert d_kernel == pytest.approx(fd, rel=1e-5, abs=1e-6)
        lo, hi, _, _ = level_interval(chain, row, n, top, sign * (y[top] + 1.0), sign,
                                      np.zeros(4, np.int64))
        assert lo > hi


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.integers(0, 2**32 - 1), st.integers(1, 24), st.sampled_from([1.0, -1.0]))
def test_pruning_keeps_the_tightest_bound_everywhere_in_the_box(seed: int, n: int,
                                                                sign: float) -> None:
    """Bounds p + q a + s b on a1 (sign 1: from above, -1: from below), the first a looser copy
    of the tightest at a corner: prune keeps a subsequence of them, in order, without that copy,
    whose tightest equals the tightest of all at the box's corners and inside it."""
    rng = np.random.default_rng(seed)
    rows = rng.normal(size=(n, 3)) * np.array([10.0, 1.0, 0.1])
    a_lo = rng.uniform(-2000.0, 1000.0)
    a_hi = a_lo + rng.uniform(0.0, 2000.0)
    b_hi = rng.uniform(0.0, 1e4)
    corner = int(np.argmin(sign * (rows[:, 0] + rows[:, 1] * a_lo)))  # (a_lo, b = 0)
    looser = rows[corner] + np.array([sign * rng.uniform(1e-6, 5.0), 0.0, 0.0])
    given_rows = np.vstack([looser, rows])
    kept = given_rows.copy()
    m = prune(kept, n + 1, sign, a_lo, a_hi, b_hi)
    kept = kept[:m]
    assert m <= n and not any(np.array_equal(r, looser) for r in kept)
    i = 0
    for r in kept:  # (i runs past the end, an IndexError, where r is none of the rows left)
        while not np.array_equal(given_rows[i], r):
            i += 1
        i += 1
    a = np.concatenate([[a_lo, a_lo, a_hi, a_hi], rng.uniform(a_lo, a_hi, 300)])
    b = np.concatenate([[0.0, b_hi, 0.0, b_hi], rng.uniform(0.0, b_hi, 300)])

    def tightest(r: np.ndarray) -> np.ndarray:
        return np.min(sign * (r[:, :1] + r[:, 1:2] * a + r[:, 2:3] * b), axis=0)

    scale = np.abs(given_rows[:, :1]) + np.abs(given_rows[:, 1:2] * a) + np.abs(
        given_rows[:, 2:3] * b)
    assert np.all(np.abs(tightest(kept) - tightest(given_rows)) <= 1e-12 * scale.max(axis=0))


def test_pruning_drops_a_looser_copy_wherever_it_stands() -> None:
    """Bounds a1 <= 10, a, 0.5 - a, a + 0.1 over a in [0, 1], b in [0, 1]: 10 and a + 0.1 are
    looser than a everywhere, a is the tightest at a = 0 and 0.5 - a at a = 1 (and in the
    middle). The two looser go wherever they stand, also once the compaction has moved the
    tightest rows over the places they were found at; a and 0.5 - a stay, in order."""
    first = np.array([[0.1, 1.0, 0.0], [10.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, -1.0, 0.0]])
    assert prune(first, 4, 1.0, 0.0, 1.0, 1.0) == 2
    assert first[:2].tolist() == [[0.0, 1.0, 0.0], [0.5, -1.0, 0.0]]
    last = np.array([[10.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, -1.0, 0.0], [0.1, 1.0, 0.0]])
    assert prune(last, 4, 1.0, 0.0, 1.0, 1.0) == 2
    assert last[:2].tolist() == [[0.0, 1.0, 0.0], [0.5, -1.0, 0.0]]


# ---- a real stretch: its sets and its motion ---------------------------------------------------

class _Stop(Exception):
    pass


def captured_layout(curve: NurbsCurve, lim) -> Layout:
    """The layout path_plan hands to its schedule (the planner stopped there)."""
    made = []

    def spy(layout, lim_, *args):
        made.append(layout)
        raise _Stop

    original = path_plan.plan_schedule
    path_plan.plan_schedule = spy
    try:
        with pytest.raises(_Stop):
            plan_curve(curve, lim)
    finally:
        path_plan.plan_schedule = original
    return made[0]


@dataclasses.dataclass
class Case:
    """A run of cells as the passes read them (planning.reach_pass), its ends, rows and sets."""

    cells: tuple[np.ndarray, ...]  # h, g0, gm, g1, lin_knot, lin_mid, floors, lims
    start: tuple[int, float, float]
    end: tuple[int, float, float]
    rows: list[np.ndarray] = dataclasses.field(default_factory=list)
    sets: tuple[np.ndarray, ...] = ()

    def __post_init__(self) -> None:
        h, g0, gm, g1, knot, mid, floors, lims = self.cells
        buffer = np.empty((ROWS_PER_CELL, 4))
        for j in range(h.size):
            n = cell_rows(g0[j], gm[j], g1[j], h[j], knot[j], mid[j], knot[j + 1], floors[j],
                          floors[j + 1], lims[j], buffer)
            self.rows.append(buffer[:n].copy())
        self.sets = rs._levels(h.size)
        assert controllable(*self.cells, *self.end, knot, False, h.size - 1, *self.sets) == -1

    def set_at(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = self.sets[3][k]
        return self.sets[0][k, :n], self.sets[1][k, :n], self.sets[2][k, :n]

    def run(self, k: int = 0, start: tuple[int, float, float] | None = None):
        """The forward pass from knot k on: (its result, b, a)."""
        q_n = self.cells[0].size - k
        b, a = np.empty(q_n + 1), np.empty(q_n + 1)
        cells = (x[k:] for x in self.cells)
        got = forward(*cells, *(start or self.start), *self.end, *(x[k:] for x in self.sets),
                      b, a)
        return got, b, a


def part(case: Case, k: int, m: int, start, end) -> Case:
    h, g0, gm, g1, knot, mid, floors, lims = case.cells
    cells = (h[k:m], g0[k:m], gm[k:m], g1[k:m], knot[k:m + 1], mid[k:m], floors[k:m + 1],
             lims[k:m])
    return Case(tuple(np.ascontiguousarray(x) for x in cells), start, end)


@pytest.fixture(scope="module")
def full() -> Case:
    """The curve's one stretch, rest to rest, linearised at the speed estimate."""
    lim = DEFAULT.limits
    layout = captured_layout(CURVE, lim)
    lin = rs._estimate(layout, lim)
    none = np.zeros(lin.size, dtype=bool)
    s = rs._Stretch(layout, 0, 0, lin, none, lim, none)
    lims = np.repeat(rs.limits_vector(lim)[None, :], s.q_n, axis=0)
    cells = (s.h, s.g0, s.gm, s.g1, s.lin_knot, s.lin_mid, np.zeros(s.q_n + 1), lims)
    return Case(cells, s.start, s.end)


@pytest.fixture(scope="module", params=["rests", "moving"])
def case(request, full: Case) -> Case:
    """The whole stretch, or cells 10 to 40 of it, ending in the motion's state at knot 40 and
    starting in the middle of its own set at knot 0 (a chain's window, moving at both ends)."""
    if request.param == "rests":
        return full
    _, b, a = full.run()
    moving = part(full, 10, 40, (END_MOVING, 0.0, 0.0), (END_MOVING, b[40], a[40]))
    la, hi, lo = moving.set_at(0)
    a0 = 0.5 * (la[0] + la[-1])
    moving.start = (END_MOVING, float(np.interp(a0, la, 0.5 * (hi + lo))), float(a0))
    return moving


def assert_keeps_rows(case: Case, k: int, b: np.ndarray, a: np.ndarray) -> None:
    """Every row of every cell from knot k on at the motion (b, a) (with u = a' / h)."""
    h = case.cells[0][k:]
    u = np.diff(a) / h
    for j, rows in enumerate(case.rows[k:]):
        terms = rows[:, :3] * np.array([b[j], a[j], u[j]])
        excess = terms.sum(axis=1) - rows[:, 3]
        scale = np.abs(terms).sum(axis=1) + np.abs(rows[:, 3])
        assert np.all(excess <= ROW_REL * scale), (k + j, np.max(excess / scale))


def assert_meets_end(case: Case, b: np.ndarray, a: np.ndarray) -> None:
    kind, p1, p2 = case.end
    if kind == END_REST:  # a = -2 b / (3 h_rest) beside the rest, b within the rest cell's cap
        scale = 3.0 * p1 * abs(a[-2]) + 2.0 * b[-2]
        assert abs(3.0 * p1 * a[-1] + 2.0 * b[-1]) <= 1e-9 * scale
        assert 0.0 <= b[-1] <= p2 * (1.0 + 1e-9)
    else:
        assert a[-1] == pytest.approx(p2, rel=1e-9, abs=1e-9 * abs(a[-2]))
        assert abs(b[-1] - p1) <= MOVING_END_REL * p1 * (1.0 + 1e-6)


def test_a_state_inside_a_set_has_a_way_on(case: Case) -> None:
    """From states inside a knot's levels (their corners, edges and random insides), the
    forward pass over the rest of the stretch gets through, keeps every row of every cell and
    meets the end (the sets are an inner approximation: states on their edges included)."""
    rng = np.random.default_rng(7)
    q_n = case.cells[0].size
    for k in sorted(set(range(0, q_n, 3)) | set(range(q_n - 4, q_n))):
        la, hi, lo = case.set_at(k)
        shares = [(0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0), *rng.random((4, 2))]
        for share_a, share_b in shares:
            a = min(la[0] + share_a * (la[-1] - la[0]), la[-1])  # not past it by rounding
            low, high = np.interp(a, la, lo), np.interp(a, la, hi)
            b = low + share_b * (high - low)
            got, b_out, a_out = case.run(k, (END_MOVING, b, a))
            assert got == -1, (k, b, a)
            assert b_out[0] == b and a_out[0] == a
            assert_keeps_rows(case, k, b_out, a_out)
            assert_meets_end(case, b_out, a_out)


def reach_lp(case: Case, k: int, objective: str, a_fixed: float | None = None) -> float:
    """The controllable set at knot k as one linear program over the states and u of every
    cell from k on (the cells' rows, b' = 2 a and a' = u between knots, and the end's own
    relation): max ('b+', 'a+') or min ('b-', 'a-') of b or a there (at a = a_fixed); NaN
    where no state has a way on."""
    h = case.cells[0][k:]
    rows = case.rows[k:]
    m = h.size
    nb = m + 1
    nv = 2 * nb + m  # b_0..b_m, a_0..a_m, u_0..u_m-1
    counts = np.array([r.shape[0] for r in rows])
    cell = np.repeat(np.arange(m), counts)
    stacked = np.vstack(rows)
    line = np.repeat(np.arange(cell.size), 3)
    cols = np.column_stack([cell, nb + cell, 2 * nb + cell]).ravel()
    a_ub = sp.csr_matrix((stacked[:, :3].ravel(), (line, cols)), shape=(cell.size, nv))
    j = np.arange(m)
    eq_rows = np.concatenate([np.repeat(2 * j, 4), np.repeat(2 * j + 1, 3)])
    eq_cols = np.concatenate([np.column_stack([j + 1, j, nb + j, 2 * nb + j]).ravel(),
                              np.column_stack([nb + j + 1, nb + j, 2 * nb + j]).ravel()])
    eq_vals = np.concatenate([np.column_stack([np.ones(m), -np.ones(m), -2.0 * h, -h * h]).ravel(),
                              np.column_stack([np.ones(m), -np.ones(m), -h]).ravel()])
    bounds: list[tuple[float | None, float | None]] = [(None, None)] * nv
    kind, p1, p2 = case.end
    if kind == END_REST:
        eq_rows = np.append(eq_rows, [2 * m, 2 * m])
        eq_cols = np.append(eq_cols, [2 * nb - 1, nb - 1])
        eq_vals = np.append(eq_vals, [3.0 * p1, 2.0])
        bounds[nb - 1] = (0.0, p2)
    else:
        bounds[2 * nb - 1] = (p2, p2)
        bounds[nb - 1] = (p1 * (1.0 - MOVING_END_REL), p1 * (1.0 + MOVING_END_REL))
    a_eq = sp.csr_matrix((eq_vals, (eq_rows, eq_cols)), shape=(eq_rows.max() + 1, nv))
    if a_fixed is not None:
        bounds[nb] = (a_fixed, a_fixed)
    at = 0 if objective[0] == "b" else nb
    c = np.zeros(nv)
    c[at] = -1.0 if objective[1] == "+" else 1.0
    res = linprog(c, A_ub=a_ub, b_ub=stacked[:, 3], A_eq=a_eq, b_eq=np.zeros(a_eq.shape[0]),
                  bounds=bounds, method="highs")
    return float(res.x[at]) if res.status == 0 else math.nan


def test_a_set_holds_only_states_with_a_way_on_and_nearly_all_of_them(case: Case) -> None:
    """Against the linear program over the same rows: at every level of the last six knots
    and of every ninth, the set's upper boundary is at most the program's greatest b, its lower
    one at least the least b, its accelerations within the program's range; and the set is
    nearly the whole of it: within 2 % at the last six knots (b 1.05 times the upper boundary
    has no way on there), within 5 % at 80 % of the levels of the others, where chords between
    levels cut off more of what the next knot's chords already cut off (at the top of a set's
    range of accelerations its boundary is near vertical, and most of it can go)."""
    q_n = case.cells[0].size
    tail = range(q_n - 6, q_n)
    near = []
    for k in sorted(set(range(0, q_n - 6, 9)) | set(tail)):
        la, hi, lo = case.set_at(k)
        a_range = reach_lp(case, k, "a-"), reach_lp(case, k, "a+")
        assert a_range[0] - 1e-9 <= la[0] and la[-1] <= a_range[1] + 1e-9
        for i in range(la.size):
            top = reach_lp(case, k, "b+", la[i])
            assert hi[i] <= top * (1.0 + 1e-6), (k, la[i], hi[i], top)
            if k in tail:
                bottom = reach_lp(case, k, "b-", la[i])
                assert lo[i] >= bottom - 1e-6 * top, (k, la[i], lo[i], bottom)
                assert hi[i] >= 0.98 * top, (k, la[i], hi[i], top)
                assert lo[i] <= bottom + 0.05 * top, (k, la[i], lo[i], bottom)
            else:
                near.append(1.05 * hi[i] >= top)
    assert np.mean(near) >= 0.8


def test_the_forward_motion_keeps_its_rows_its_sets_and_its_ends(case: Case) -> None:
    """The forward pass over the stretch: its start is the start's state (or, from a rest, on
    the rest cell's ray a = 2 b / (3 h_rest) within its cap), each cell's b quadratic and a
    linear (b_j+1 = b_j + h (a_j + a_j+1)), every row of every cell kept at u = (a_j+1 - a_j) /
    h, each knot's state inside that knot's set, and the end met."""
    got, b, a = case.run()
    assert got == -1
    kind, p1, p2 = case.start
    if kind == END_REST:
        assert a[0] == pytest.approx(2.0 * b[0] / (3.0 * p1), rel=1e-12)
        assert 0.0 < b[0] <= p2
    else:
        assert (b[0], a[0]) == (p1, p2)
    h = case.cells[0]
    assert np.allclose(b[1:], b[:-1] + h * (a[:-1] + a[1:]), rtol=0.0, atol=1e-9 * b.max())
    assert_keeps_rows(case, 0, b, a)
    for j in range(h.size):
        la, hi, lo = case.set_at(j)
        assert la[0] <= a[j] <= la[-1]
        low, high = np.interp(a[j], la, lo), np.interp(a[j], la, hi)
        assert low * (1.0 - SET_REL) <= b[j] <= high * (1.0 + SET_REL), (j, b[j], low, high)
    assert_meets_end(case, b, a)


# ---- the highest state both sets hold ----------------------------------------------------------

def random_levels(rng: np.random.Generator, width: int) -> tuple[np.ndarray, ...]:
    """A set's levels: up to `width` accelerations in [-1, 1], its upper boundary concave, its
    lower one convex (0 or above), kept where the one is above the other (possibly nowhere)."""
    a = np.unique(rng.uniform(-1.0, 1.0, rng.integers(1, width + 1)))
    hi = rng.uniform(1.0, 3.0) - rng.uniform(0.2, 3.0) * (a - rng.uniform(-1.0, 1.0)) ** 2
    lo = np.maximum(rng.uniform(0.2, 3.0) * (a - rng.uniform(-1.0, 1.0)) ** 2
                    - rng.uniform(0.5, 3.0), 0.0)
    inside = np.flatnonzero(lo <= hi)
    keep = slice(inside[0], inside[-1] + 1) if inside.size else slice(0, 0)
    return a[keep], hi[keep], lo[keep]


def highest_exactly(ks, rs_, use_lower: bool = True) -> float:
    """The greatest min(K_hi(a), R_hi(-a)) where max(K_lo, R_lo) <= min(K_hi, R_hi), over every
    level of either and every crossing of any two of the four boundaries between them (linear
    there: the greatest lies at one of those); without use_lower, the lower ones are ignored."""
    ka, khi, klo = ks
    ra, rhi, rlo = -rs_[0][::-1], rs_[1][::-1], rs_[2][::-1]
    if ka.size == 0 or ra.size == 0 or max(ka[0], ra[0]) > min(ka[-1], ra[-1]):
        return 0.0
    first, last = max(ka[0], ra[0]), min(ka[-1], ra[-1])
    points = np.unique(np.concatenate([[first, last], ka, ra]))
    points = points[(points >= first) & (points <= last)]
    lines = [(ka, khi), (ka, klo), (ra, rhi), (ra, rlo)]
    values = np.array([np.interp(points, x, y) for x, y in lines])
    found = [points]
    for p in range(4):
        for q in range(p + 1, 4):
            d = values[p] - values[q]
            cross = np.flatnonzero(d[:-1] * d[1:] < 0.0)
            found.append(points[cross] + (points[cross + 1] - points[cross])
                         * d[cross] / (d[cross] - d[cross + 1]))
    x = np.concatenate(found)
    k_hi, k_lo, r_hi, r_lo = (np.interp(x, xs, ys) for xs, ys in lines)
    top = np.minimum(k_hi, r_hi)
    ok = np.maximum(k_lo, r_lo) <= top + 1e-12 if use_lower else np.ones(x.size, dtype=bool)
    return float(top[ok].max()) if ok.any() else 0.0


def run_highest(k_sets: list, r_sets: list, width: int) -> np.ndarray:
    def padded(sets, i):
        return np.array([np.pad(s[i], (0, width - s[i].size)) for s in sets])

    out = np.empty(len(k_sets))
    highest(padded(k_sets, 0), padded(k_sets, 1), padded(k_sets, 2),
            np.array([s[0].size for s in k_sets]), padded(r_sets, 0), padded(r_sets, 1),
            padded(r_sets, 2), np.array([s[0].size for s in r_sets]), out)
    return out


@pytest.mark.parametrize("seed", range(4))
def test_the_highest_state_two_sets_share_is_found_where_their_tops_meet(seed: int) -> None:
    """Random level sets K and R (R's knots reversed, its accelerations negated, as highest
    reads them): the result never exceeds the exact top of what both hold, and is that top
    wherever the highest point of the lower upper boundary is inside both sets (most of the
    cases: the lower boundaries do not cut it off); a fine grid finds nothing higher."""
    rng = np.random.default_rng(seed)
    width, knots = 8, 6
    uncut = 0
    for _ in range(40):
        k_sets = [random_levels(rng, width) for _ in range(knots)]
        r_sets = [random_levels(rng, width) for _ in range(knots)]
        out = run_highest(k_sets, r_sets, width)
        for j in range(knots):
            ks, rr = k_sets[j], r_sets[knots - 1 - j]
            exact = highest_exactly(ks, rr)
            assert out[j] <= exact + 1e-12
            if exact > 0.0:
                grid = np.linspace(max(ks[0][0], -rr[0][-1]), min(ks[0][-1], -rr[0][0]), 2001)
                k_hi, r_hi = np.interp(grid, ks[0], ks[1]), np.interp(-grid, rr[0], rr[1])
                k_lo, r_lo = np.interp(grid, ks[0], ks[2]), np.interp(-grid, rr[0], rr[2])
                top = np.minimum(k_hi, r_hi)
                inside = np.maximum(k_lo, r_lo) <= top
                assert top[inside].max(initial=0.0) <= exact + 1e-12
            if exact == highest_exactly(ks, rr, use_lower=False):
                uncut += 1
                assert out[j] == pytest.approx(exact, rel=1e-12, abs=1e-12)
    assert uncut >= 0.8 * 40 * knots


def test_the_highest_state_is_found_where_a_lower_boundary_cuts_the_top() -> None:
    """One knot. K: levels at a = 0, 1, b in [0, 1] and [2.5, 3]; R (reversed): at -a = 1, 0,
    b in [0, 2] and [0, 1.5]. min(K_hi, R_hi) = min(1 + 2 a, 1.5 + 0.5 a) rises to 2 at a = 1,
    but K_lo = 2.5 a cuts it at a = 0.75: the top is 1.875 there, between two levels and not
    where the upper boundaries cross (a = 1 / 3, b = 5 / 3)."""
    k = (np.array([0.0, 1.0]), np.array([1.0, 3.0]), np.array([0.0, 2.5]))
    r = (np.array([-1.0, 0.0]), np.array([2.0, 1.5]), np.array([0.0, 0.0]))
    assert highest_exactly(k, r) == pytest.approx(1.875, rel=1e-12)
    assert run_highest([k], [r], 2)[0] == pytest.approx(1.875, rel=1e-9)


# ---- the end folded into the last cell ---------------------------------------------------------

@pytest.mark.parametrize("kind", [END_REST, END_MOVING, END_MOVING_LOOSE])
def test_folded_end_rows_hold_exactly_where_the_cell_keeps_its_rows_and_meets_the_end(
        kind: int) -> None:
    """Random rows over (b, a, u) and states (b, a), some near the end's line: the folded rows
    (u = 0 in them) hold where the cell's rows hold with the u the end fixes and the end is met
    (a moving end: a = p2 there and b within MOVING_END_REL (LOOSE_END_REL) of p1; a rest: a =
    -2 b / (3 h_rest) there, with u solved from that, b in [0, p2]), and only there."""
    rng = np.random.default_rng(kind)
    h, n = 0.05, 8
    rows = rng.normal(size=(n, 4))
    rows[:, 3] = 40.0 * np.abs(rows[:, 0]) + 400.0 * np.abs(rows[:, 1]) + 4e3 * np.abs(
        rows[:, 2]) * rng.uniform(0.3, 1.0, n)
    p1, p2 = (0.03, 60.0) if kind == END_REST else (25.0, rng.uniform(-500.0, 500.0))
    out = np.empty((n + 2, 4))
    m = fold_end(rows, n, h, kind, p1, p2, out)
    assert m == n + 2 and np.all(out[:m, 2] == 0.0)
    thick = (MOVING_END_REL if kind == END_MOVING else LOOSE_END_REL) * p1
    seen = {True: 0, False: 0}
    for _ in range(4000):
        a = rng.uniform(-800.0, 800.0)
        if kind == END_REST:
            b = rng.uniform(0.0, 80.0)
            u = -(2.0 * b + (4.0 * h + 3.0 * p1) * a) / (2.0 * h * h + 3.0 * p1 * h)
            assert u == pytest.approx(-(b + (2.0 * h + 1.5 * p1) * a) / (h * h + 1.5 * p1 * h))
        else:
            b = p1 - h * (a + p2) + thick * rng.uniform(-2.0, 2.0)
            u = (p2 - a) / h
        b_end, a_end = b + 2.0 * h * a + h * h * u, a + h * u
        if kind == END_REST:
            assert abs(3.0 * p1 * a_end + 2.0 * b_end) <= 1e-9 * (p1 * abs(a) + b + 1.0)
            margins = [b_end, p2 - b_end]
        else:
            assert a_end == pytest.approx(p2, abs=1e-9 * abs(a))
            margins = [thick - abs(b_end - p1)]
        margins.extend(rows[:, 3] - rows[:, :3] @ np.array([b, a, u]))
        folded = out[:m, 3] - out[:m, :2] @ np.array([b, a])
        if min(np.abs(margins).min(), np.abs(folded).min()) < 1e-9 * (abs(b) + abs(a) + 1.0):
            continue  # on an edge, rounding decides
        holds = bool(np.all(folded > 0.0))
        assert holds == (min(margins) > 0.0), (b, a)
        seen[holds] += 1
    assert min(seen.values()) >= 200  # both sides sampled, not only the far inside


# ---- a motion's time ---------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(6))
def test_a_motions_time_is_the_integral_of_ds_over_its_speed(seed: int) -> None:
    """Random cells, b quadratic on each (b' = 2 a continuous at the knots), and rest cells at
    each end (b = b_end y^(4/3), y the share of the rest cell) or none (a moving end): the time
    is the integral of ds / sqrt(b), by adaptive quadrature, within 0.1 % (eight Gauss points
    a cell, where b may fall to 1/2000 of its peak: the passes compare motions by it, the
    stepper times the law itself)."""
    rng = np.random.default_rng(seed)
    q_n = int(rng.integers(1, 9))
    h = rng.uniform(0.01, 2.0, q_n)
    while True:
        b = rng.uniform(1.0, 400.0, q_n + 1)
        a = np.empty(q_n + 1)
        a[0] = rng.uniform(-100.0, 100.0)
        for j in range(q_n):
            a[j + 1] = (b[j + 1] - b[j]) / h[j] - a[j]
        x = np.linspace(0.0, 1.0, 101)[:, None] * h
        inner = b[:-1] + x * (2.0 * a[:-1] + np.diff(a) / h * x)
        if inner.min() > 0.2:
            break
    start_h, end_h = rng.choice([0.0, rng.uniform(0.01, 1.0)], 2)
    want = 0.0
    for j in range(q_n):
        u = (a[j + 1] - a[j]) / h[j]
        want += quad(lambda s, j=j, u=u: 1.0 / math.sqrt(b[j] + 2.0 * a[j] * s + u * s * s),
                     0.0, h[j], epsabs=0.0, epsrel=1e-13)[0]
    for rest_h, b_end in ((start_h, b[0]), (end_h, b[-1])):
        if rest_h > 0.0:  # y^(-2/3) / sqrt(b_end) over the cell, its singularity weighted
            want += rest_h / math.sqrt(b_end) * quad(lambda y: 1.0, 0.0, 1.0, weight="alg",
                                                     wvar=(-2.0 / 3.0, 0.0))[0]
    assert motion_time(h, b, a, start_h, end_h) == pytest.approx(want, rel=1e-3)


# ---- the jerk rows' tangent --------------------------------------------------------------------

@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.floats(1.0, 1e6), st.one_of(st.just(0.0), st.floats(1e-3, 1e4)),
       st.floats(1e-14, 1e8))
def test_the_jerk_tangent_lies_below_the_limit_and_touches_it(limit: float, jump: float,
                                                              b0: float) -> None:
    """|L| <= J / sqrt(b) - sqrt(b) jump, linearised at b0 (or at J / jump, where the limit
    is 0, if b0 is beyond it; at least B_FLOOR): the row's bound - slope b is at most the limit
    for every b > 0 and equal to it, with the same slope, where it was taken; b = 0 keeps it."""
    slope, bound = jerk_tangent(limit, jump, b0)
    at = max(min(b0, limit / jump) if jump > 0.0 else b0, B_FLOOR)

    def exact(b):
        return limit / np.sqrt(b) - np.sqrt(b) * jump

    b = np.concatenate([np.geomspace(1e-16, 1e12, 4001), at * (1.0 + np.linspace(-0.1, 0.1, 21))])
    assert np.all(bound - slope * b <= exact(b) + 1e-12 * (limit / np.sqrt(b) + np.sqrt(b) * jump))
    assert bound - slope * at == pytest.approx(exact(at), abs=1e-12 * limit / math.sqrt(at))
    assert slope == pytest.approx(0.5 * limit / at**1.5 + 0.5 * jump / math.sqrt(at), rel=1e-12)
    assert bound > 0.0


# ---- rounding on a straight piece ----------------------------------------------------------------

def test_an_axis_a_straight_piece_does_not_move_has_no_rows() -> None:
    """On a straight piece along Y, T's X part, K and K_s are rounding (1e-16): X's rows would
    have a u coefficient of 1e-16, which bounds a1 by terms of 1e17 whose rounding alone is
    100 mm/s^2. Every row there has a u coefficient of 0 or at least 1e-12."""
    g = np.zeros(G_SIZE)
    g[G_T:G_T + 3] = (-4.7e-16, 1.0, 0.0)
    g[G_KS:G_KS + 3] = (-4.1e-16, -1.9e-31, 0.0)
    g[G_CAP] = 1e4
    rows = np.empty((ROWS_PER_CELL, 4))
    lims = rs.limits_vector(DEFAULT.limits)
    n = cell_rows(g, g, g, 0.15, 2800.0, 3100.0, 3400.0, 0.0, 0.0, lims, rows)
    cu = np.abs(rows[:n, 2])
    assert np.all((cu == 0.0) | (cu >= 1e-12)), cu
    assert np.count_nonzero(cu) > 0  # the path's and Y's jerk rows stay


def test_a_line_along_an_axis_after_a_bend_is_planned_near_the_reference() -> None:
    """40 mm along X, a bend, 40 mm along Y at 100 mm/s: X's rounding rows on the Y leg left
    the sets there no motion, and the curve fell back to the S-curve plan (1.109 s against the
    reference's 0.976 s). The path planner plans it within 1 % of the reference."""
    lim = dataclasses.replace(DEFAULT.limits, feed_mm_s=100.0)
    plan = plan_curve(BEND, lim)
    assert plan.planner == "optimal" and plan.schedule is not None
    reference = jerk_limited_schedule(BEND, lim, np.empty(0), np.empty(0))
    assert plan.cycle_time_s <= 1.01 * reference.cycle_s, (plan.cycle_time_s, reference.cycle_s)


def test_toolpaths_along_the_axes_are_planned_by_the_path_planner() -> None:
    """72 toolpaths as CAM writes them (legs along the axes, corners and cusps; the other axes'
    parts of T rounding, 1e-15): every one planned by the path planner under the default
    profile. Before the rounding counted as 0 in the axes' rows, 4 of these (9 of the first
    150) found no motion in the sets of a straight leg and took the S-curve plan."""
    planners = {curve.name: plan_curve(curve, dataclasses.replace(
        DEFAULT.limits, feed_mm_s=min(feed, DEFAULT.limits.feed_mm_s))).planner
        for curve, feed in axis_toolpaths(72)}
    assert set(planners.values()) == {"optimal"}, {k: v for k, v in planners.items()
                                                   if v != "optimal"}


def test_two_cusps_5_um_apart_leave_a_stretch_the_nodes_can_cut() -> None:
    """A quadratic that runs back on itself twice within 5 um (an axis toolpath whose leg turns
    back): the stretch between the two cusps has no grid node, so its inserted nodes took a
    speed estimate of 0 and were cut past any count (no nodes: the S-curve plan under
    paper-table1's limits, 2.883 s). They take the speed constant jerk reaches from the nearer
    rest; the path planner plans the curve."""
    corners = np.array([[0.0, 0.0, 0.0], [-0.8004416712036622, 0.0, 0.0],
                        [19.800541455598662, 0.0, 0.0],
                        [19.800541455598662, 14.122384980634308, 0.0],
                        [19.800541455598662, -11.446062832005119, 0.0],
                        [-6.9706723319728106, -11.446062832005119, 0.0],
                        [-2.879696649237042, -11.446062832005119, 0.0]])
    points = [corners[0]]
    for a, b in zip(corners[:-1], corners[1:]):
        points += [a + t * (b - a) for t in (1 / 3, 2 / 3)] + [b]
    knots = np.concatenate([np.zeros(3), np.linspace(0.0, 1.0, 18)[1:-1], np.ones(3)])
    curve = NurbsCurve.build(2, knots, np.array(points), None, "two-cusps")
    lim = load_machine("paper-table1", {"jerk_model": "path", "planner": "optimal"}).limits
    plan = plan_curve(curve, dataclasses.replace(lim, feed_mm_s=60.0))
    assert plan.planner == "optimal"
    assert np.count_nonzero(plan.key_kind == KIND_CUSP) >= 2  # both cusps rest


def test_a_set_narrower_than_the_fine_probes_is_found() -> None:
    """A toolpath whose straight leg meets a 0.1 um turn at a knot (kappa 9,400 /mm; the motion
    passes at 0.03 mm/s on cells of half a micrometre): the set of the knot before the turn
    spans less in a than the fine probes' spacing, and none of them met it; probed at a = 0
    and at the next knot's levels, it is found, and the path planner plans the curve (it took
    the S-curve plan, 3.669 s; 3.515 s now) under paper-table1's limits."""
    curve, feed = axis_toolpaths(76)[75]
    lim = load_machine("paper-table1", {"jerk_model": "path", "planner": "optimal"}).limits
    plan = plan_curve(curve, dataclasses.replace(lim, feed_mm_s=min(feed, lim.feed_mm_s)))
    assert plan.planner == "optimal"
    assert plan.cycle_time_s < 3.6


@pytest.mark.parametrize("feed_mm_min", [6.84, 10.0])
def test_cells_cut_for_time_keep_the_faster_schedule(feed_mm_min: float) -> None:
    """Fuzz seed 3116's degree-4 curve at a few mm/min: its 14 um hairpin (|C'| 7.5 % of its
    mean) is passed at rest, and the first schedule dwells in one cell beside it; on the cells
    cut there the plan crept into the rest cell at 4e-5 mm/s, 14 s more (111.0 s at F10). The
    motion cruises at the feed but for milliseconds either side of the rest: its cycle is the
    length over the feed, within 0.2 %."""
    spec = json.loads((ROOT / "tests" / "data" / "path_planner" / "hairpin-at-rest-low-feed.json")
                      .read_text())["curves"][0]
    curve = NurbsCurve.build(spec["degree"], np.array(spec["knots"], dtype=float),
                             np.array(spec["control_points"]), np.array(spec["weights"]), "crawl")
    feed = feed_mm_min / 60.0
    plan = plan_curve(curve, load_machine("default").limits, np.array([curve.u_min]),
                      np.array([feed]))
    length = quad(lambda u: float(np.linalg.norm(curve.derivatives(np.array([u]))[1][0])),
                  curve.u_min, curve.u_max, points=list(np.unique(curve.knots)), limit=200)[0]
    assert length / feed <= plan.cycle_time_s <= 1.002 * length / feed
