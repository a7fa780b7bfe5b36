"""Bugs the fuzzing tier (tests/fuzz, docs/testing.md "Fuzzing") found in the G-code readers,
one test each, through the command line as the fuzzer saw them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsfeed.analysis.check.curve_checks import foot_arcs
from nurbsfeed.analysis.check.projection import feet_ahead_of_behind, project_points_and_others
from nurbsfeed.cli import main
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import plan_block
from nurbsfeed.planning.plan import KIND_CUSP
from nurbsfeed.program import CurveBlock
from nurbsfeed.readers import read_program
from tests.fuzz.oracle import check_case

ROOT = Path(__file__).resolve().parents[1]

HEAD = "G21 G90 G0 X0 Y0\nF100\n"


def refused(tmp_path: Path, text: str, name: str = "in.nc") -> str:
    """Convert `text`; it must be refused with exit 2 and no output: the message."""
    source = tmp_path / name
    source.write_bytes(text.encode("utf-8", "surrogateescape"))
    target = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(target)])
    assert result.exit_code == 2, result.output
    assert not target.exists()
    assert "internal error" not in result.stderr
    return result.stderr.strip().removeprefix(str(source))


@pytest.mark.parametrize(("line", "message"), [
    ("X#" + "9" * 5000, ":3:2: #99999999...: parameter numbers go from 0 to 999999"),
    ("#" + "9" * 5000 + "=5", ":3:1: #99999999...: parameter numbers go from 0 to 999999"),
    ("#1=#1000000", ":3:4: #1000000: parameter numbers go from 0 to 999999"),
    ("G1 X- # 1234567", ":3:7: #1234567: parameter numbers go from 0 to 999999"),
])
def test_a_parameter_number_of_thousands_of_digits_is_refused_at_its_place(
        tmp_path: Path, line: str, message: str) -> None:
    """int() of a 5000-digit string raises ValueError (Python's 4300-digit limit): it was an
    internal error."""
    assert refused(tmp_path, HEAD + line + "\n") == message


def test_the_largest_parameter_number_and_leading_zeros_are_read(tmp_path: Path) -> None:
    source = tmp_path / "in.nc"
    source.write_text(HEAD + "#999999=5.\n#0007=2.5\nG1 X#999999 Y#7\n")
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(tmp_path / "o.nc")])
    assert result.exit_code == 0, result.stderr
    assert (tmp_path / "o.nc").read_text() == source.read_text()


def test_a_bug_while_loading_a_profile_is_one_line_not_a_traceback(tmp_path: Path) -> None:
    """A 400-digit integer in a profile raised OverflowError in the profile check, outside any
    conversion: the traceback reached the user (a fuzz find). It is refused at its line."""
    profile = tmp_path / "huge.yaml"
    default = (Path(__file__).parents[1] / "configs" / "default.yaml").read_text()
    profile.write_text(default.replace("max_feed_mm_s: 200.0", "max_feed_mm_s: " + "9" * 400))
    source = tmp_path / "in.ngc"
    source.write_text("G17 G21 G0 X0 Y0\nM2\n")
    result = CliRunner().invoke(main, ["convert", str(source), "-m", str(profile), "-o",
                                       str(tmp_path / "out.nc")])
    assert result.exit_code == 2
    assert "Traceback" not in result.stderr and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith(f"{profile}:3:"), result.stderr
    assert not (tmp_path / "out.nc").exists()


def test_usage_errors_are_still_clicks_own(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["convert", "a.nc", "b.nc"])
    assert result.exit_code == 2
    assert result.stderr.endswith("Error: several inputs need -o DIR\n")


FANUC_CURVE = "G06.2 P3 K0 X0 Y0 Z0\nK0 X1 Y1\nK0 X2 Y0\nK1\nK1\nK1\nM30\n"
G62_CURVE = "G6.2 P3 Q1 K0 X0 Y0 Z0\nK0 X1 Y1\nK0 X2 Y0\nG6.2 K1\nG6.2 K1\nG6.2 K1\nM2\n"


@pytest.mark.parametrize(("typo", "curve", "message"), [
    ("G06.3", FANUC_CURVE, ":3:1: G06.3 is a G code nurbsfeed does not know, and K0 on line 4 is "
                           "a knot of a curve nothing opened: write G06.2 to open it"),
    ("G6", FANUC_CURVE, ":3:1: G6 is a G code nurbsfeed does not know, and K0 on line 4"),
    ("G062", FANUC_CURVE, ":3:1: G062 is a G code nurbsfeed does not know, and K0 on line 4"),
    ("G6.3", G62_CURVE, ":3:1: G6.3 is a G code nurbsfeed does not know, and K0 on line 4"),
])
def test_a_mistyped_g06_2_is_refused_at_its_own_line(tmp_path: Path, typo: str, curve: str,
                                                     message: str) -> None:
    """The curve's control points passed through as straight G0 moves (G062 is Fanuc's G62,
    corner override): nothing was refused. Now the first knot blames the unknown code."""
    text = HEAD + curve.replace(curve.split()[0], typo, 1)
    assert refused(tmp_path, text, "in.ngc").startswith(message)


def test_a_g6_2_block_without_its_point_after_a_typo_blames_the_typo(tmp_path: Path) -> None:
    """The G6.2 of the first knot-only line opened a curve: the message blamed that line, three
    lines after the G code that should have been G6.2."""
    text = HEAD + "G6.3 P3 Q1\nG6.2 K1\n"
    assert refused(tmp_path, text, "in.ngc") == (
        ":3:1: G6.3 is a G code nurbsfeed does not know, and the G06.2 on line 4 has no control "
        "point: write G06.2 to open the curve")  # no Q word: read as Fanuc's
    assert refused(tmp_path, HEAD + "G6.2 K1\n", "in.ngc") == (
        ":3:1: the first block of a G06.2 curve needs its first control point (X, Y or Z)")


@pytest.mark.parametrize(("line", "message"), [
    ("K1.", ":3:1: K1.: a NURBS knot with no G06.2 curve open (under G0/G1 K means nothing): "
            "write G06.2 on the curve's first block"),
    ("N5 K0 X1 Y1 R2", ":3:4: K0: a NURBS knot with no G06.2 curve open"),
])
def test_a_knot_with_no_curve_open_is_refused(tmp_path: Path, line: str, message: str) -> None:
    assert refused(tmp_path, HEAD + line + "\n").startswith(message)


@pytest.mark.parametrize("program", [
    "G18 G21 G90 G0 X0 Z0\nF100\nG2 X0 Z0 K5.\nK5.\n",  # G2/G3: K is the arc centre
    "G17 G21 G90 G0 X0 Y0 Z5.\nF100\nG81 X1. Y1. Z-1. R1. K3\nK2\nG80\n",  # a cycle's repeats
    "G17 G21 G90 G0 X0 Y0\nF100\nG1 X1 K0\n",  # a K with a G code in its block: not ours
])
def test_k_words_where_they_mean_something_pass_through(tmp_path: Path, program: str) -> None:
    source = tmp_path / "in.nc"
    source.write_text(program)
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(tmp_path / "o.nc")])
    assert result.exit_code == 0, result.stderr
    assert (tmp_path / "o.nc").read_text() == program


@pytest.mark.parametrize("name", ["in.ngc", "in.nc", "in.json"])
def test_json_under_any_name_is_read_as_json_by_the_tool_and_the_oracle(tmp_path: Path,
                                                                         name: str) -> None:
    """Fuzz seed 32 (samples family): a JSON sample spliced whole into an .ngc or .nc file is
    converted as JSON (its first character is "{"), and the oracle judged its output as a
    G-code program's ('output line not in the input'). Both now follow the README's rule; a
    G-code program is still judged by its pass-through lines."""
    data = (ROOT / "samples" / "quarter-circle.json").read_bytes()
    outcome = check_case(tmp_path, name, b"\n " + data)
    assert outcome.exit_code == 0 and outcome.problem is None, outcome
    gcode = (ROOT / "samples" / "linuxcnc-nurbs-xy.ngc").read_bytes()
    assert check_case(tmp_path, "in.ngc", gcode).problem is None


def test_a_cruise_capped_at_a_nodes_limit_keeps_a_bump_between_nodes_within_it(
        tmp_path: Path) -> None:
    """Fuzz seed 35 (gcode family), under the default (paper-model) profile: a segment's cruise
    capped at the limit of its fast cruise nodes alone (not the lowest of all its fast nodes,
    as the path model now does) ran at 43.43 mm/s over a curvature bump between two nodes,
    0.5 % above both (kappa 0.7816 against 0.7776 and 0.7779), and `check` measured the normal
    jerk v^3 kappa^2 0.09 % above its limit and the rounding allowance. The oracle runs
    convert and check as the fuzzer did."""
    source = ROOT / "tests" / "data" / "peaks" / "cruise-over-a-bump-between-nodes.ngc"
    outcome = check_case(tmp_path, "in.ngc", source.read_bytes())
    assert outcome.exit_code == 0 and outcome.problem is None, outcome


RETRACE = ROOT / "tests" / "data" / "check-turns" / "retrace-cusp-inch.json"
TURN_BACKS = [ROOT / "tests" / "data" / "check-turns" / f"retrace-turn-back-inch{tail}.json"
              for tail in ("", "-b")]


def test_check_allows_for_the_arc_between_feet_as_near_at_a_retracing_cusp(
        tmp_path: Path) -> None:
    """Fuzz seed 36 (json family, json-3601136-539): an inch curve retraces itself through a
    cusp; points written within rounding of it round onto points of the leg in, and `check`'s
    walk kept three of them there (5 r of arc off): tangential jerk 1.06x on an output whose
    trace keeps J_t (49,974 mm/s^3 on the true arc). Such a point's arc is known only to the
    arc between its equally near feet, and the check now allows for it."""
    outcome = check_case(tmp_path, "in.json", RETRACE.read_bytes())
    assert outcome.exit_code == 0 and outcome.problem is None, outcome


def test_only_points_at_the_retracing_cusp_have_another_foot() -> None:
    """The allowance is local: a second foot as near is found only for the points written
    within a few roundings of the cusp, and it lies across the cusp from the foot taken."""
    machine = load_machine("default")
    [block] = [item.in_mm() for item in read_program(RETRACE) if isinstance(item, CurveBlock)]
    plan = plan_block(block, machine)
    [cusp] = plan.key_u[plan.key_kind == KIND_CUSP]
    written = np.round(interpolate(plan).points / 25.4, 6) * 25.4  # the inch output's 6 decimals
    r = 0.5e-6 * math.sqrt(3.0) * 25.4
    foot, dist, other = project_points_and_others(block.curve, written, 2.0 * r, r, 10.0 * r)
    assert dist.max() <= r
    at = block.curve.point(np.array([cusp]))[0]
    two = np.flatnonzero(np.isfinite(other))
    assert 1 <= two.size <= 8, two
    assert np.all(np.linalg.norm(written[two] - at, axis=1) <= 10.0 * r)
    assert np.all((foot[two] - cusp) * (other[two] - cusp) < 0.0)


@pytest.mark.parametrize("key", ["\name", "a\u0007b", "x\udbf2y", "\u2028"])
def test_an_unknown_json_key_is_shown_escaped_on_one_line(tmp_path: Path, key: str) -> None:
    """Fuzz seed 37 (json family, json-3701122-92): a curve key written "\\name" in JSON is a
    newline and "ame"; the unknown-key message printed it raw, a message of two lines (and any
    control character or lone surrogate reached the terminal as it was)."""
    curve = {"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [1, 0]], key: 1}
    for document in ({"curves": [curve]}, {"curves": [{k: v for k, v in curve.items()
                                                       if k != key}], key: 1}):
        message = refused(tmp_path, json.dumps(document), "in.json")
        assert "\n" not in message and "\r" not in message and "\u2028" not in message
        assert f"unknown key {key!r}" in message


def refused_profile(tmp_path: Path, extra_yaml: str) -> str:
    """Convert a sample under the default profile with `extra_yaml` appended; the profile must
    be refused with exit 2: the message."""
    profile = tmp_path / "p.yaml"
    profile.write_text((ROOT / "configs" / "default.yaml").read_text() + extra_yaml)
    result = CliRunner().invoke(main, ["convert", str(ROOT / "samples" / "circle.json"),
                                       "-m", str(profile), "-o", str(tmp_path / "out.nc")])
    assert result.exit_code == 2
    assert not (tmp_path / "out.nc").exists()
    return result.stderr.strip()


def test_an_unknown_profile_key_is_shown_escaped_on_one_line(tmp_path: Path) -> None:
    """The same in a machine profile: a YAML key "odd\\nkey" printed raw split the message."""
    message = refused_profile(tmp_path, '"odd\\nkey\\x07": 1\n')
    assert "\n" not in message and "unknown key 'odd\\nkey\\x07'" in message


def test_a_key_given_twice_is_shown_escaped_on_one_line(tmp_path: Path) -> None:
    """The same class as the unknown key: a JSON or YAML key given twice was echoed raw."""
    text = '{"curves": [{"degree": 1, "knots": [0, 0, 1, 1], "control_points": [[0, 0], [1, 0]]}],'
    message = refused(tmp_path, text + ' "a\\nb": 1, "a\\nb": 2}', "in.json")
    assert "\n" not in message and "'a\\nb' appears twice" in message
    message = refused_profile(tmp_path, '"a\\nb": 1\n"a\\nb": 2\n')
    assert "\n" not in message and "key 'a\\nb' appears twice" in message


@pytest.mark.parametrize("source", TURN_BACKS, ids=lambda p: p.stem)
def test_check_passes_a_curve_retracing_a_segment_through_turn_backs(tmp_path: Path,
                                                                     source: Path) -> None:
    """Fuzz seed 42 (json family, json-4201142-299 and json-4201146-706): inch curves whose
    control points alternate between two points run along one segment and back. `check`
    failed them at 1.023x and 1.065x the tangential jerk beside a turn-back, where the written
    points' trace keeps J_t (49,956 and 49,963 mm/s^3): a point there has a foot on each leg,
    and the arc between them, its allowance, was understated by two thirds (`foot_arcs`)."""
    outcome = check_case(tmp_path, "in.json", source.read_bytes())
    assert outcome.exit_code == 0 and outcome.problem is None, outcome


@pytest.mark.parametrize("source", [RETRACE] + TURN_BACKS, ids=lambda p: p.stem)
def test_the_arc_between_two_feet_is_the_curves_own(source: Path) -> None:
    """The arc between a point's two feet as near, as `check` allows for it, against the
    trapezoid rule on a million samples of |C'| between them (the cusp's kink between the
    feet costs it only O(h^2)): within 1e-4 (Gauss-Legendre is off by a few per cent on the
    one piece of FOOT_ARC_PIECES that holds the kink)."""
    machine = load_machine("default")
    [block] = [item.in_mm() for item in read_program(source) if isinstance(item, CurveBlock)]
    written = np.round(interpolate(plan_block(block, machine)).points / 25.4, 6) * 25.4
    r = 0.5e-6 * math.sqrt(3.0) * 25.4
    foot, _, other = project_points_and_others(block.curve, written, 2.0 * r, r, 10.0 * r)
    s, between = foot_arcs(block.curve, foot, other)
    two = np.flatnonzero(np.isfinite(other))
    assert two.size >= 1
    assert np.all(between[np.isnan(other)] == 0.0) and np.all(np.diff(s) > -2.0 * r)
    for k in two:
        u = np.linspace(min(foot[k], other[k]), max(foot[k], other[k]), 1_000_001)
        speed = block.curve.speed(u)
        arc = float(np.sum(0.5 * (speed[1:] + speed[:-1]) * np.diff(u)))
        assert between[k] == pytest.approx(arc, rel=1e-4), (k, foot[k], other[k])


def test_check_passes_a_point_written_on_the_same_position_past_a_turn_back(
        tmp_path: Path) -> None:
    """Fuzz seed 44 (gcode family, gcode-4400149-302): a Fanuc curve of repeated control
    points turns back on the Y axis; the point two periods past the turn-back rounds to the
    position of the point two before it, on the leg in. The walk gave it that point's foot
    and no other, and `check` failed the output at 1.003x the tangential jerk while its trace
    keeps J_t (49,972 mm/s^3 at full precision). A foot behind one taken before it is now
    looked for again past that one (`feet_ahead_of_behind`), and the arc between is allowed."""
    source = ROOT / "tests" / "data" / "check-turns" / "turn-back-same-position.nc"
    outcome = check_case(tmp_path, "in.nc", source.read_bytes())
    assert outcome.exit_code == 0 and outcome.problem is None, outcome


def test_a_foot_behind_the_walk_gets_the_foot_past_the_turn_back() -> None:
    """On a curve that runs out along X and back, a point on the leg in placed after a point
    nearer the turn-back gets, as its other foot, the mirror parameter on the leg back."""
    curve = NurbsCurve.build(1, [0.0, 0.0, 0.5, 1.0, 1.0],
                             [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    u = np.array([0.2, 0.45, 0.4])  # the third is behind the second: past the turn at 0.5
    targets = curve.point(u)
    other = feet_ahead_of_behind(curve, targets, u, np.full(3, np.nan), 1e-9)
    assert np.isnan(other[:2]).all()
    assert other[2] == pytest.approx(0.6, abs=1e-9)


REVERSAL = ROOT / "tests" / "data" / "stepping-stops" / "reversal-before-corner.nc"


def test_a_reversal_between_a_corner_knot_and_the_sample_before_it_is_a_rest(
        tmp_path: Path) -> None:
    """Fuzz seed 61 (gcode-6100206-129): a quadratic runs from y = 3 down to 0.0375 and back up
    to the corner at u = 1/6 (y(t) = 3 (1 - t)^2 + 0.038 t^2, C' = 0 at t = 3 / 3.038), half a
    micrometre before the corner and inside the last grid interval before it: no sample saw the
    tangent turn back, the motion reversed at speed (7e5 mm/s^3 from the points under either
    planner) and the motion guard refused the valid program. The curve now arrives at the knot
    against the chord from the sample before it, the reversal between them is found and rested
    at, and the program converts within every limit."""
    [block] = [item.in_mm() for item in read_program(REVERSAL, "auto")
               if isinstance(item, CurveBlock)][:1]
    plan = plan_block(block, load_machine("default"))
    reversal = 3.0 / 3.038 / 6.0
    assert np.min(np.abs(plan.key_u - reversal)) < 1e-9
    assert np.any(np.abs(plan.key_u - 1.0 / 6.0) < 1e-12)  # the corner stays a rest too
    outcome = check_case(tmp_path, "in.nc", REVERSAL.read_bytes())
    assert outcome.problem is None, outcome.problem


CUSP_KNOT = ROOT / "tests" / "data" / "stepping-stops" / "reversal-after-cusp-knot.ngc"


def test_a_reversal_just_after_a_knot_where_c_prime_vanishes_is_a_rest(tmp_path: Path) -> None:
    """Fuzz seed 62 (gcode-6200189-377): a quartic along the Y axis stops at its knot u = 0.5
    (C' = 0 there, a cusp), leaves it towards -Y and turns back 0.15 um later, at u = 0.51338,
    inside the grid interval after the knot; the knot's own zero was taken and the interval
    beside it not looked at, so the motion reversed at speed (4e5 mm/s^3 from the points) and
    the guard refused the valid program. The way the curve leaves a zero at a knot is now read
    from a chord 1e-6 of the span long, and the reversal after it is found and rested at."""
    blocks = [item.in_mm() for item in read_program(CUSP_KNOT, "auto")
              if isinstance(item, CurveBlock)]
    plan = plan_block(blocks[1], load_machine("default"))
    _, d1, _ = blocks[1].curve.derivatives(np.linspace(0.505, 0.52, 1501))
    turn = np.linspace(0.505, 0.52, 1501)[np.flatnonzero(np.diff(np.sign(d1[:, 1])))]
    assert turn.size == 1  # C'_y changes sign once there: the reversal (C'_x = C'_z = 0)
    assert np.min(np.abs(plan.key_u - turn[0])) < 2e-5
    assert np.any(plan.key_u == 0.5)
    outcome = check_case(tmp_path, "in.ngc", CUSP_KNOT.read_bytes())
    assert outcome.problem is None, outcome.problem


@pytest.mark.parametrize(("name", "check_motion"), [
    ("slow-degree-one-curves.json", False),
    ("coincident-first-points-inch.json", True),
    ("jerk-vector-refused.ngc", True),
])
def test_the_path_planners_former_findings_convert_and_check_clean(tmp_path: Path, name: str,
                                                                  check_motion: bool) -> None:
    """Fuzz seeds 63, 53 and 52 under the default profile: three degree-1 rational curves at
    0.35 and 0.67 mm/s (146 s of motion) took 13 s, past the fuzz's 10 s, while the banded
    programs grew with the curve's duration; a degree-4 inch curve whose first two control
    points coincide took over 200 s in the S-curve plan's check against the path model; a
    G-code program the motion guard refused (a jerk vector of 243,000 mm/s^3 from the points)
    under every planner then. The reachability passes plan all three: exit 0, the oracle's
    property, and `check` clean on the two short ones (the long one's 145,000 points are the
    fuzz's own check's share)."""
    source = ROOT / "tests" / "data" / "path_planner" / name
    outcome = check_case(tmp_path, "in" + source.suffix, source.read_bytes(),
                         check_motion=check_motion)
    assert outcome.exit_code == 0 and outcome.problem is None, outcome
