"""The path jerk model (issue 15): the frame terms it computes, the profile keys that choose it,
and the limits the machine feels, measured from the interpolation points themselves."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from nurbsfeed.analysis.check import check_files, render_check
from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.errors import CurveError, ProfileError
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.nurbs import curvature_from_derivatives
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import load_machine, machine_from_mapping
from nurbsfeed.pipeline import convert_file, plan_block
from nurbsfeed.planning.path_check import least_cycle_s
from nurbsfeed.planning.path_model import frames, jump_limits, motion_ratio
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.readers.json_curves import read_json_curves
from nurbsfeed.safety import MotionGuard
from tests.bench.dense_curves import dense_curves
from tests.motion_from_positions import path_motion
from tests.test_degenerate import EXAMPLES, degenerate_curves

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = sorted((ROOT / "samples").iterdir())
# the finite differences of one period read within 2 % of the motion (issue 15's allowance)
FROM_POSITIONS = 1.02

PAPER_LIMITS = {"period_s": 0.001, "max_feed_mm_s": 100.0, "chord_error_mm": 0.001,
                "max_acc_mm_s2": 1000.0, "max_jerk_mm_s3": 10000.0,
                "max_normal_acc_mm_s2": 1000.0, "max_normal_jerk_mm_s3": 10000.0}
# per-axis limits below the path's, so that they are the ones that bind where an axis leads
PATH_PROFILE = {**PAPER_LIMITS, "jerk_model": "path",
                "max_vel_x_mm_s": 80.0, "max_vel_y_mm_s": 90.0, "max_vel_z_mm_s": 40.0,
                "max_acc_x_mm_s2": 800.0, "max_acc_y_mm_s2": 900.0, "max_acc_z_mm_s2": 500.0,
                "max_jerk_x_mm_s3": 8000.0, "max_jerk_y_mm_s3": 9000.0,
                "max_jerk_z_mm_s3": 5000.0}


def _circle(radius: float) -> NurbsCurve:
    w = math.sqrt(0.5)
    pts = radius * np.array([[1, 0, 0], [1, 1, 0], [0, 1, 0], [-1, 1, 0], [-1, 0, 0]], float)
    return NurbsCurve.build(2, [0, 0, 0, 0.5, 0.5, 1, 1, 1], pts, [1, w, 1, w, 1], "half")


def test_a_circle_has_constant_curvature_no_change_and_no_torsion() -> None:
    f = frames(_circle(5.0), np.linspace(0.01, 0.99, 57))
    assert np.allclose(f.kappa, 0.2, rtol=1e-12)
    assert np.allclose(f.dkappa_ds, 0.0, atol=1e-12)
    assert np.allclose(f.torsion, 0.0, atol=1e-12)
    # the frame is orthonormal and the normal points at the centre
    c = _circle(5.0).point(np.linspace(0.01, 0.99, 57))
    assert np.allclose(f.normal, -c / 5.0, atol=1e-12)
    assert np.allclose(np.cross(f.tangent, f.normal), f.binormal, atol=1e-12)


@pytest.mark.parametrize("curve", [c for c in dense_curves(quick=True)
                                   if c.name in ("figure-eight", "helix")],
                         ids=lambda c: c.name)
def test_dkappa_ds_and_torsion_agree_with_differences_of_the_curve(curve: NurbsCurve) -> None:
    """kappa' against a central difference of kappa over arc length, tau against -B' . N, both
    from C' and C'' alone (no third derivative), away from the knots where C''' jumps."""
    u = np.linspace(curve.u_min, curve.u_max, 400)[1:-1]
    u = u[np.min(np.abs(u[:, None] - curve.knots[None, :]), axis=1) > 1e-4]
    h = 1e-6
    f = frames(curve, u)
    _, c1m, c2m = curve.derivatives(u - h)
    _, c1p, c2p = curve.derivatives(u + h)
    ds = 2 * h * np.linalg.norm(curve.derivatives(u)[1], axis=1)
    dk = (curvature_from_derivatives(c1p, c2p) - curvature_from_derivatives(c1m, c2m)) / ds
    scale = np.abs(f.dkappa_ds).max()
    assert np.abs(f.dkappa_ds - dk).max() <= 1e-5 * scale

    def binormal(c1: np.ndarray, c2: np.ndarray) -> np.ndarray:
        b = np.cross(c1, c2)
        return b / np.linalg.norm(b, axis=1)[:, None]

    tau = -np.einsum("ij,ij->i", (binormal(c1p, c2p) - binormal(c1m, c2m)) / ds[:, None],
                     f.normal)
    assert np.abs(f.torsion - tau).max() <= 1e-5 * max(np.abs(f.torsion).max(), 1e-9)
    if curve.name == "helix":  # r = 10, pitch 2: tau = c / (r^2 + c^2), c = 2 / 2pi
        c = 2.0 / (2 * math.pi)
        middle = f.torsion[len(u) // 3: 2 * len(u) // 3]
        assert np.allclose(middle, c / (100.0 + c * c), rtol=0.02)


def test_the_motion_ratio_is_the_slowdown_that_brings_each_quantity_to_its_limit() -> None:
    lim = machine_from_mapping(PATH_PROFILE, "test").limits
    f = frames(_circle(5.0), np.array([0.3]))
    for v, a, j in ((50.0, 0.0, 0.0), (30.0, 600.0, -4000.0), (10.0, -900.0, 9000.0)):
        ratio = motion_ratio(f, np.array([v]), np.array([a]), np.array([j]), lim)[0]
        slowed = motion_ratio(f, np.array([v / ratio]), np.array([a / ratio**2]),
                              np.array([j / ratio**3]), lim)[0]
        assert slowed == pytest.approx(1.0, rel=1e-9)


def test_a_knot_where_curvature_jumps_gets_the_speed_its_jump_allows() -> None:
    """A quarter circle (kappa 0.2) meeting a straight line: over one period the jump of
    kappa N reads as v^2 kappa / T of normal jerk; the smooth half circle's knot has none."""
    lim = machine_from_mapping(PAPER_LIMITS | {"jerk_model": "path"}, "test").limits
    assert np.isinf(jump_limits(_circle(5.0), np.array([0.5]), lim)).all()
    w = math.sqrt(0.5)
    pts = np.array([[5, 0, 0], [5, 5, 0], [0, 5, 0], [-2.5, 5, 0], [-5, 5, 0]], float)
    bend = NurbsCurve.build(2, [0, 0, 0, 0.5, 0.5, 1, 1, 1], pts, [1, w, 1, 1, 1], "bend")
    v = jump_limits(bend, np.array([0.5]), lim)[0]
    assert v == pytest.approx(math.sqrt(10000.0 * 0.001 / 0.2), rel=1e-9)


