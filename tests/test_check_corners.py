"""check's projection at a corner (a C0 knot, where the motion rests): found by the fuzzing tier
as tangential jerk 1.1x and path deviation 1.27x their allowances on outputs that keep both.

A step of the projection's walk that crossed the corner, from the distance rising before it to
the distance rising after it, left the minimum after the corner unseen: a point just after the
corner was measured against the incoming leg (2.8e-4 mm where the curve is 6.6e-5 mm away), and
its foot put the arc length back, a jerk spike in the divided differences. The stepped points
themselves keep the limits (their jerk from the trace: 49,939 mm/s^3 at most).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from nurbsfeed.analysis import check_files
from nurbsfeed.analysis.check import project_points
from nurbsfeed.analysis.check.curve_checks import least_time_s
from nurbsfeed.analysis.check.projection import nearest_on_curve
from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file
from nurbsfeed.program import CurveBlock
from nurbsfeed.readers import read_program
from tests.conftest import default_paper_machine

CASES = Path(__file__).parent / "data" / "check-corners"
INCH = CASES / "inch-path-deviation.ngc"
R_MM = 0.5e-5 * 25.4 * np.sqrt(3.0)  # output rounding at 5 decimals of an inch
CORNER_U = 5.0 / 6.0  # the double knot of the inch program's quadratic
# written points around its corner (mm): two on the way in, the corner, two on the way out
AROUND_THE_CORNER = np.array([[38.100254, 56.311292, 20.9804], [38.1, 56.311546, 20.9804],
                              [38.1, 56.3118, 20.9804], [38.1, 56.311546, 20.980146],
                              [38.1, 56.311546, 20.979892]])


@pytest.mark.parametrize("name", ["corner-tangential-jerk.ngc", "inch-path-deviation.ngc",
                                  "inch-turn-back-jerk.json"])
def test_a_program_with_a_corner_converted_passes_check(tmp_path: Path, name: str) -> None:
    machine = load_machine("default")
    target = tmp_path / "out.nc"
    convert_file(CASES / name, target, machine)
    report = check_files(CASES / name, target, machine)
    assert report.ok, "\n".join(map(str, report.violations))


def test_points_around_a_corner_are_measured_against_their_own_leg() -> None:
    curve = next(item.in_mm() for item in read_program(INCH)
                 if isinstance(item, CurveBlock)).curve
    foot, dist = project_points(curve, AROUND_THE_CORNER, 2.0 * R_MM, R_MM, 10.0 * R_MM)
    # the distance to the curve by brute force: every 1e-11 of u on either leg near the corner
    u = np.linspace(CORNER_U - 1e-5, CORNER_U + 1e-5, 2_000_001)
    on_curve = curve.point(u)
    nearest = np.array([np.linalg.norm(on_curve - p, axis=1).min()
                        for p in AROUND_THE_CORNER])
    assert dist == pytest.approx(nearest, rel=1e-4, abs=1e-9)
    assert nearest[3] < 0.5 * R_MM  # once measured as 1.27 R_MM against the incoming leg
    assert foot[0] < foot[1] < CORNER_U < foot[3] < foot[4]
    assert foot[2] == pytest.approx(CORNER_U, abs=1e-12)


TURNS = Path(__file__).parent / "data" / "check-turns"


@pytest.mark.parametrize("name", ["path-deviation.ngc", "path-deviation-2.nc",
                                  "path-deviation-3.nc", "path-deviation-4.nc",
                                  "tangential-jerk.ngc"])
def test_a_point_past_a_sharp_turn_is_measured_against_the_nearest_leg(tmp_path: Path,
                                                                       name: str) -> None:
    """Fuzzer finds (tests/fuzz): points just past a sharp turn that the walk measured against the
    leg before it, up to 8x the rounding allowance off a curve they lie on (brute force put one
    at 1e-12 mm); check now looks again around the anchor, then along the whole curve, before it
    calls a point off."""
    machine = load_machine("default")
    target = tmp_path / "out.nc"
    convert_file(TURNS / name, target, machine)
    report = check_files(TURNS / name, target, machine)
    assert report.ok, "\n".join(map(str, report.violations))


def test_the_least_time_of_a_near_cusp_curve_stays_below_its_plan(tmp_path: Path) -> None:
    """Fuzzer find: a slow (F5) curve with a near-cusp, whose length a Gauss rule over whole knot
    spans put 0.7 % long, so check's lower bound on the time (288.75 s) exceeded the plan
    (286.80 s) and called a correct program 'cut short'. The polygon under the curve is a
    lower bound of its length whatever |C'| does.

    The find's curve is run at F50 instead of F5: a tenth of the moves to check (29,000), and
    the old Gauss bound still calls it cut short (28.88 s needed, 28.69 s + 0.14 s rounding
    written); it stops doing so only above F100, where the plan's own ramps and slowdown at the
    near-cusp outweigh the 0.7 %."""
    find = json.loads((TURNS / "slow-near-cusp.json").read_text())
    assert find["curves"][1]["feed"] == 5.0
    find["curves"][1]["feed"] = 50.0
    source = tmp_path / "slow-near-cusp.json"
    source.write_text(json.dumps(find))
    machine = load_machine("default")
    target = tmp_path / "out.nc"
    convert_file(source, target, machine)
    report = check_files(source, target, machine)
    assert report.ok, "\n".join(map(str, report.violations))
    slow = [block for block in curve_blocks(source) if block.feed_mm_s.size][1]
    polygon = np.linalg.norm(np.diff(slow.curve.point(np.linspace(0.0, 1.0, 1_000_001)),
                                     axis=0), axis=1).sum()
    feed, acc = slow.feed_mm_s[0], machine.limits.acc_mm_s2
    # the bound is the trapezoid L / v + v / A, whose ramp term v / A (0.4 ms at F50) is
    # exact: the polygon of 4097 points under the curve is no longer than this finer one
    assert least_time_s(slow, np.inf, acc) <= polygon / feed + feed / acc


@pytest.mark.parametrize("name", ["hairpin-chord-error.ngc", "cusp-tangential-jerk.ngc",
                                  "corner-turn-back-jerk.nc", "inch-corner-path-deviation.ngc",
                                  "reversal-path-deviation.ngc"])
def test_points_around_a_turn_back_are_measured_on_the_leg_the_motion_is_on(
        tmp_path: Path, name: str) -> None:
    """Fuzzer finds (tests/fuzz): at a turn of nearly 180 degrees (a cubic running out along X
    and back, a cusp of collinear control points, a polyline corner of 171 degrees) both legs lie
    within rounding of the points beside the tip, and the walk took the leg before the turn for
    points after it, or walked that leg backwards: tangential jerk up to 45x, acceleration 24x,
    chord error 12x, path deviation 1.1-15x, on outputs whose traced positions keep every limit
    (the check given the trace's own parameters passes). Written points on the way back repeat
    the ones on the way out exactly (corner-turn-back-jerk, cusp-tangential-jerk)."""
    machine = load_machine("default")
    target = tmp_path / "out.nc"
    convert_file(TURNS / name, target, machine)
    report = check_files(TURNS / name, target, machine)
    assert report.ok, "\n".join(map(str, report.violations))


def _first_turn_back(lines: list[str]) -> int:
    """Index of the first written point of curve 0 after which X decreases (its moves run out
    along X first)."""
    start = next(i for i, line in enumerate(lines) if line.startswith("(nurbsfeed: curve 0"))
    previous = (-1, -np.inf)
    for i in range(start + 1, len(lines)):
        word = re.match(r"(?:G1 )?X(-?[\d.]+)", lines[i])
        if word:
            if float(word.group(1)) < previous[1]:
                return previous[0]
            previous = (i, float(word.group(1)))
    raise AssertionError("no turn back in curve 0")


@pytest.mark.parametrize("broken", ["lifted", "cut"])
def test_a_real_violation_beside_a_turn_back_is_still_caught(tmp_path: Path, broken: str) -> None:
    """The leg rules never hide a broken motion at a turn: a written point lifted 1 um off the
    curve (100 times the rounding) is a path deviation, and the motion cut across the turn (the
    13 moves around its tip removed, so the points jump back at speed) breaks the tangential
    jerk on the points before the cut."""
    source = TURNS / "hairpin-chord-error.ngc"
    machine = default_paper_machine()  # its tangential jerk row is the paper model's
    target = tmp_path / "out.nc"
    convert_file(source, target, machine)
    lines = target.read_text().splitlines(keepends=True)
    tip = _first_turn_back(lines)
    # the planner rests at the tip: the move into it averages under 0.1 mm/s (6 mm/min)
    assert float(lines[tip].rsplit("F", 1)[1]) < 6.0
    if broken == "lifted":
        z = next(float(m.group(1)) for line in lines[tip::-1]
                 if (m := re.search(r"Z(-?[\d.]+)", line)))
        body = re.sub(r" Z-?[\d.]+", "", lines[tip])
        lines[tip] = body.replace(" F", f" Z{z + 0.001:.5f} F")  # 1 um above the curve
        expected = {("path-deviation", tip + 1)}
    else:
        del lines[tip - 6:tip + 7]
        expected = {("tangential-jerk", line) for line in range(tip - 15, tip - 5)}
    target.write_text("".join(lines))
    report = check_files(source, target, machine)
    found = {(v.check, int(v.where.rsplit(":", 1)[1])) for v in report.violations}
    assert found & expected, "\n".join(map(str, report.violations))


def test_the_nearest_point_beside_a_corner_knot_is_found_on_either_leg() -> None:
    """Fuzzer find (data/check-corners/corner-wrong-leg-deviation.json): the point written just
    before a corner of a rational polyline, (-2, 1.488, -3.42699) under the default profile, is
    7.11e-6 mm from the leg before the corner and 8.77e-6 mm from the leg after it; the search
    zoomed across the corner knot onto the farther leg and check called it 1.012x the rounding
    allowance off the curve. Distances to the two straight legs are the closed-form oracle."""
    raw = json.loads((CASES / "corner-wrong-leg-deviation.json").read_text())["curves"][0]
    curve = NurbsCurve.build(raw["degree"], raw["knots"], raw["control_points"], raw["weights"])
    before, corner, after = (np.array(raw["control_points"][k]) for k in (1, 2, 3))

    def to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        return float(np.linalg.norm(p - (a + t * (b - a))))

    written = np.array([-2.0, 1.488, -3.42699])
    on_leg = to_segment(written, before, corner)
    assert on_leg < to_segment(written, corner, after) - 1e-6
    _, nearest = nearest_on_curve(curve, written[None, :])
    assert nearest[0] == pytest.approx(on_leg, abs=1e-12)


TURN_BACK = CASES / "inch-turn-back-jerk.json"
TURN_BACK_KNOT = 2.5e-7  # its corner: the path turns back 167 degrees, its legs 13 degrees apart
R6_MM = 0.5e-6 * 25.4 * np.sqrt(3.0)  # output rounding at 6 decimals of an inch


def _segment_mm(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * (b - a))))


def test_the_point_before_a_turn_back_corner_is_measured_on_the_leg_before() -> None:
    """Fuzzer find (json-2901100-390, reduced to data/check-corners/inch-turn-back-jerk.json):
    the point written 1 ms before the rest at a 167-degree polyline corner is 0.58 r from the
    leg before the corner and 0.54 r from the leg after it. The walk's step ended on the corner
    knot, where the curve's derivative is the leg after's: the distance fell along it, so the
    foot just before the knot went unseen and the point was measured on the leg after, its arc
    1.4e-4 mm ahead (tangential jerk 55,628 > 50,000 + 2,750; the written points measured on
    the legs they were stepped on: 49,338). Distances to the straight legs are the oracle."""
    raw = json.loads(TURN_BACK.read_text())["curves"][0]
    inch = np.array(raw["control_points"])
    curve = NurbsCurve.build(raw["degree"], raw["knots"], inch * 25.4, None)
    start, corner, end = inch * 25.4
    # written (inch): two on the way in, the corner, two on the way out
    written = np.array([[0.498994, 1.150995, -0.000004], [0.498998, 1.150998, -0.000001],
                        [0.499, 1.151, 0.0], [0.498999, 1.150998, -0.000001],
                        [0.498995, 1.150993, -0.000003]]) * 25.4
    assert _segment_mm(written[1], corner, end) < _segment_mm(written[1], start, corner) < R6_MM
    foot, dist = project_points(curve, written, 2.0 * R6_MM, R6_MM, 10.0 * R6_MM)
    assert foot[0] < foot[1] < TURN_BACK_KNOT < foot[3] < foot[4]
    assert foot[2] == pytest.approx(TURN_BACK_KNOT, abs=1e-10)
    legs = [(start, corner)] * 2 + [(corner, end)] * 3
    assert dist == pytest.approx([_segment_mm(p, *leg) for p, leg in zip(written, legs)],
                                 rel=1e-6, abs=1e-11)


def test_a_point_out_of_time_before_a_turn_back_corner_is_still_caught(tmp_path: Path) -> None:
    """The point before the corner, moved 2e-5 in (5.1e-4 mm) back along the leg it is on, F
    words set so that each move still takes its period: the motion would cover 0.6 um in the
    last 1 ms before its rest, and measured on that leg the tangential jerk is broken."""
    machine = default_paper_machine()  # its tangential jerk row is the paper model's
    target = tmp_path / "out.nc"
    convert_file(TURN_BACK, target, machine)
    lines = target.read_text().splitlines(keepends=True)
    at_corner = lines.index("X0.499 Y1.151 Z0. F0.18\n")
    points = [np.array([float(v) for v in re.findall(r"[XYZ](-?[\d.]+)", lines[k])])
              for k in (at_corner - 2, at_corner - 1, at_corner)]
    start, corner, _ = np.array(json.loads(TURN_BACK.read_text())["curves"][0]["control_points"])
    leg_in = corner - start
    moved = np.round(points[1] - 2e-5 * leg_in / np.linalg.norm(leg_in), 6)
    per_min = 60.0 / machine.limits.period_s  # inch/min of a move of 1 inch in one period
    lines[at_corner - 1] = ("X{:.6f} Y{:.6f} Z{:.6f}".format(*moved)
                            + f" F{per_min * np.linalg.norm(moved - points[0]):.5f}\n")
    lines[at_corner] = f"X0.499 Y1.151 Z0. F{per_min * np.linalg.norm(points[2] - moved):.5f}\n"
    target.write_text("".join(lines))
    report = check_files(TURN_BACK, target, machine)
    assert {v.check for v in report.violations} == {"tangential-jerk"}, report.violations
