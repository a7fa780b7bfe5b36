"""The path planner (`planner: optimal`, the default profile's; planning.cells, reach_rows,
reach_schedule, schedule_law): its rows against the limits they stand for, its law against its
schedule, its cycle against closed forms, the reference and the S-curve planner, the limits
measured from its points, and the check from the points before writing with its fallback.
The kernels of its sets and passes have tests of their own (tests/test_reach_planner.py)."""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nurbsfeed.analysis.bound.solve import jerk_limited_schedule
from nurbsfeed.analysis.check import check_files
from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file, plan_block, verified_plan
from nurbsfeed.planning.basis import G_CAP, G_D, point_weights
from nurbsfeed.planning.plan import PathDiagnostics, SCurveDiagnostics
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.planning.ratios import point_ratio
from nurbsfeed.planning.reach_rows import NORMAL_SIDES, ROWS_PER_CELL, cell_rows, limits_vector
from nurbsfeed.safety import slowdown_from_points
from tests.bench.dense_curves import _long_cam_curve, dense_curves
from tests.test_bound import scurve_rest_to_rest_s
from tests.test_degenerate import EXAMPLES, degenerate_curves
from tests.test_path_model import assert_keeps_every_path_limit

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data" / "path_planner"
DEFAULT = load_machine("default")
PAPER_PATH = load_machine("paper-table1", {"jerk_model": "path", "planner": "optimal"})
# the bound on the cycle over the jerk-limited reference (measured: 0.97-1.016)
REFERENCE_BOUND = 1.03


def scurve_of(lim):
    return dataclasses.replace(lim, planner="scurve")


def sample_block(name: str):
    [block] = curve_blocks(ROOT / "samples" / name)
    return block


def dense_curve(name: str) -> NurbsCurve:
    return next(c for c in dense_curves(quick=True) if c.name == name)


# ---- the solver, against HiGHS ----------------------------------------------------------------

# ---- the rows, against the limits -------------------------------------------------------------

def layout_and_schedule(curve: NurbsCurve, lim):
    """The layout and schedule plan_path makes of `curve`, by planning it."""
    from nurbsfeed.planning import path_plan

    made = {}
    original = path_plan.plan_schedule

    def keep(layout, lim_, *args):
        made["schedule"] = original(layout, lim_, *args)
        return made["schedule"]

    path_plan.plan_schedule = keep
    try:
        plan_curve(curve, lim)
    finally:
        path_plan.plan_schedule = original
    return made["schedule"].layout, made["schedule"]


def rows_at(layout, lim, c):
    """Every cell's rows (planning.reach_rows) linearised at the schedule c itself, and their
    left sides at its motion: b, a = b'/2 and u = b''/2 at each cell's start. (left, rhs)."""
    limits = limits_vector(lim)
    rows = np.empty((ROWS_PER_CELL, 4))
    w = np.empty((3, 3))
    left, rhs = [], []
    for q in range(layout.cells.shape[0]):
        i0 = int(layout.cells[q, 0])
        b_at = []
        for x in (0.0, 0.5, 1.0):
            point_weights(*layout.cells[q, 1:5], x, w)
            b_at.append(max(float(w[0] @ c[i0:i0 + 3]), 1e-12))
        point_weights(*layout.cells[q, 1:5], 0.0, w)
        b, d, dd = w @ c[i0:i0 + 3]
        g = layout.geo[q]
        n = cell_rows(g[0], g[1], g[2], layout.cells[q, 4], *b_at, 0.0, 0.0, limits, rows)
        left.append(rows[:n, :3] @ np.array([b, 0.5 * d, 0.5 * dd]))
        rhs.append(rows[:n, 3].copy())
    return np.concatenate(left), np.concatenate(rhs)


