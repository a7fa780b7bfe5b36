"""Degenerate geometry (repeated control points, corners, cusps, reversals, zero-length spans):
never a wild move.

Each file of tests/data/degenerate/ is one case with what it must produce: where the motion
rests (stops, with their kind), and that the motion measured from positions (tests/motion_check)
keeps the profile. A hypothesis property does the same over random curves built to contain such
places: every point on the curve, at rest at every stop, no limit exceeded from positions, and
the written program arriving where and when the plan does.
"""

from __future__ import annotations

import dataclasses
import io
import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from nurbsfeed.analysis.check import check_files
from nurbsfeed.cli import main
from nurbsfeed.gcode.writer import MoveWriter
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.plan import KIND_CORNER, KIND_CUSP, KIND_NAMES
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.readers import read_program
from tests.conftest import default_paper_limits, load_curve
from tests.motion_check import FD_REL, motion, written_moves

CASES = Path(__file__).parent / "data" / "degenerate"
DEFAULT = load_machine("default").limits  # the path model, with per-axis limits
PAPER = default_paper_limits()  # the same path limits under the paper model
# At rest: the moves on either side of a stop are at most this long (v <= 1 mm/s at 1 ms).
REST_MOVE_MM = 1e-3
# Hypothesis examples of the random-curve property, the same ones on every run of the suite;
# NURBSFEED_PROPERTY_EXAMPLES above 300 makes a long run with random (or --hypothesis-seed) ones.
EXAMPLES = int(os.environ.get("NURBSFEED_PROPERTY_EXAMPLES", "300"))


def load(name: str) -> NurbsCurve:
    return load_curve(name, CASES)


# file -> the stops the plan must find, as (u, kind), and the length of the path
EXPECTED = {
    # a quadratic written P0 P0 P2 with weights 1, 0.544, 1 is a straight line; once written
    # as ONE G1 at F1.7e6 (|C'(0)| was 1.8e-15, not 0, and kappa 9.9e30 there)
    "repeated-start-weighted": ([], None),
    # ... and, at u = 0.33488, a hairpin of radius 4 um (|C'| 2 % of its mean, not 0), a turn
    # back passed at rest (the minimum of |C'|, by dense sampling, is the stop)
    "repeated-end-weighted": ([(0.3348761921, "cusp")], None),
    # a control point repeated `degree` times with simple knots: C' = 0 there, the path turns
    # by 90 degrees (G0 continuity written the usual NURBS way)
    "corner-tripled-point": ([(0.5, "corner")], 40.0),
    # a line that turns back on itself at u = 0.5: C' = 0 and the tangent reverses
    "reversal-on-a-line": ([(0.5, "cusp")], 20.0),
    # a cubic Bezier with a cusp at u = 0.5 (x' = 3 (1 - 2u)^2, y' = 3 - 6u, times 10)
    "cubic-cusp": ([(0.5, "cusp")], None),
    # x = 10 (2u - 1)^3 on a line: C'(0.5) = 0 but the path goes straight through: no stop
    "removable-zero-on-a-line": ([], 20.0),
    # four equal control points: the span [0.4, 0.6] has zero length, one corner
    "zero-length-span": ([(0.4, "corner")], None),
    # a rational reversal just before a knot, where |C'| falls on through the samples around it
    # (found by the tangent turning back between them; once taken at 39,000 mm/s^2)
    "reversal-between-samples": ([(0.0494847550, "cusp")], None),
    # a double knot with the control point there repeated on both sides: C' = 0 from both
    "double-knot-corner-repeated-point": ([(0.5, "corner")], 20.0),
    # weights 1e-3 beside the ends (the envelope's ratio of 1000): a hook at each end and a near
    # corner in the middle (at 1e-5, outside the envelope now, the whole segment was once capped
    # at the hook's limit: 5e6 s)
    "weights-near-zero": ([], None),
    # a weight of 1e3 in the middle: three sharp peaks close together
    "weight-1e3": ([], None),
    # a 2 um reversal at the start, then out along x and back 2 um aside: a turn of ~5 nm
    # radius (kappa 2e8; C' small but not 0), once held at 1e-5 mm/s for 2.6 s (1.38 s without
    # shoulders today); its far end at x = 26.44 is a turn back of |C'| 1e-4 of its mean (kappa
    # 2e8), passed at rest at the minimum of |C'| (by dense sampling)
    "near-cusp-beside-repeated-points": ([(0.1, "cusp"), (0.3307692308, "cusp")], None),
    # a corner at a C0 knot beside a near cusp (|C'| 1 % of its mean, kappa 4e6) that the samples
    # at 200 mm/s step over: once planned at 1,097 s (the whole law slowed 3,183-fold); the near
    # cusp turns back, and rests at the minimum of |C'| (by dense sampling)
    "spike-finer-than-the-samples": ([(0.0450000057, "cusp"), (0.05, "corner")], None),
}
# file -> the most its plan may take under the default's limits and the paper model at 100 mm/s (s)
CYCLE_AT_MOST_S = {"weights-near-zero": 0.6, "weight-1e3": 0.7,
                   "near-cusp-beside-repeated-points": 0.8}


