"""The path planner's unit, a chain with its state given at its two ends (planner.chain_schedule,
design §3b): a curve cut in two at a node of its own plan and each part planned with the
whole plan's state at the cut meets the whole plan (the same state, about the same cycle), keeps
every limit, and keeps the state it was given; a state that breaks a limit, or that asks to
move where the curve must rest, is not planned."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import POSITION_REL
from nurbsfeed.planning.basis import AT_REST, BETWEEN, POINTS, ChainEnds, EndState, point_weights
from nurbsfeed.planning.path_plan import END_SLACKS_REL, end_slack_mm
from nurbsfeed.planning.planner import chain_schedule
from nurbsfeed.planning.ratios import cell_ratios
from tests.bench.dense_curves import dense_curves
from tests.cut_curves import cut

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = load_machine("default")
PAPER_PATH = load_machine("paper-table1", {"jerk_model": "path", "planner": "optimal"})
NONE = np.empty(0)
# the two parts' cycles over the whole's (measured: 0.9997-1.0056, the star's parts losing
# most at its slow tips): each part is planned on nodes and sets of its own, inner
# approximations of another size, so neither is the whole's restriction exactly
CYCLE_REL = 0.01


def curve_named(name: str) -> NurbsCurve:
    if name.endswith(".json"):
        [block] = curve_blocks(ROOT / "samples" / name)
        return block.curve
    return next(c for c in dense_curves(quick=True) if c.name == name)


def state_at(schedule, share: float) -> tuple[float, float, float, float]:
    """The schedule's (u, s, b, b') at the start of the inner cell nearest `share` of its
    length (a node of its own: its b and b' are the spline's there, exactly)."""
    layout = schedule.layout
    node = layout.cell_node
    q = int(np.argmin(np.abs(layout.s_mm[node] - share * layout.s_mm[-1])))
    w = np.empty((3, 3))
    point_weights(*layout.cells[q, 1:5], 0.0, w)
    i0 = int(layout.cells[q, 0])
    b, d, _ = w @ np.asarray(schedule.c)[i0:i0 + 3]
    return float(layout.u[node[q]]), float(layout.s_mm[node[q]]), float(b), float(d)


def seed_of(schedule, s_cut: float, side: int, overlap_mm: float):
    """The schedule's nodes and coefficients over overlap_mm after (side 0) or before (side 1)
    the cut at s_cut, on the part's own arc (path_plan.plan_path's seed): inner knots only."""
    layout = schedule.layout
    knots = layout.cell_node[1:]  # the inner cells' knots, rest cells' aside
    s = layout.s_mm[knots]
    lo, hi = (s_cut, s_cut + overlap_mm) if side == 0 else (s_cut - overlap_mm, s_cut)
    nodes = s[(s >= lo - 1e-12) & (s <= hi + 1e-12)]
    origin = s_cut if side == 0 else 0.0
    inside = (layout.xi > nodes[0]) & (layout.xi < nodes[-1])
    return (nodes - origin, layout.xi[inside] - origin, np.asarray(schedule.c)[inside])


def halves(curve: NurbsCurve, u: float) -> tuple[NurbsCurve, NurbsCurve]:
    """The curve cut at its stored parameter u into two curves (the same path)."""
    a, b = cut(curve.degree, curve.knots, curve.points, curve.weights, [u])
    return (NurbsCurve.build(a.degree, a.knots, a.points, a.weights, "first"),
            NurbsCurve.build(b.degree, b.knots, b.points, b.weights, "second"))


def worst_ratio(schedule, lim, points=POINTS, away_mm: float = 0.0) -> float:
    """The largest slowdown any limit asks at the schedule's cell points (<= 1: all kept),
    the moving end's own point left out (its state is the one given), and the cells within
    away_mm of a moving end."""
    layout = schedule.layout
    geo = layout.geo if points is POINTS else layout.between
    out = np.empty(layout.cells.shape[0])
    cell_ratios(np.asarray(schedule.c), layout.cells, geo, np.array(points), lim.jerk_mm_s3,
                lim.acc_mm_s2, lim.normal_jerk_mm_s3, np.array(lim.axis_acc_mm_s2, dtype=float),
                np.array(lim.axis_vel_mm_s, dtype=float),
                np.array(lim.axis_jerk_mm_s3, dtype=float), lim.period_s, out)
    keep = np.ones(out.size, dtype=bool)
    keep[0] &= not layout.moving[0]
    keep[-1] &= not layout.moving[1]
    at = layout.s_mm[layout.cell_node]
    if layout.moving[0]:
        keep &= at > layout.s_mm[0] + away_mm
    if layout.moving[1]:
        keep &= at < layout.s_mm[-1] - away_mm
    return float(out[keep].max())


@pytest.mark.parametrize(("name", "machine", "share"), [
    ("butterfly.json", DEFAULT, 0.5),
    ("butterfly.json", DEFAULT, 0.27),
    ("helix", DEFAULT, 0.5),
    ("star", PAPER_PATH, 0.4),
    ("figure-eight", PAPER_PATH, 0.6),
])
def test_a_curve_cut_in_two_and_planned_from_the_whole_plans_state_meets_the_whole_plan(
        name: str, machine, share: float) -> None:
    lim = machine.limits
    curve = curve_named(name)
    whole = chain_schedule(curve, lim, NONE, NONE, AT_REST)
    assert whole is not None
    u, s_cut, b, d = state_at(whole.schedule, share)
    state = EndState(math.sqrt(b), d / 2.0)
    first, second = halves(curve, u)
    overlap = 0.2 * whole.schedule.layout.s_mm[-1]
    before = chain_schedule(first, lim, NONE, NONE, ChainEnds(end=state),
                            seed_of(whole.schedule, s_cut, 1, overlap))
    after = chain_schedule(second, lim, NONE, NONE, ChainEnds(start=state),
                           seed_of(whole.schedule, s_cut, 0, overlap))
    assert before is not None and after is not None
    for part in (before, after):
        assert part.slowdown <= 1.0 + 1e-6
        # every limit kept, but within the braking distance of the cut: a part that finds no
        # way from (into) a state the whole plan rides its limits in there is planned with
        # them loosened by one of END_SLACKS_REL (an acceleration's share is the square of a
        # speed's)
        assert worst_ratio(part.schedule, lim, away_mm=end_slack_mm(lim)) <= 1.0 + 1e-6
        assert worst_ratio(part.schedule, lim) <= math.sqrt(1.0 + max(END_SLACKS_REL)) + 1e-6
        # between the points the programs read, within what the conversion's look at the
        # points holds every plan to
        assert worst_ratio(part.schedule, lim, BETWEEN) <= 1.0 + POSITION_REL
    # the state at the cut, as each part's spline holds it: b and the polygon's slope
    c, xi = np.asarray(before.schedule.c), before.schedule.layout.xi
    assert c[-1] == pytest.approx(b, rel=1e-12)
    assert (c[-1] - c[-2]) / (xi[-1] - xi[-2]) == pytest.approx(d, rel=1e-9, abs=1e-9)
    c, xi = np.asarray(after.schedule.c), after.schedule.layout.xi
    assert c[0] == pytest.approx(b, rel=1e-12)
    assert (c[1] - c[0]) / (xi[1] - xi[0]) == pytest.approx(d, rel=1e-9, abs=1e-9)
    # ... and as their laws start and end: at that speed
    assert after.law.v0_mm_s[0] == pytest.approx(state.speed_mm_s, rel=1e-12)
    _, _, v_end, _, _ = before.law.sample(np.array([before.law.duration_s]))
    assert v_end[0] == pytest.approx(state.speed_mm_s, rel=1e-9)
    # the whole plan's restriction to each part is a schedule for it, and the two parts
    # joined are one for the whole (C1 at the cut): the optimum is the same, within nodes
    total = before.schedule.cycle_s + after.schedule.cycle_s
    assert abs(total / whole.schedule.cycle_s - 1.0) <= CYCLE_REL, (total, whole.schedule.cycle_s)


def test_a_chain_that_starts_moving_ends_at_rest_on_a_whole_period_and_holds_it() -> None:
    """Its law is not stretched (that would change the speed it starts at): where its last
    period would end before the next whole one, the rest is held up to it, in a piece of its
    own with no motion; a chain that ends moving ends within a share of a period."""
    lim = DEFAULT.limits
    curve = curve_named("helix")
    whole = chain_schedule(curve, lim, NONE, NONE, AT_REST)
    u, _, b, d = state_at(whole.schedule, 0.5)
    first, second = halves(curve, u)
    state = EndState(math.sqrt(b), d / 2.0)
    after = chain_schedule(second, lim, NONE, NONE, ChainEnds(start=state))
    law = after.law
    periods = law.duration_s / lim.period_s
    assert periods == pytest.approx(round(periods), abs=1e-9)
    piece, local, v, _, _ = law.sample(np.array([law.duration_s]))
    assert law.s0_mm[piece[0]] + local[0] == pytest.approx(after.schedule.layout.s_mm[-1],
                                                            rel=1e-12)
    assert abs(v[0]) < 1e-9
    held = law.duration_s - law.t0_s[-1] < lim.period_s * (1.0 - 1e-9)  # a hold of its own
    if held:
        assert law.v0_mm_s[-1] == 0.0 and law.jerk_mm_s3[-1] == 0.0
    assert np.all(np.diff(law.s0_mm) >= 0.0) and np.all(law.v0_mm_s >= 0.0)
    before = chain_schedule(first, lim, NONE, NONE, ChainEnds(end=state))
    ends_at = before.law.duration_s / lim.period_s
    assert 0.0 <= math.ceil(ends_at) - ends_at < 1.0
    assert np.all(np.diff(before.law.t0_s) > 0.0)


def test_a_state_a_chain_cannot_keep_is_not_planned() -> None:
    """The butterfly's start allows 47 mm/s under the default (its chord error and normal
    acceleration): 50 mm/s there, or an acceleration above the limit, is refused (None: the
    caller plans otherwise), never slowed into another state; 30 mm/s is planned."""
    lim = DEFAULT.limits
    curve = curve_named("butterfly.json")
    assert chain_schedule(curve, lim, NONE, NONE, ChainEnds(start=EndState(50.0, 0.0))) is None
    assert chain_schedule(curve, lim, NONE, NONE,
                          ChainEnds(start=EndState(30.0, 2.0 * lim.acc_mm_s2))) is None
    assert chain_schedule(curve, lim, NONE, NONE, ChainEnds(end=EndState(50.0, 0.0))) is None
    made = chain_schedule(curve, lim, NONE, NONE, ChainEnds(start=EndState(30.0, 0.0)))
    assert made is not None and made.law.v0_mm_s[0] == pytest.approx(30.0)


def test_a_chain_may_not_move_at_an_end_where_its_curve_must_rest() -> None:
    """A curve whose tangent turns back at its end (a zero of C' there: the curve stops)
    cannot end moving: not planned."""
    # a cubic whose last two control points coincide: C'(1) = 0
    cusp = NurbsCurve.build(3, [0, 0, 0, 0, 1, 1, 1, 1],
                            [[0, 0, 0], [10, 5, 0], [20, 0, 0], [20, 0, 0]])
    lim = DEFAULT.limits
    assert chain_schedule(cusp, lim, NONE, NONE, AT_REST) is not None
    assert chain_schedule(cusp, lim, NONE, NONE, ChainEnds(end=EndState(5.0, 0.0))) is None
    assert chain_schedule(cusp, lim, NONE, NONE, ChainEnds(start=EndState(5.0, 0.0))) is not None