def test_the_jerk_model_and_per_axis_keys_are_read_and_checked() -> None:
    lim = machine_from_mapping(PATH_PROFILE, "test").limits
    assert lim.jerk_model == "path"
    assert lim.axis_vel_mm_s == (80.0, 90.0, 40.0)
    assert lim.axis_jerk_mm_s3 == (8000.0, 9000.0, 5000.0)
    assert machine_from_mapping(PAPER_LIMITS, "test").limits.jerk_model == "paper"
    assert machine_from_mapping(PAPER_LIMITS, "test").limits.axis_acc_mm_s2 == (math.inf,) * 3
    with pytest.raises(ProfileError, match="jerk_model.*paper, path"):
        machine_from_mapping({**PAPER_LIMITS, "jerk_model": "real"}, "test")
    with pytest.raises(ProfileError, match="per-axis limits .*max_acc_x_mm_s2.* jerk_model: path"):
        machine_from_mapping({**PAPER_LIMITS, "max_acc_x_mm_s2": 500.0}, "test")
    with pytest.raises(ProfileError, match="max_jerk_z_mm_s3"):
        machine_from_mapping({**PATH_PROFILE, "max_jerk_z_mm_s3": -1.0}, "test")
    # the command line's --jerk-model overrides the file's
    assert machine_from_mapping(PATH_PROFILE, "test",
                                overrides={"jerk_model": "path"}).limits.jerk_model == "path"
    with pytest.raises(ProfileError, match="jerk_model: path"):
        machine_from_mapping({**PATH_PROFILE, "jerk_model": "paper"}, "test")


def test_a_profile_file_places_a_bad_jerk_model_at_its_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("".join(f"{k}: {v}\n" for k, v in PAPER_LIMITS.items())
                    + "jerk_model: proxy\n")
    with pytest.raises(ProfileError) as caught:
        load_machine(str(path))
    assert str(caught.value.location) == f"{path}:8:1"