def assert_motion_within(points: np.ndarray, lim: Limits) -> None:
    """Speed and accelerations from positions keep the profile (tests/motion_check)."""
    m = motion(points, lim.period_s)
    assert np.isfinite(points).all()
    assert m.speed_mm_s.max() <= lim.feed_mm_s * (1 + 1e-6)
    assert m.tangential_acc_mm_s2.max() <= lim.acc_mm_s2 * (1 + FD_REL)
    assert m.normal_acc_mm_s2.max() <= lim.normal_acc_mm_s2 * (1 + FD_REL)


def assert_rests_at(points: np.ndarray, u: np.ndarray, curve: NurbsCurve,
                    stop_u: float) -> None:
    """A point falls on the stop, and the moves on either side are at rest. The point is the
    one nearest in parameter among those on the stop's place (a path may pass the same place
    twice); where the curve stays put over a stretch of parameters (repeated control points),
    it may lie at the stretch's other end, so the curve between the two must not move."""
    at = curve.point(stop_u)
    on = np.flatnonzero(np.linalg.norm(points - at, axis=1) <= 1e-9)
    assert on.size > 0, "no point on the stop"
    k = int(on[np.argmin(np.abs(u[on] - stop_u))])
    between = curve.point(np.linspace(min(stop_u, u[k]), max(stop_u, u[k]), 101))
    assert np.linalg.norm(between - at, axis=1).max() <= 1e-9
    assert 0 < k < len(points) - 1
    steps = np.linalg.norm(np.diff(points[k - 1:k + 2], axis=0), axis=1)
    assert steps.max() <= REST_MOVE_MM, steps