def worst_point_ratio(geo, layout, lim, c) -> float:
    w = np.empty((3, 3))
    worst = 0.0
    for q in range(layout.cells.shape[0]):
        i0 = int(layout.cells[q, 0])
        for p in range(3):
            point_weights(*layout.cells[q, 1:5], 0.5 * p, w)
            b, d, dd = w @ c[i0:i0 + 3]
            worst = max(worst, point_ratio(
                geo[q, p], b, d, dd, lim.jerk_mm_s3, lim.acc_mm_s2,
                lim.normal_jerk_mm_s3, np.array(lim.axis_acc_mm_s2),
                np.array(lim.axis_vel_mm_s), np.array(lim.axis_jerk_mm_s3), lim.period_s))
    return worst


@pytest.mark.parametrize("name", ["star", "helix"])
def test_rows_that_hold_keep_every_limit_and_every_limit_kept_nearly_holds_them(
        name: str) -> None:
    """Linearised at the schedule itself, the rows are the limits (the normal jerk's polygon
    inscribed, cos(pi / 16) of them): the schedule keeps its rows and every limit; scaled up
    until its tightest limit binds, its rows break by at most the polygon's share, and scaled
    past that every schedule breaks a row."""
    lim = DEFAULT.limits
    layout, schedule = layout_and_schedule(dense_curve(name), lim)
    c = np.asarray(schedule.c)
    left, rhs = rows_at(layout, lim, c)
    assert np.all(left <= rhs + 1e-6 * np.abs(rhs) + 1e-9)
    assert 0.98 < worst_point_ratio(layout.geo, layout, lim, c) <= 1.0 + 1e-6  # fast: it binds
    uncapped = layout.geo.copy()
    uncapped[:, :, G_CAP] = np.inf  # scaled past the caps, the other limits bind
    ratio = worst_point_ratio(uncapped, layout, lim, c)
    capless = dataclasses.replace(layout, geo=uncapped)
    for lam in (1.0 / ratio, 1.05 / ratio):
        left, rhs = rows_at(capless, lim, c * lam**2)
        bounded = rhs > 0.0
        excess = float(np.max(left[bounded] / rhs[bounded]))
        if lam * ratio <= 1.0:
            assert excess <= 1.0 / math.cos(math.pi / NORMAL_SIDES) + 1e-6
        else:
            assert excess > 1.0


# ---- the law, against its schedule ------------------------------------------------------------

@pytest.mark.parametrize("name", ["figure-eight-cusps", "tiny-star"])
def test_the_law_passes_through_the_schedule_at_every_period(name: str) -> None:
    """At each period inside the inner cells the law's speed is the schedule's at the law's arc
    (b = v^2 read back from the spline there), over one factor per stretch: the stretch's time
    stretched to whole periods (>= 1, at most a period over the stretch's duration); no step is
    longer than its speeds allow."""
    lim = DEFAULT.limits
    curve = dense_curve(name)
    layout, schedule = layout_and_schedule(curve, lim)
    law = plan_curve(curve, lim).law
    s, v, t = law.s0_mm, law.v0_mm_s, law.t0_s
    node = layout.cell_node
    q = np.clip(np.searchsorted(layout.s_mm[node], s, side="right") - 1, 0, node.size - 1)
    share = (s - layout.s_mm[node[q]]) / layout.cells[q, 4]
    inside = (share >= 0.0) & (share <= 1.0) & (v > 1e-3 * lim.feed_mm_s)
    w = np.empty((3, 3))
    ratio = np.full(s.size, np.nan)
    for k in np.flatnonzero(inside):
        i0 = int(layout.cells[q[k], 0])
        point_weights(*layout.cells[q[k], 1:5], share[k], w)
        ratio[k] = math.sqrt(max(w[0] @ schedule.c[i0:i0 + 3], 0.0)) / v[k]
    stretch = np.searchsorted(law.key_t_s, t, side="right") - 1
    for j in np.unique(stretch[inside]):
        r = ratio[inside & (stretch == j)]
        duration = law.key_t_s[j + 1] - law.key_t_s[j]
        assert r.min() >= 1.0 - 1e-3 and r.max() <= 1.0 / (1.0 - lim.period_s / duration) + 1e-3
        assert r.max() - r.min() <= 1e-3 * r.max()
    steps = np.diff(s)
    assert np.all(steps <= np.maximum(v[:-1], v[1:]) * lim.period_s * 1.01 + 1e-9)