def _worst_over_limits(points: np.ndarray, period_s: float, lim) -> dict[str, float]:
    """Every path-model quantity from the points, as measured / limit."""
    m = path_motion(points, period_s)
    worst = {"a_t": m.path.tangential_acc_mm_s2.max() / lim.acc_mm_s2,
             "a_n": m.path.normal_acc_mm_s2.max() / lim.normal_acc_mm_s2,
             "j_t": np.abs(m.tangential_jerk_mm_s3).max() / lim.jerk_mm_s3,
             "j_n": m.normal_jerk_mm_s3.max() / lim.normal_jerk_mm_s3}
    for x, axis in enumerate("XYZ"):
        worst[f"v{axis}"] = np.abs(m.axis_velocity_mm_s[:, x]).max() / lim.axis_vel_mm_s[x]
        worst[f"a{axis}"] = np.abs(m.axis_acc_mm_s2[:, x]).max() / lim.axis_acc_mm_s2[x]
        worst[f"j{axis}"] = np.abs(m.jerk_mm_s3[:, x]).max() / lim.axis_jerk_mm_s3[x]
    return worst


@pytest.mark.parametrize("sample", SAMPLES, ids=lambda p: p.name)
def test_every_sample_keeps_every_path_limit_measured_from_its_points(sample: Path) -> None:
    machine = machine_from_mapping(PATH_PROFILE, "test")
    for block in curve_blocks(sample):
        plan = plan_block(block, machine)
        result = interpolate(plan, "rk2c")
        if len(result.points) < 4:
            continue
        worst = _worst_over_limits(result.points, result.period_s, plan.limits)
        assert max(worst.values()) <= FROM_POSITIONS, worst


@pytest.mark.parametrize("curve", dense_curves(quick=True), ids=lambda c: c.name)
def test_dense_curves_keep_every_path_limit_measured_from_their_points(curve: NurbsCurve) -> None:
    """Near-cusps, a helix's torsion, mm-sized curves: where the paper's model let the normal
    jerk reach 4x its limit and an axis's jerk 4x the path's."""
    lim = machine_from_mapping(PATH_PROFILE, "test").limits
    result = interpolate(plan_curve(curve, lim), "rk2c")
    worst = _worst_over_limits(result.points, result.period_s, lim)
    assert max(worst.values()) <= FROM_POSITIONS, worst
    MotionGuard(lim, curve.name).check(result.points)  # and the path model's guard lets it pass


def test_the_paper_model_is_still_the_papers() -> None:
    """paper-table1 plans the butterfly as before (Table 2's 6.747 s): the path model changes
    nothing unless a profile asks for it, and under it the butterfly runs slower, not faster."""
    _, [(curve, _)] = read_json_curves(ROOT / "samples" / "butterfly.json")
    paper = plan_curve(curve, load_machine("paper-table1").limits)
    assert paper.cycle_time_s == pytest.approx(6.747, abs=5e-4)
    path = plan_curve(curve, machine_from_mapping(PAPER_LIMITS | {"jerk_model": "path"},
                                                  "test").limits)
    assert path.cycle_time_s > paper.cycle_time_s


# ---- check under the path model --------------------------------------------------------------

def _profile_file(tmp_path: Path, profile: dict) -> Path:
    path = tmp_path / "profile.yaml"
    path.write_text("".join(f"{key}: {value}\n" for key, value in profile.items()))
    return path


PATH_ROWS = ("tangential-jerk-xyz", "normal-jerk-xyz", "axis-vel-x", "axis-vel-y", "axis-acc-x",
             "axis-acc-y", "axis-jerk-x", "axis-jerk-y")


@pytest.mark.parametrize("name", ["butterfly.json", "fanuc-multi-curve.nc",
                                  "linuxcnc-nurbs-yz.ngc"])
def test_check_measures_the_path_quantities_and_passes_a_path_plan(tmp_path: Path,
                                                                   name: str) -> None:
    """Under `path`, check adds the jerk vector split on the path and each axis's velocity,
    acceleration and jerk from the written points, and a path plan keeps every one of them
    (and drops the proxy v^3 kappa^2, which the path model does not limit)."""
    profile = _profile_file(tmp_path, PATH_PROFILE)
    machine = load_machine(str(profile))
    out = tmp_path / "out.nc"
    convert_file(ROOT / "samples" / name, out, machine)
    report = check_files(ROOT / "samples" / name, out, machine)
    assert report.ok, "\n".join(map(str, report.violations))
    measured = {m.name: m for m in report.measures}
    moving = [row for row in PATH_ROWS if row[-1] in "xy" or name != "linuxcnc-nurbs-yz.ngc"]
    for row in moving:
        assert measured[row].n_checked > 0.99 * report.n_moves - 10, row
    assert measured["normal-jerk"].n_checked == 0
    table = render_check(report, "test")
    assert "X jerk from positions" in table and "normal jerk v^3 kappa^2" not in table