@pytest.mark.parametrize("model", ["paper", "path"])
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_degenerate_case(name: str, model: str) -> None:
    curve = load(name)
    stops, length_mm = EXPECTED[name]
    plan = plan_curve(curve, dataclasses.replace(PAPER if model == "paper" else DEFAULT,
                                                  feed_mm_s=100.0))
    found = [(float(plan.key_u[k]), KIND_NAMES[int(plan.key_kind[k])])
             for k in range(plan.key_u.size) if plan.key_kind[k] in (KIND_CORNER, KIND_CUSP)]
    assert [kind for _, kind in found] == [kind for _, kind in stops]
    assert [u for u, _ in found] == pytest.approx([u for u, _ in stops], abs=1e-9)
    if length_mm is not None:
        assert plan.length_mm == pytest.approx(length_mm, rel=1e-9)
    if model == "paper":  # (the path model's cycles are longer: it keeps the jerk it feels)
        assert plan.cycle_time_s <= CYCLE_AT_MOST_S.get(name, np.inf)
    result = interpolate(plan)
    assert result.n_points == plan.n_periods + 1
    np.testing.assert_array_equal(result.points[0], curve.points[0])
    np.testing.assert_array_equal(result.points[-1], curve.points[-1])
    assert_motion_within(result.points, plan.limits)
    for stop_u, _ in stops:
        assert_rests_at(result.points, result.u, curve, stop_u)
    # the path is followed: no step longer than the feed allows (the collapse wrote one G1)
    assert result.n_points >= plan.length_mm / (plan.limits.feed_mm_s * plan.limits.period_s)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_plan_names_the_stops(name: str) -> None:
    """`nurbsfeed plan` lists each stop by kind, and its time-optimal bound is finite even
    across a zero-length span (warnings are errors in the tests)."""
    result = CliRunner().invoke(main, ["plan", str(CASES / f"{name}.json")],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.output
    rows = [line.split() for line in result.output.splitlines() if line[:6].strip().isdigit()]
    kinds = [row[1] for row in rows if row[1] in ("corner", "cusp")]
    assert kinds == [kind for _, kind in EXPECTED[name][0]]
    assert "time-optimal bound" in result.output and "nan" not in result.output


def test_a_spike_finer_than_the_samples_is_a_rest_not_a_slowdown() -> None:
    """At 200 mm/s the samples are 0.4 mm apart and step over the near cusp; the grid finds it
    (a turn back, so a rest), instead of a uniform slowdown of the whole law."""
    plan = plan_curve(load("spike-finer-than-the-samples"), PAPER)
    assert plan.cycle_time_s < 0.6
    assert plan.time_scale < 1.01


def test_removable_zero_is_passed_at_speed() -> None:
    """The straight line through a removable zero of C' is not slowed there: its cycle is the
    one of a plain straight 20 mm line."""
    through = plan_curve(load("removable-zero-on-a-line"), DEFAULT)
    line = plan_curve(NurbsCurve.build(1, [0, 0, 1, 1], [[-10, 0], [10, 0]]), DEFAULT)
    assert through.cycle_time_s == pytest.approx(line.cycle_time_s, abs=2 * DEFAULT.period_s)


# the strategies drawn from, built once (hypothesis validates every new one at its first draw)
DEGREES, DISTINCT_POINTS = st.integers(2, 4), st.integers(2, 6)
COORDS = st.floats(-30, 30, allow_nan=False).map(lambda x: round(x, 3))
COPIES = {degree: st.sampled_from([1, 1, 1, 2, degree, degree + 1]) for degree in (2, 3, 4)}
WEIGHTS = st.sampled_from([1.0, 1.0, 0.5, 2.0, 0.2, 5.0])


@st.composite
def degenerate_curves(draw) -> NurbsCurve:
    """Curves of degree 2-4 with runs of repeated control points (up to degree + 1 copies, at
    the ends too), random weights, and knots of full multiplicity (corners) at random."""
    degree = draw(DEGREES)
    n_distinct = draw(DISTINCT_POINTS)
    distinct = [[draw(COORDS), draw(COORDS)] for _ in range(n_distinct)]
    points = []
    for p in distinct:
        points.extend([p] * draw(COPIES[degree]))
    if len(points) < degree + 1:
        points.extend([distinct[-1]] * (degree + 1 - len(points)))
    n = len(points)
    inner = sorted(draw(st.lists(st.integers(1, 19), min_size=n - degree - 1,
                                 max_size=n - degree - 1)))
    for i in range(len(inner) - degree + 1):  # at most `degree` equal interior knots
        if len(set(inner[i:i + degree])) == 1 and i + degree < len(inner):
            assume(inner[i + degree] != inner[i])
    knots = [0] * (degree + 1) + [k / 20 for k in inner] + [1] * (degree + 1)
    weights = [draw(WEIGHTS) for _ in range(n)]
    curve = NurbsCurve.build(degree, knots, points, weights)
    assume(not curve.is_degenerate)
    return curve


@settings(max_examples=EXAMPLES, deadline=None, derandomize=EXAMPLES <= 300,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(degenerate_curves(), st.sampled_from([20.0, 100.0, 200.0]),
       st.sampled_from([PAPER, DEFAULT]))
def test_random_degenerate_curves_move_on_the_curve_within_the_limits(curve, feed_mm_s,
                                                                       limits) -> None:
    lim = dataclasses.replace(limits, feed_mm_s=feed_mm_s)
    plan = plan_curve(curve, lim)
    assume(plan.n_periods < 40_000)  # keep the example fast; long plans are no different
    result = interpolate(plan)
    points = result.points
    # every point on the curve: C(u_k), the ends exactly; the point before a stop may lie a hair
    # past it in u, on the span before it extrapolated: its distance to the curve near u_k
    off = np.linalg.norm(points - curve.point(result.u), axis=1)
    for k in np.flatnonzero(off > 1e-9):
        near = curve.point(np.clip(result.u[k] + np.linspace(-0.05, 0.05, 100001), 0.0, 1.0))
        assert np.linalg.norm(near - points[k], axis=1).min() <= 1e-5, (k, off[k])
    np.testing.assert_array_equal(points[-1], curve.points[-1])
    assert result.n_points == plan.n_periods + 1
    assert_motion_within(points, lim)
    for k in np.flatnonzero(np.isin(plan.key_kind, (KIND_CORNER, KIND_CUSP))):
        assert_rests_at(points, result.u, curve, float(plan.key_u[k]))
    # the written program: each point within the output rounding of the point due at its
    # time (from the written lengths and F words), and arriving when the plan ends
    out = io.BytesIO()
    writer = MoveWriter(out, 4, 3, lim.period_s, "\n", points[0])
    writer.write_curve(points)
    written, period = written_moves(out.getvalue().decode(), points[0], lim.period_s)
    rounding_mm = 0.5e-4 * np.sqrt(3)
    assert period[-1] == plan.n_periods
    assert np.all(np.diff(period) >= 1)
    deviation = np.linalg.norm(written - points[period], axis=1)
    assert deviation.max() <= rounding_mm * (1 + 1e-9)


def test_a_reversal_beside_a_double_knot_is_a_stop(tmp_path: Path) -> None:
    """Fuzzer find: a cubic along X (all its points on the X axis) turns back three times, once
    just before a knot of multiplicity 2, where C'' jumps: Gauss-Newton from the middle of the
    samples around it ran to the knot and stayed, the stop was missed, and the stepping crossed
    the turn within one period (6474 mm/s^2 from positions; the motion guard refused the
    curve). Every sign change of x'(u), found here by dense sampling, must be a stop node."""
    source = CASES / "double-knot-reversal.nc"
    curves = [item.curve for item in read_program(source) if hasattr(item, "curve")]
    curve = curves[2]  # the third curve lies on the X axis: a sign change of x' is a reversal
    flips = x_reversals(curve)
    assert flips.size == 3
    assert_stops_at_and_check_passes(source, curve, flips, tmp_path)


def x_reversals(curve: NurbsCurve) -> np.ndarray:
    """The parameters where a curve lying on the X axis turns back: the sign changes of x'(u),
    by dense sampling."""
    assert np.all(curve.points[:, 1:] == 0.0)
    u = np.linspace(curve.u_min, curve.u_max, 2_000_001)
    dx = curve.derivatives(u)[1][:, 0]
    return u[np.flatnonzero(np.sign(dx[:-1]) * np.sign(dx[1:]) < 0)]


def assert_stops_at_and_check_passes(source: Path, curve: NurbsCurve, flips: np.ndarray,
                                     tmp_path: Path) -> None:
    """Under the default profile every parameter of `flips` is a stop node of the curve's
    plan (within 1e-6), and `source` converts to a program `check` passes."""
    machine = load_machine("default")
    plan = plan_curve(curve, machine.limits)
    stops = plan.grid.u[plan.grid.stop_index]
    for flip in flips:
        assert np.min(np.abs(stops - flip)) <= 1e-6, (flip, stops)
    target = tmp_path / "out.nc"
    convert_file(source, target, machine)
    report = check_files(source, target, machine)
    assert report.ok, "\n".join(map(str, report.violations))


def test_a_corner_across_a_zero_length_span_of_a_closed_curve_is_a_stop(tmp_path: Path) -> None:
    """Fuzzer find (seed 32): a rational polyline (degree 1) out along X and back to the origin,
    a span of no length there (two equal control points), up along Y and back to the origin,
    where it ends. At the origin the path turns by 90 degrees across the empty span, but the
    probe for the tangent after it grew tenfold from the span's width straight to the curve's
    end, also the origin, found no length and called the corner an end of the curve: taken at
    speed, 5,493 mm/s^2 from positions, and the motion guard refused the curve. The polygon
    says where the motion must rest: at the turns back (knots 3 and 13 of 14) and at the corner
    (knot 5, where the empty span starts), and nowhere else (a corner's flip of the tangent
    between samples is no near cusp)."""
    source = CASES / "closed-zero-length-span-corner.nc"
    curve = next(item.curve for item in read_program(source) if hasattr(item, "curve"))
    machine = load_machine("default")
    plan = plan_curve(curve, machine.limits)
    stops = plan.grid.u[plan.grid.stop_index]
    np.testing.assert_allclose(stops, np.array([3, 5, 13]) / 14, atol=1e-12)
    target = tmp_path / "out.nc"
    convert_file(source, target, machine)
    report = check_files(source, target, machine)
    assert report.ok, "\n".join(map(str, report.violations))


@pytest.mark.parametrize("name", ["reversal-before-a-corner-knot",
                                  "reversal-before-a-corner-knot-b"])
def test_a_reversal_just_before_a_corner_knot_is_a_stop(tmp_path: Path, name: str) -> None:
    """Fuzzer finds (seed 42): a rational quadratic along X turns back inside its first span,
    0.015 mm before a knot of multiplicity 2 where it turns back again (a corner). The sample
    at the knot takes the tangent of the span after it, which points back like the one of the
    sample before the reversal, so their tangents showed no turn while the chord between them
    went forward; the reversal was passed at 3.6 mm/s, and the motion guard refused the curve
    (3,713 and 7,046 mm/s^2 against 2,828). Every sign change of x'(u), found here by dense
    sampling, must be a stop node."""
    source = CASES / f"{name}.ngc"
    curve = next(item.curve for item in read_program(source) if hasattr(item, "curve"))
    flips = x_reversals(curve)
    # the reversal inside the first span, then the corner's turn back at the knot that ends it
    # (and, in the first program, a third at its knot 6/7, where two equal control points meet)
    corner = np.unique(curve.knots)[1]
    assert flips.size >= 2 and abs(flips[1] - corner) <= 1e-6
    assert 0 < corner - flips[0] < 0.1 * (curve.u_max - curve.u_min)
    assert_stops_at_and_check_passes(source, curve, flips, tmp_path)


def test_a_reversal_just_after_a_zero_of_c_prime_at_a_knot_is_a_stop(tmp_path: Path) -> None:
    """Fuzzer find (seed 57, gcode-5700174-120): a rational cubic comes to rest at its knot
    1/3 (C' = 0 there, a cusp at (0, 0.25)), leaves it down the Y axis and turns back up at
    u = 0.3718, before the first sample after the knot (0.375) has come back past the knot's
    position: the chord from the knot to that sample still points the way the curve left, so
    no chord showed the reversal, only the sample's tangent, up the axis. It was passed at
    1 mm/s (a jerk vector of 1.7e6 mm/s^3 from the points), and the motion guard refused the
    valid program however far it was slowed. Every sign change of y'(u) on the Y axis, found
    here by dense sampling, must be a stop node."""
    source = CASES / "reversal-just-after-a-zero-at-a-knot.ngc"
    curve = next(item.curve for item in read_program(source) if hasattr(item, "curve"))
    knot = np.unique(curve.knots)[1]
    u = np.linspace(knot, np.unique(curve.knots)[2], 2_000_001)[1:]
    position, derivative = curve.derivatives(u)[:2]
    assert np.all(position[:, 0] == 0.0)  # on the Y axis after the knot
    dy = derivative[:, 1]
    flips = u[np.flatnonzero(np.sign(dy[:-1]) * np.sign(dy[1:]) < 0)]
    assert flips.size == 1 and 0.0 < flips[0] - knot < 0.375 - knot
    assert_stops_at_and_check_passes(source, curve, np.concatenate([[knot], flips]), tmp_path)