# ---- cycle time -------------------------------------------------------------------------------

@pytest.mark.parametrize("length_mm", [0.5, 5.0, 50.0, 300.0])
def test_a_straight_line_runs_within_1_percent_of_the_closed_form(length_mm: float) -> None:
    """Along a line the path model is the S-curve's own: the optimum is the closed form. The
    plan is never below it, within 1 % and a period above it, and faster than the S-curve
    planner, whose acceleration and jerk are 75 % of the limits under the path model."""
    line = NurbsCurve.build(1, [0, 0, 1, 1], [[0, 0, 0], [length_mm, 0, 0]])
    lim = PAPER_PATH.limits
    exact = scurve_rest_to_rest_s(length_mm, lim.feed_mm_s, lim.acc_mm_s2, lim.jerk_mm_s3)
    plan = plan_curve(line, lim)
    assert plan.planner == "optimal"
    assert exact * (1 - 1e-9) <= plan.cycle_time_s <= exact * 1.01 + lim.period_s
    assert plan_curve(line, scurve_of(lim)).cycle_time_s > plan.cycle_time_s


def test_each_planner_hands_on_its_own_diagnostics() -> None:
    """What only `nurbsfeed plan` reads comes in the planner's own record: the path planner's
    (its keys are its rests) the passes over its sets and a peak per stretch, the S-curve
    planner's a speed per key point and a peak and holds per segment."""
    line = NurbsCurve.build(1, [0, 0, 1, 1], [[0, 0, 0], [50.0, 0, 0]])
    lim = PAPER_PATH.limits
    path = plan_curve(line, lim)
    assert path.planner == "optimal" and isinstance(path.diagnostics, PathDiagnostics)
    assert path.diagnostics.passes >= 2  # a backward and a forward one at least
    assert path.diagnostics.stretch_peak_mm_s.shape == path.piece_periods.shape
    assert 0.9 * lim.feed_mm_s < path.diagnostics.stretch_peak_mm_s[0] <= lim.feed_mm_s
    scurve = plan_curve(line, scurve_of(lim))
    record = scurve.diagnostics
    assert scurve.planner == "scurve" and isinstance(record, SCurveDiagnostics)
    assert record.key_nominal_mm_s.shape == record.key_v_mm_s.shape == scurve.key_node.shape
    assert (record.seg_peak_mm_s.shape == record.seg_hold_start_mm.shape
            == record.seg_hold_end_mm.shape == (scurve.key_node.size - 1,))
    assert record.seg_peak_mm_s[0] == pytest.approx(lim.feed_mm_s)


@pytest.mark.parametrize(("name", "machine"), [("quarter-circle.json", PAPER_PATH),
                                               ("butterfly.json", DEFAULT),
                                               ("figure-eight", PAPER_PATH),
                                               ("tiny-star", DEFAULT)])
def test_curves_run_within_3_percent_of_the_reference(name: str, machine) -> None:
    """The reference (analysis.bound, code of its own) keeps every limit, so the optimum is no
    slower than it: the plan is within 3 % of it (measured 0.995, 1.016, 0.976, 1.009), where
    the S-curve planner is 4 % to 50 % above."""
    if name.endswith(".json"):
        block = sample_block(name)
        curve, feed_u, feed = block.curve, block.feed_u, block.feed_mm_s
    else:
        curve, feed_u, feed = dense_curve(name), np.empty(0), np.empty(0)
    lim = machine.limits
    plan = plan_curve(curve, lim, feed_u, feed)
    # the butterfly's and the tiny star's under the default take minutes: their reference
    # cycles as `python -m tests.bench.reference` prints them
    reference = ({"butterfly.json": 3.6883, "tiny-star": 0.5341}.get(name)
                 or jerk_limited_schedule(curve, lim, feed_u, feed).cycle_s)
    assert plan.planner == "optimal" and plan.uniform_slowdown <= 1.01
    assert plan.cycle_time_s <= REFERENCE_BOUND * reference, (plan.cycle_time_s, reference)
    assert plan.cycle_time_s < plan_curve(curve, scurve_of(lim), feed_u, feed).cycle_time_s