def test_check_fails_a_paper_plan_under_path_limits(tmp_path: Path) -> None:
    """The butterfly planned under the paper model with the path profile's own limits breaks
    the path model's (issue 15's table: the axis jerk 4x its limit): check, given the path
    profile, finds the jerk across the path and the X and Y jerk over their limits."""
    out = tmp_path / "out.nc"
    source = ROOT / "samples" / "butterfly.json"
    convert_file(source, out, load_machine(str(_profile_file(tmp_path, PAPER_LIMITS))))
    path_machine = load_machine(str(_profile_file(tmp_path, PATH_PROFILE)))
    report = check_files(source, out, path_machine)
    measured = {m.name: m for m in report.measures}
    for row in ("normal-jerk-xyz", "axis-jerk-x", "axis-jerk-y"):
        assert measured[row].n_violations > 0 and measured[row].ratio > 1.5, measured[row]


def test_check_under_the_paper_model_shows_no_path_rows(tmp_path: Path) -> None:
    out = tmp_path / "out.nc"
    source = ROOT / "samples" / "butterfly.json"
    machine = load_machine("paper-table1")
    convert_file(source, out, machine)
    table = render_check(check_files(source, out, machine), "paper-table1")
    assert "normal jerk v^3 kappa^2" in table
    assert "jerk from positions" not in table and "X velocity" not in table


# Random curves (tests/test_degenerate's strategy) the path model once planned absurdly, each
# at under 5 s under paper-model limits: 7.6e8 s (u from s by a linear guess beside a triple
# control point, where s grows as (u - u0)^3, put law samples 1e-9 of u from the stop, where
# kappa is rounding noise: kappa 5e20), 1.7e9 s and 3e20 s (a node where C' = 0 that the grid
# passes at speed, a zero-length span's end or a removable zero at a knot: its frame is noise,
# kappa 2e30, and its static limit 1e-19 mm/s), 1.06e6 s (zero-length-end-span-jump: the jump
# of kappa N at a knot beside a span of no length, rounding noise, set 2e-14 mm/s); and 23 s,
# 13 s, 83 s, 12 s (brake-into-needle-peak, cubic-knot-step, cusp-departure-dip,
# hook-beside-the-end: a low of the path limit between two key points, or a needle of kappa
# hidden between the last node and a still end, left to a segment cap or a uniform slowdown
# of the whole curve). Refused as too long, or planning for minutes. still-first-span-double-
# knot was the paper model's: a first span of no length took the noise kappa of the knot after
# it (7e13: 65 hours at 2.8e-11 mm/s). Now within 2x the paper model's cycle under the same
# limits (the path model's own cost: the butterfly takes 1.35x, cam-63 1.74x; see
# docs/benchmarks.md), and the paper model's within 10x the length at the feed.
DEGENERATE = sorted((Path(__file__).parent / "data" / "path").glob("*.json"))


@pytest.mark.parametrize("source", DEGENERATE, ids=lambda p: p.stem)
def test_degenerate_curves_are_planned_sanely_and_keep_the_path_limits(source: Path) -> None:
    _, [(curve, feed)] = read_json_curves(source)
    lim = dataclasses.replace(machine_from_mapping(PATH_PROFILE, "test").limits, feed_mm_s=feed)
    paper = plan_curve(curve, dataclasses.replace(lim, jerk_model="paper"), max_curve_time_s=60.0)
    assert paper.cycle_time_s <= 10.0 * float(paper.grid.s_mm[-1]) / feed
    plan = plan_curve(curve, lim, max_curve_time_s=60.0)
    assert plan.cycle_time_s <= 2.0 * paper.cycle_time_s, (plan.cycle_time_s, paper.cycle_time_s)
    result = interpolate(plan, "rk2c")
    worst = _worst_over_limits(result.points, result.period_s, lim)
    assert max(worst.values()) <= FROM_POSITIONS, worst
    MotionGuard(lim, source.stem).check(result.points)


