"""Curvature peaks the planning grid or the limit rounds missed (fuzzer finds): the normal limits
must hold at every interpolation point, not only at the grid's nodes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.nurbs import curvature_from_derivatives
from nurbsfeed.geometry.peaks import near_cusp_peaks
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.readers import read_program
from tests.conftest import default_paper_limits
from tests.limits_check import measure
from tests.test_path_model import assert_keeps_every_path_limit

DATA = Path(__file__).parent / "data" / "peaks"
LIMIT_REL = 1e-6

# tests/data/peaks/peak-before-end.nc: kappa 37.3 inside the last sample interval (kappa 2.5 at
# the sample before, 20.3 at the end); the plan ran v^3 kappa^2 to 1.72 J_n there
BEFORE_END = NurbsCurve.build(
    3, [0, 0, 0, 0, 0.6, 0.9, 0.9, 1, 1, 1, 1],
    [[1, 2, 0], [3.946, 0, 0], [0.341, 0.341, 0], [0, 0.01, 0], [1.29, 4.869, 0],
     [4.032, 3.386, 0], [4.01, 3.679, 0]],
    [1, 1.1, 1, 1.193, 1, 1, 1])
# tests/data/peaks/peak-before-knot.ngc (G18: Z, X): kappa 21.7 just before the knot 0.25,
# where kappa jumps from 16.8 down to 7.5; the sample before it has 16.4. 1.69 J_n.
BEFORE_KNOT = NurbsCurve.build(
    2, [0, 0, 0, 0.25, 0.5, 0.75, 1, 1, 1],
    [[3, 3, 0], [0.772, 3, 4.289], [1.335, 3, 4.393], [0, 3, 0.391], [4.955, 3, 0.972],
     [0, 3, 0]],
    [1, 1.571, 1.812, 1.177, 0.528, 1])


def kappa_at(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    _, c1, c2 = curve.derivatives(u)
    return curvature_from_derivatives(c1, c2)


@pytest.mark.parametrize("curve", [BEFORE_END, BEFORE_KNOT], ids=["end", "knot"])
def test_no_grid_interval_hides_a_curvature_above_both_its_nodes(curve: NurbsCurve) -> None:
    """The planner bounds the limit between two nodes by the lower of their limits: kappa
    between them must not exceed the higher of theirs (dense sampling, 64 per interval)."""
    grid = plan_curve(curve, load_machine("default").limits).grid
    frac = np.linspace(0.0, 1.0, 66)[1:-1]
    inside = grid.u[:-1, None] + np.diff(grid.u)[:, None] * frac[None, :]
    highest = kappa_at(curve, inside.ravel()).reshape(inside.shape).max(axis=1)
    ends = np.maximum(grid.kappa_1_mm[:-1], grid.kappa_1_mm[1:])
    assert np.all(highest <= ends * (1 + 1e-3)), np.max(highest / ends)


@pytest.mark.parametrize(("curve", "where"), [(BEFORE_END, (0.9972, 0.9975)),
                                              (BEFORE_KNOT, (0.2403, 0.2408))],
                         ids=["end", "knot"])
def test_the_hidden_maximum_is_a_peak_node(curve: NurbsCurve, where) -> None:
    grid = plan_curve(curve, load_machine("default").limits).grid
    peaks = grid.u[grid.peak_index]
    (found,) = peaks[(peaks > where[0]) & (peaks < where[1])]
    around = kappa_at(curve, found + np.array([-1e-6, 0.0, 1e-6]))
    assert around[1] >= around.max() * (1 - 1e-12)


@pytest.mark.parametrize("curve", [BEFORE_END, BEFORE_KNOT], ids=["end", "knot"])
def test_normal_limits_hold_at_every_interpolation_point(curve: NurbsCurve) -> None:
    """Under the default profile's limits and the paper's model (v_m 200 mm/s), whose normal
    jerk is the proxy v^3 kappa^2 that `measure` reads."""
    lim = default_paper_limits()
    m = measure(curve, interpolate(plan_curve(curve, lim)), lim)
    assert m.normal_jerk <= lim.normal_jerk_mm_s3 * (1 + LIMIT_REL), m
    assert m.normal_acc <= lim.normal_acc_mm_s2 * (1 + LIMIT_REL), m
    assert m.v_over_limit <= 1 + LIMIT_REL, m


@pytest.mark.parametrize("curve", [BEFORE_END, BEFORE_KNOT], ids=["end", "knot"])
def test_the_path_limits_hold_from_the_points_under_the_default(curve: NurbsCurve) -> None:
    """Under the default profile itself (path model, optimal planner): the peak hidden in the
    last interval is passed within every path and per-axis limit, measured from the points."""
    lim = load_machine("default").limits
    assert_keeps_every_path_limit(interpolate(plan_curve(curve, lim)), lim, "peak")


@pytest.mark.parametrize("name", ["peak-before-end.nc", "peak-before-knot.ngc"])
def test_check_passes_on_the_conversion(tmp_path: Path, name: str) -> None:
    """The programs as the fuzzer's finds had them (one curve each): `check` measured normal
    jerk 1.68 and 1.66 times J_n on their conversions."""
    out = tmp_path / "out.nc"
    runner = CliRunner()
    converted = runner.invoke(main, ["convert", str(DATA / name), "-o", str(out)])
    assert converted.exit_code == 0, converted.stderr
    checked = runner.invoke(main, ["check", str(DATA / name), str(out)])
    assert checked.exit_code == 0, checked.output
    assert "result: OK: 0 violation(s)" in checked.output


# A quarter circle of radius 10 (rational quadratic): kappa 0.1 everywhere, so the limit is
# sqrt(A_n / kappa) = 31.62 mm/s under the linuxcnc profile at every point, and no node shows
# more than any other. Its shoulder segments one grid interval long once peaked at 32.08 and
# 33.16 mm/s between their two nodes: v^2 kappa 9 % over A_n where no node looked.
QUARTER = NurbsCurve.build(2, [0, 0, 0, 1, 1, 1], [[10, 0, 0], [10, 10, 0], [0, 10, 0]],
                           [1, 2**-0.5, 1])


def test_a_peak_between_two_nodes_keeps_the_limit_at_every_point() -> None:
    """Measured at every interpolation point (tests/limits_check, the curve's own curvature),
    and on the law itself, sampled at 0.1 ms (the circle's limit is one number)."""
    lim = load_machine("linuxcnc").limits
    plan = plan_curve(QUARTER, lim)
    m = measure(QUARTER, interpolate(plan, "rk2c"), lim)
    assert m.normal_acc <= lim.normal_acc_mm_s2 * (1 + LIMIT_REL), m
    assert plan.piece_scale.size == 1  # rest to rest: the law runs at v / piece_scale
    v = plan.law.sample(np.arange(0.0, plan.law.duration_s, 1e-4))[1] / plan.piece_scale[0]
    assert v.max() <= np.sqrt(lim.normal_acc_mm_s2 / 0.1) * (1 + LIMIT_REL), v.max()


# tests/data/peaks/hairpin-needle.ngc, its second curve (fuzz seed 30, case gcode-3000111-507):
# the control points (0, 0.5), (0, 1.736), (0, 0.5) make the path turn back in a hairpin whose
# |C'| dips to 0.004 (of a mean ~10) without reaching 0, so kappa peaks at 2.4e7 1/mm in a
# needle ~1e-5 wide in u. The samples either side had 3,777 and 6,087, sampling their bracket
# stepped over the needle, and the plan passed the hairpin at 0.11 mm/s: the velocity reversed
# within one period (a jerk vector of 133,000 mm/s^3 from the full-precision positions).
HAIRPIN = NurbsCurve.build(
    4, [0, 0, 0, 0, 0, 1, 1, 1, 6, 7, 7, 7, 7, 7],
    [[1, 2, 0], [0, 0, 0], [0, 0.5, 0], [0, 1.736, 0], [0, 0.5, 0], [1, 0, 0], [3.417, 0, 0],
     [2.284, 5, 0], [0, 0, 0]],
    [1, 0.5, 0.5, 1, 0.5, 1, 1, 1, 1])
# tests/data/peaks/hairpin-drift.ngc (fuzz seed 31, case gcode-3100096-877), a G5.2 cubic
# (LinuxCNC's knots 0 0 0 0 1 2 3 4 5 5 5 5, the start prepended): its last control points lie
# on x = 0 and the path turns back near (0, 0.2552) where |C'| dips to 7e-6 (4e-7 of its mean,
# above the 1e-7 that makes a zero): kappa 1e12. Refined as a peak it was planned at 2e-9 mm/s,
# but rk2c's arc position runs ~0.2 um ahead of the law between rests, so the stepping met the
# tip while the law was still slowing down: the velocity reversed at 0.06 mm/s (`check`:
# tangential jerk 1.009x; the trace: a jerk vector of 120,000 mm/s^3).
DRIFT = NurbsCurve.build(
    3, [0, 0, 0, 0, 1, 2, 3, 4, 5, 5, 5, 5],
    [[1, 0, 0], [4.317, 4.264, 0], [4.508, 0, 0], [0.662, 4.508, 0], [0, 1.549, 0],
     [0, 0, 0], [0, 0.5, 0], [0, 4.948, 0]],
    [1, 1.737, 1, 0.925, 0.588, 1.501, 1.58, 0.5])


def densest(curve: NurbsCurve, low: float, high: float, of) -> float:
    """Where of(u) is largest in [low, high]: 2e5 samples, then 4,000 around the best."""
    u = np.linspace(low, high, 200_001)
    best = u[np.argmax(of(u))]
    step = (high - low) / 200_000
    u = np.linspace(best - step, best + step, 4001)
    return float(u[np.argmax(of(u))])


def hairpin_peak() -> tuple[float, float]:
    """The needle's u and kappa by dense sampling (~150 samples across its half width)."""
    u = densest(HAIRPIN, 0.94 / 7, 0.96 / 7, lambda u: kappa_at(HAIRPIN, u))
    return u, float(kappa_at(HAIRPIN, np.array([u]))[0])


@pytest.mark.parametrize(("curve", "where"), [(HAIRPIN, (0.94 / 7, 0.96 / 7)),
                                              (DRIFT, (3.99 / 5, 4.01 / 5))],
                         ids=["needle", "drift"])
def test_a_hairpin_tighter_than_the_samples_is_passed_at_rest(curve: NurbsCurve, where) -> None:
    """The tip (the densely sampled minimum of |C'|, which is not 0) is a stop: a key point of
    speed 0 where the stepping lands exactly, so no arc drift can put the tip before it."""
    tip = densest(curve, *where, lambda u: -curve.speed(u))
    assert 0.0 < curve.speed(np.array([tip]))[0] < 1e-3 * curve.speed(np.linspace(0, 1, 999)).mean()
    plan = plan_curve(curve, load_machine("default").limits)
    stops = plan.grid.u[plan.grid.stop_index]
    assert stops.size and np.min(np.abs(stops - tip)) <= 1e-9, (stops, tip)
    k = int(np.argmin(np.abs(plan.key_u - tip)))
    assert k in plan.piece_key  # a rest (speed 0): the stepping lands there
    points = interpolate(plan).points
    at_tip = np.linalg.norm(points - curve.point(np.array([plan.key_u[k]]))[0], axis=1)
    assert at_tip.min() == 0.0  # a point written exactly there


def test_a_near_cusp_needle_is_refined_to_its_peak() -> None:
    """The refinement a near cusp that does not turn back gets (`near_cusp_peaks`), given the
    samples the grid had around the needle: it finds the densely sampled peak."""
    u_peak, k_peak = hairpin_peak()
    samples = np.array([0.94458705, 0.94698661, 0.94938616, 0.95178571]) / 7
    kappa = kappa_at(HAIRPIN, samples)
    assert kappa.max() < 1e4 < k_peak  # the samples do not show it
    tip = densest(HAIRPIN, samples[1], samples[2], lambda u: -HAIRPIN.speed(u))
    knots, coef = HAIRPIN.knots, HAIRPIN.span_polynomials
    (found,) = near_cusp_peaks(knots, coef, HAIRPIN.degree, samples, kappa, np.array([tip]),
                                1.0)
    assert kappa_at(HAIRPIN, np.array([found]))[0] >= k_peak * (1 - 1e-6)


@pytest.mark.parametrize("name", ["hairpin-needle.ngc", "hairpin-drift.ngc"])
def test_a_hairpin_conversion_passes_check_and_its_jerk_vector_holds(tmp_path: Path,
                                                                     name: str) -> None:
    """Judged by the positions: the jerk vector differenced from the full-precision trace stays
    within the tangential and normal jerk limits together (the old plans reached 1.9 and 1.7
    times it), and `check` passes (it read tangential jerk 1.0033 and 1.009 times the limit)."""
    source = DATA / name
    out, trace = tmp_path / "out.nc", tmp_path / "trace.csv"
    runner = CliRunner()
    converted = runner.invoke(main, ["convert", str(source), "-o", str(out),
                                     "--trace", str(trace)])
    assert converted.exit_code == 0, converted.stderr
    checked = runner.invoke(main, ["check", str(source), str(out)])
    assert checked.exit_code == 0, checked.output
    rows = np.genfromtxt(trace, delimiter=",", names=True)
    lim = load_machine("default").limits
    worst = 0.0
    for c in np.unique(rows["curve"]):
        mine = rows[rows["curve"] == c]
        pos = np.column_stack([mine["x"], mine["y"], mine["z"]])
        jerk = np.diff(pos, 3, axis=0) / lim.period_s**3
        worst = max(worst, float(np.linalg.norm(jerk, axis=1).max(initial=0.0)))
    assert worst <= 1.02 * np.hypot(lim.jerk_mm_s3, lim.normal_jerk_mm_s3), worst


def test_a_peak_inside_the_first_interval_after_a_knot_is_planned(tmp_path: Path) -> None:
    """Fuzz seed 45 (gcode-4500152-167): after the knot u = 8/9 of a cubic, kappa falls from
    14.7 to 6.7, rises to 23.1 and falls to 14.6, all inside the first sample interval, whose
    ends (14.7, 14.6) showed nothing: the plan passed the peak at 5.1 mm/s, v^3 kappa^2 1.42x
    the normal-jerk limit (4.54 mm/s there), and `check` failed the output. kappa at an
    interval's middle, more than 10 % above both ends, now splits it. The dense maximum of
    kappa in the span is a peak node, and the conversion passes `check`."""
    source = DATA / "peak-after-a-knot-between-nodes.ngc"
    curve = next(item.curve for item in read_program(source) if hasattr(item, "curve"))
    u = np.linspace(8 / 9, 1.0, 1_000_001)
    _, c1, c2 = curve.derivatives(u)
    kappa = curvature_from_derivatives(c1, c2)
    top = u[int(np.nanargmax(kappa))]
    assert np.nanmax(kappa) > 20.0
    plan = plan_curve(curve, load_machine("default").limits)
    peaks = plan.grid.u[plan.grid.peak_index]
    assert np.min(np.abs(peaks - top)) <= 1e-5, (top, peaks)
    target = tmp_path / "out.nc"
    converted = CliRunner().invoke(main, ["convert", str(source), "-o", str(target)])
    assert converted.exit_code == 0, converted.output
    checked = CliRunner().invoke(main, ["check", str(source), str(target)])
    assert checked.exit_code == 0, checked.output