def test_a_cam_curve_of_many_spans_is_planned_by_the_optimal_planner() -> None:
    """tests/bench/dense_curves.py's 32-point CAM curve (a row pass drove b to 0 inside a
    stretch of the planner before this one): planned here, far faster than the S-curve plan,
    its points within every limit."""
    curve = _long_cam_curve(32)
    plan = verified_plan(curve, DEFAULT.limits, np.empty(0), np.empty(0))
    assert plan.planner == "optimal"
    assert plan.cycle_time_s < 0.8 * plan_curve(curve, scurve_of(DEFAULT.limits)).cycle_time_s
    assert_keeps_every_path_limit(interpolate(plan, "rk2c"), DEFAULT.limits, curve.name)


def test_a_knot_where_a_curve_meets_a_line_passes_at_the_speed_its_jump_allows() -> None:
    """tests/data/check-turns/retrace-cusp-inch.json: kappa jumps from 0.019 /mm to 0 at a knot.
    The jump entered the jerk rows as b |D| / T (a jerk sqrt(b) times its own), the schedule
    came to a near stop at the knot, its law jumped 0.27 mm in one period there, and the plan
    fell back to the S-curve's, slowed 510 times (1,405 s). Now the jump's tangent is in the
    rows: the path planner's plan, 2.47 s, keeps every limit from its points."""
    from nurbsfeed.pipeline import read_program
    from nurbsfeed.program import CurveBlock

    [block] = [item.in_mm() for item in read_program(
        ROOT / "tests" / "data" / "check-turns" / "retrace-cusp-inch.json", "auto")
        if isinstance(item, CurveBlock)]
    plan = plan_block(block, DEFAULT)
    assert plan.planner == "optimal" and plan.uniform_slowdown <= 1.0 + 1e-9  # rounding aside
    assert plan.cycle_time_s < 3.0
    points = interpolate(plan, "rk2c").points
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    assert steps.max() <= DEFAULT.limits.feed_mm_s * DEFAULT.limits.period_s * (1 + 1e-3)
    assert_keeps_every_path_limit(interpolate(plan, "rk2c"), DEFAULT.limits, "retrace")


def test_a_joint_feed_step_narrower_than_any_cell_does_not_stall_the_planner() -> None:
    """samples/linuxcnc-g5-chain.ngc: each joint's curvature jump caps the feed over 1e-9 of the
    chain's range, and cells that narrow made the programs' rows so stiff that none solved; the
    start stood in, slowed 15 times (29.7 s for 39 mm). Cells of at least a millionth of the
    length merge the step into the joint's node, whose cap keeps it."""
    from nurbsfeed.chains import ChainWindow, chain_items
    from nurbsfeed.pipeline import chain_block, read_program

    [window] = [item for item in chain_items(iter(read_program(
        ROOT / "samples" / "linuxcnc-g5-chain.ngc", "auto")), DEFAULT)
        if isinstance(item, ChainWindow)]
    block, _, found = chain_block(window, DEFAULT.limits)
    assert np.all(np.isfinite(found.cap_mm_s))  # the joints are capped
    plan = plan_block(block, DEFAULT)
    assert plan.planner == "optimal" and plan.uniform_slowdown <= 1.0 + 1e-9  # rounding aside
    assert plan.cycle_time_s < 2.1  # 2.001 s; the curves planned apart rest at the joints


# ---- the limits, measured from the points -----------------------------------------------------

@pytest.mark.parametrize("curve", dense_curves(quick=True), ids=lambda c: c.name)
def test_dense_curves_keep_every_limit_measured_from_their_points(curve: NurbsCurve) -> None:
    """Every path and per-axis quantity from the interpolation points within FROM_POSITIONS of
    its limit and the motion guard passes them, under the default profile; never slower than
    the S-curve planner."""
    plan = verified_plan(curve, DEFAULT.limits, np.empty(0), np.empty(0))
    assert plan.planner == "optimal"
    assert plan.cycle_time_s <= plan_curve(curve, scurve_of(DEFAULT.limits)).cycle_time_s
    assert_keeps_every_path_limit(interpolate(plan, "rk2c"), DEFAULT.limits, curve.name)