PATH_EXAMPLES = max(20, EXAMPLES // 3)
# a near cusp (the tangent turns back by 153 degrees, kappa above 1,000/mm beside it) 30 mm
# into a curve whose limit dips to 70 mm/s 6 mm after it: the S-curve planner held 0.3 mm/s up
# to the dip, and capped the segment from the cusp at 0.2 mm/s up to a shoulder 9 mm on
# (55.3 s against the paper model's 1.494 s); confined (scurve_plan.CRAWL_REL), 2.10 s
NEAR_CUSP_BEFORE_A_DIP = NurbsCurve.build(
    4, [0, 0, 0, 0, 0, 0.05, 0.05, 1, 1, 1, 1, 1],
    [[0, 3.762, 0], [-29.669, 3, 0], [11.5, -0.643, 0], [-0.96, 15.795, 0], [-0.96, 15.795, 0],
     [19.433, 0, 0], [-29.669, 0, 0]],
    [1.25, 0.25, 0.25, 1.25, 0.25, 0.25, 0.25])


@settings(max_examples=PATH_EXAMPLES, deadline=None, derandomize=PATH_EXAMPLES <= 100,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(degenerate_curves(), st.sampled_from([20.0, 100.0, 200.0]))
@example(NEAR_CUSP_BEFORE_A_DIP, 100.0)
def test_random_curves_keep_every_path_limit_at_a_sane_cycle(curve: NurbsCurve,
                                                             feed_mm_s: float) -> None:
    """Random curves with repeated control points, corners and extreme weights under the path
    model: every quantity from the points within FROM_POSITIONS of its limit, the motion guard
    passes them, and the cycle stays within 3x the paper model's (on 3,000 random curves the
    worst was 2.05x, 1.19x at the median)."""
    lim = dataclasses.replace(machine_from_mapping(PATH_PROFILE, "test").limits,
                              feed_mm_s=feed_mm_s)
    paper = plan_curve(curve, dataclasses.replace(lim, jerk_model="paper"))
    plan = plan_curve(curve, lim)
    assert plan.cycle_time_s <= 3.0 * paper.cycle_time_s, (plan.cycle_time_s, paper.cycle_time_s)
    assume(plan.n_periods < 40_000)  # keep the example fast; long plans are no different
    assert_keeps_every_path_limit(interpolate(plan, "rk2c"), lim, curve.name)


def assert_keeps_every_path_limit(result, lim, name: str) -> None:
    """The interpolation's points finite, every path-model quantity from them within
    FROM_POSITIONS of its limit, and the motion guard lets them pass."""
    assert np.isfinite(result.points).all()
    if len(result.points) >= 4:
        worst = _worst_over_limits(result.points, result.period_s, lim)
        assert max(worst.values()) <= FROM_POSITIONS, worst
    MotionGuard(lim, name).check(result.points)


def test_a_curve_too_slow_for_an_axis_is_refused_by_a_lower_bound_before_planning() -> None:
    """The quarter circle moves X 10 mm: at max_vel_x_mm_s 0.001 no motion takes less than
    10,000 s. The path model's fix rounds sample the law twice a period (19 M samples here), so
    the refusal at max_curve_time_s 3,600 took 53 s of CPU; the bound refuses it first."""
    _, [(curve, feed)] = read_json_curves(ROOT / "samples" / "quarter-circle.json")
    lim = machine_from_mapping({**PATH_PROFILE, "max_vel_x_mm_s": 0.001}, "test").limits
    lim = dataclasses.replace(lim, feed_mm_s=min(lim.feed_mm_s, feed))
    with pytest.raises(CurveError, match=r"^cycle of at least 10000 s exceeds max_curve_time_s "
                                         r"= 3600 s"):
        plan_curve(curve, lim, max_curve_time_s=3600.0)


@pytest.mark.parametrize("curve", dense_curves(quick=True)[:3], ids=lambda c: c.name)
def test_the_lower_bound_is_below_every_planned_cycle_and_not_trivial(curve: NurbsCurve) -> None:
    """Each grid interval lasts at least its arc over the feed and each axis's travel over its
    limit: never more than the plan's cycle, and at least the arc at the feed."""
    lim = machine_from_mapping(PATH_PROFILE, "test").limits
    plan = plan_curve(curve, lim)
    fcap = np.full(plan.grid.u.size, np.inf)
    least = least_cycle_s(curve, plan.grid, lim, fcap)
    assert plan.length_mm / lim.feed_mm_s <= least <= plan.cycle_time_s