@settings(max_examples=max(8, EXAMPLES // 20), deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(degenerate_curves(), st.sampled_from([100.0, 200.0]))
def test_random_curves_keep_every_limit_and_never_lose_to_the_scurve_planner(
        curve: NurbsCurve, feed_mm_s: float) -> None:
    """Repeated control points, corners, extreme weights, under the default's limits: the
    verified plan is no slower than the S-curve planner's (which stands in where the path
    planner cannot plan), its points keep every limit and the guard passes them."""
    lim = dataclasses.replace(DEFAULT.limits, feed_mm_s=feed_mm_s)
    plan = verified_plan(curve, lim, np.empty(0), np.empty(0))
    assert plan.cycle_time_s <= plan_curve(curve, scurve_of(lim)).cycle_time_s * (1 + 1e-9)
    assert_keeps_every_path_limit(interpolate(plan, "rk2c"), lim, curve.name)


# ---- the check from the points before writing, and its fallback -------------------------------

def test_the_slowdown_from_points_reads_each_difference_against_its_limit() -> None:
    """Points along X at constant acceleration a: second differences a T^2 exactly, so the
    slowdown asked is sqrt(a / A_x) when a is above A_x, and 1 below it (the jerk within its
    limit, the speeds within limits raised out of the way)."""
    lim = dataclasses.replace(DEFAULT.limits, feed_mm_s=1e9, axis_vel_mm_s=(1e9, 1e9, 1e9))
    t = np.arange(30) * lim.period_s
    for acc, expected in ((4 * lim.axis_acc_mm_s2[0], 2.0), (0.5 * lim.axis_acc_mm_s2[0], 1.0)):
        points = np.zeros((t.size, 3))
        points[:, 0] = 0.5 * acc * t**2
        chunks = [points[:7], points[7:8], points[8:]]  # the differences span the chunks
        speed, rest = slowdown_from_points(lim, chunks)
        assert speed == 1.0 and rest == pytest.approx(expected, rel=1e-9)


def test_the_slowdown_from_points_reads_the_path_speed_against_the_feed() -> None:
    """Points along the diagonal of X and Y at 1.002 times the feed: each axis moves at 0.71 of
    it, within its velocity limit, and the speed asked is the path's, 1.002; the accelerations
    and jerks ask nothing."""
    lim = dataclasses.replace(DEFAULT.limits, feed_mm_s=10.0)
    step = 1.002 * lim.feed_mm_s * lim.period_s / np.sqrt(2.0)
    points = np.zeros((20, 3))
    points[:, 0] = points[:, 1] = step * np.arange(20)
    speed, rest = slowdown_from_points(lim, [points])
    assert speed == pytest.approx(1.002, rel=1e-12) and rest == 1.0


def test_a_speed_above_the_feed_by_less_than_the_acceleration_margin_is_slowed(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Fuzz seed 58 (case 497): a law at a programmed 0.1 mm/s stepped to 0.100101 mm/s, 0.1 %
    over, which the verification from the points let pass (its margin, 0.5 %, is the
    accelerations') and the motion guard refused (its margin on a speed is 0.1 %). A speed
    above the feed by more than half the guard's margin slows the law by what it asks."""
    import nurbsfeed.verified as verified

    asked = iter([(1.001, 1.0), (1.0, 1.0)])
    monkeypatch.setattr(verified, "slowdown_from_readings", lambda lim, readings: next(asked))
    curve = NurbsCurve.build(3, [0, 0, 0, 0, 1, 1, 1, 1],
                             [[0, 0, 0], [10, 5, 0], [20, -5, 0], [30, 0, 0]])
    lim = DEFAULT.limits
    plain = plan_curve(curve, lim)
    plan = verified_plan(curve, lim, np.empty(0), np.empty(0))
    assert plan.cycle_time_s >= 1.001 * plain.cycle_time_s * (1.0 - 1e-3)
    assert plan.uniform_slowdown >= 1.001 * plain.uniform_slowdown


def test_a_low_feed_leaves_its_rests_as_fast_as_the_scurve_plan() -> None:
    """Fuzz seed 58 (case 497, at F60 here): a grid whose first interval beside the start is 1.2
    mm long and whose last one is short. Each end has nodes of its own beside its rest, the
    first no longer than constant jerk takes to reach the feed: the plan is within 0.05 % of
    the S-curve plan (the feed all along, 23.165 s)."""
    block = curve_blocks(DATA / "low-feed-start.json")[0]
    plan = plan_curve(block.curve, DEFAULT.limits, block.feed_u, block.feed_mm_s)
    scurve = plan_curve(block.curve, scurve_of(DEFAULT.limits), block.feed_u, block.feed_mm_s)
    assert plan.planner == "optimal"
    assert plan.cycle_time_s <= 1.0005 * scurve.cycle_time_s


def test_a_stretch_of_one_node_between_two_rests_converts_quietly(tmp_path: Path) -> None:
    """Fuzz seed 57 (case 870): repeated control points put a single grid node between two
    rests (a planner before this one divided by their zero distance, and the valid program was
    refused). It converts, with no warning, and check passes it."""
    name = "single-node-stretch.nc"
    out = tmp_path / "out.nc"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no division by zero reaches stderr either
        convert_file(DATA / name, out, DEFAULT)
    report = check_files(DATA / name, out, DEFAULT)
    assert report.ok, "\n".join(map(str, report.violations))


@pytest.mark.parametrize("name", ["axis-jerk-from-positions-a.ngc",
                                  "axis-jerk-from-positions-b.ngc",
                                  "scurve-fallback-slowed.ngc"])
def test_a_program_whose_plans_once_broke_a_limit_from_their_points_converts_within_them(
        tmp_path: Path, name: str) -> None:
    """Fuzz seeds 50 (cases 11 and 268) and 52 (case 385): plans whose laws kept every limit
    sampled twice a period but whose points, one period apart, jerked 5.5 %, 17.7 % and 15 %
    above an axis's limit. Each program converts, check passes it, and each curve's points ask
    no slowdown beyond the margin of the check from the points."""
    out = tmp_path / "out.nc"
    convert_file(DATA / name, out, DEFAULT)
    report = check_files(DATA / name, out, DEFAULT)
    assert report.ok, "\n".join(map(str, report.violations))
    for block in curve_blocks(DATA / name):
        plan = plan_block(block, DEFAULT)
        points = interpolate(plan, "rk2c").points
        speed, rest = slowdown_from_points(dataclasses.replace(plan.limits, feed_mm_s=np.inf),
                                           [points])
        assert speed <= 1.0 and rest <= 1.005


def test_jumps_reach_the_rows_only_at_knots() -> None:
    """The jump term sits at the points on a knot where kappa N jumps, nowhere else (the
    butterfly is C2 at its knots: none)."""
    lim = DEFAULT.limits
    layout, _ = layout_and_schedule(sample_block("butterfly.json").curve, lim)
    assert not np.any(layout.geo[:, :, G_D:G_D + 3])


def test_a_stretch_too_short_for_its_own_knots_is_planned_by_the_scurve_planner(
        tmp_path: Path) -> None:
    """Fuzz seed 60 (gcode-6000188-981): the second curve rests twice within a few millionths
    of its length, a stretch no node can be added to (nodes closer than 10^-6 of the length
    are one), and the layout indexed its empty cells: an internal error. That curve is the
    S-curve planner's now, the first the path planner's; the program converts and check passes
    it."""
    name = "two-rests-a-hair-apart.ngc"
    out = tmp_path / "out.nc"
    convert_file(DATA / name, out, DEFAULT)
    report = check_files(DATA / name, out, DEFAULT)
    assert report.ok, "\n".join(map(str, report.violations))
    planners = [plan_block(block, DEFAULT).planner for block in curve_blocks(DATA / name)]
    assert planners == ["optimal", "scurve"]
