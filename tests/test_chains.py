"""Chains of curves (design §3b): merged curves, joints, the lines between curves, and converted
chains against the whole curve they were cut from.

The reference is knot insertion (tests/cut_curves.py): a curve cut at its knots into pieces is
the very same path, so a chain of the pieces must convert within 1 % of the whole curve's cycle,
its points on the whole curve, and every axis's v / a / j measured from its positions within 2 %
of the limit.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from nurbsfeed import chains
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import Machine, load_machine
from nurbsfeed.pipeline import convert_file
from nurbsfeed.planning.chain import (
    JOINT_CAP_HALF_WIDTH,
    chain_feed,
    elevate,
    joint_feed,
    joints,
    merge_curves,
)
from nurbsfeed.program import CurveBlock, PassThrough
from nurbsfeed.readers import read_program
from tests.cut_curves import Piece, cut, cuts_for, gcode_chain
from tests.motion_from_positions import path_motion
from tests.naive_nurbs import evaluate

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples"
DEFAULT = load_machine("default")
CONFIGS = Path(__file__).resolve().parents[1] / "configs"
CYCLE_REL = 0.01  # the bound: a chain within 1 % of the whole curve's cycle
POSITION_REL = 0.02  # v, a, j measured from positions within 2 % of each axis's limit


def _json_curve(path: Path) -> tuple[int, list[float], list[list[float]], list[float]]:
    data = json.loads(path.read_text())
    curve = data["curves"][0] if "curves" in data else data
    points = curve["control_points"]
    return (curve["degree"], curve["knots"], points,
            curve.get("weights", [1.0] * len(points)))


def _pieces(name: str, n: int) -> tuple[list[Piece], Piece]:
    degree, knots, points, weights = _json_curve(SAMPLES / name)
    return cut(degree, knots, points, weights, cuts_for(knots, degree, n)), \
        cut(degree, knots, points, weights, [])[0]


def _built(piece: Piece) -> NurbsCurve:
    return NurbsCurve.build(piece.degree, piece.knots, piece.points, piece.weights)


# ---- the merged curve ---------------------------------------------------------------------------

@pytest.mark.parametrize(("name", "n"), [("butterfly.json", 7), ("circle.json", 3)])
def test_the_merged_curve_is_each_piece(name: str, n: int) -> None:
    """The merged curve, evaluated at each piece's parameters mapped into it, is the piece as
    the textbook evaluator reads it; the pieces' weights are scaled at random first (a rational
    curve does not change), so the merge must rescale them to agree at the joints."""
    pieces, _ = _pieces(name, n)
    rng = np.random.default_rng(29)
    scaled = [Piece(p.degree, p.knots, p.points, p.weights * rng.uniform(0.3, 3.0))
              for p in pieces]
    curves = [_built(p) for p in scaled]
    chain = merge_curves(curves)
    assert chain.curve.knots[0] == 0.0 and chain.curve.knots[-1] == 1.0
    worst = 0.0
    for i, (piece, curve) in enumerate(zip(scaled, curves)):
        own_u = np.linspace(0.0, 1.0, 41)
        merged = chain.curve.point(chain.merged_u(i, own_u))
        for u, got in zip(curve.input_u(own_u), merged):
            want, _, _ = evaluate(piece.degree, piece.knots, piece.points, piece.weights, u)
            worst = max(worst, float(np.abs(got - want).max()))
    assert worst < 1e-9
    assert np.array_equal(chain.piece_of(chain.joint_u), np.arange(len(curves) - 1))
    # cut from one curve, the chain is that curve again: its parameterization (|C'| continuous
    # at the joints) and its knots, the joints' extra copies removed
    whole = _built(_pieces(name, 1)[1])
    assert chain.curve.knots == pytest.approx(whole.knots, abs=1e-12)
    assert chain.curve.points == pytest.approx(whole.points, abs=1e-9)


def test_a_corner_joint_keeps_its_knot() -> None:
    """Two lines at a right angle: nothing is removable, the joint's knot stays repeated
    `degree` times (C0), the tangent jumps there."""
    chain = merge_curves(_two_lines(np.pi / 2))
    assert np.count_nonzero(chain.curve.knots == chain.joint_u[0]) == chain.curve.degree
    assert chain.curve.point(chain.joint_u) == pytest.approx(np.zeros((1, 3)))


def test_a_chain_of_one_is_the_curve_itself() -> None:
    pieces, whole = _pieces("circle.json", 1)
    curve = _built(whole)
    chain = merge_curves([curve])
    assert chain.curve is curve and chain.joint_u.size == 0


def test_the_pieces_feeds_become_one_step_function() -> None:
    """A piece with no F is uncapped (inf) over its range; equal neighbouring steps merge."""
    pieces, _ = _pieces("butterfly.json", 3)
    chain = merge_curves([_built(p) for p in pieces])
    feed_u, feed_mm_s = chain_feed(chain, [(np.array([0.0]), np.array([50.0])),
                                           (np.empty(0), np.empty(0)),
                                           (np.array([0.0, 0.5]), np.array([50.0, 20.0]))])
    assert feed_u.tolist() == [0.0, chain.u_start[1], chain.u_start[2],
                               chain.merged_u(2, np.array([0.5]))[0]]
    assert feed_mm_s.tolist() == [50.0, np.inf, 50.0, 20.0]
    none = chain_feed(chain, [(np.empty(0), np.empty(0))] * 3)
    assert none[0].size == 0 and none[1].size == 0


# ---- joints -------------------------------------------------------------------------------------

def _two_lines(turn_rad: float) -> list[NurbsCurve]:
    """Two straight cubic pieces of 20 mm meeting at the origin, the second turned by turn_rad."""
    first = np.linspace([-20.0, 0.0, 0.0], [0.0, 0.0, 0.0], 4)
    direction = np.array([np.cos(turn_rad), np.sin(turn_rad), 0.0])
    second = np.linspace([0.0, 0.0, 0.0], 20.0 * direction, 4)
    knots = [0, 0, 0, 0, 1, 1, 1, 1]
    return [NurbsCurve.build(3, knots, first), NurbsCurve.build(3, knots, second)]


def test_joint_speeds_follow_the_period_rule() -> None:
    """A knot cut is smooth (no cap); a turn the planner would not see as a corner is capped
    at min over axes of (A T, J T^2) / |dt| (worked by hand here); a corner rests (cap 0)."""
    lim = DEFAULT.limits
    pieces, _ = _pieces("butterfly.json", 5)
    smooth = joints(merge_curves([_built(p) for p in pieces]), lim)
    assert np.all(smooth.turn_rad < 1e-9) and np.all(np.isinf(smooth.cap_mm_s))
    small = 5e-5  # rad: below the planner's corner tolerance (1.4e-4)
    found = joints(merge_curves(_two_lines(small)), lim)
    dt = np.array([np.cos(small) - 1.0, np.sin(small)])
    # Y's jump binds: J_y T^2 / |dt_y| = 50,000 * 1e-6 / 5e-5 = 1000 mm/s, above the feed,
    # and A_y T / |dt_y| = 2500 * 1e-3 / 5e-5 = 50,000; the path's J T^2 / |dt| = 1000 as well
    assert found.turn_rad[0] == pytest.approx(small, rel=1e-6)
    assert np.isinf(found.cap_mm_s[0])  # 1000 mm/s is above the 200 mm/s feed: no cap
    assert dt[1] > 0
    # with a tenth of the jerk the same rule binds below the feed: 5000 * 1e-6 / |dt| at
    # 1.2e-4 rad is 41.7 mm/s (|dt| = 2 sin(turn / 2), the path's and Y's limits equal)
    soft = dataclasses.replace(lim, jerk_mm_s3=5000.0, axis_jerk_mm_s3=(5000.0,) * 3)
    sharper = joints(merge_curves(_two_lines(1.2e-4)), soft)
    assert sharper.cap_mm_s[0] == pytest.approx(5000 * 1e-6 / (2 * np.sin(0.6e-4)), rel=1e-6)
    corner = joints(merge_curves(_two_lines(np.pi / 2)), lim)
    assert corner.cap_mm_s[0] == 0.0 and corner.turn_rad[0] == pytest.approx(np.pi / 2)


def test_a_capped_joint_is_a_feed_step_around_it() -> None:
    chain = merge_curves(_two_lines(1.2e-4))
    caps = np.array([100.0])
    feed_u, feed_mm_s = joint_feed(chain, caps, np.array([0.0]), np.array([150.0]))
    u = chain.joint_u[0]
    assert feed_u.tolist() == [0.0, u - JOINT_CAP_HALF_WIDTH, u + JOINT_CAP_HALF_WIDTH]
    assert feed_mm_s.tolist() == [150.0, 100.0, 150.0]


# ---- which lines a chain runs on across ----------------------------------------------------------

@pytest.mark.parametrize(("line", "joins", "words"), [
    ("(a comment)", True, False),
    ("N120", True, False),
    ("", True, False),
    ("G1 X50. Y0.", True, True),  # the point reached: no length
    ("G0 X50.0000 Y0 Z0", True, True),
    ("G90 G17 G21", True, True),  # modal words already in force
    ("F900.", True, True),  # a new feed cap from here on
    ("G1 X50.1 Y0.", False, False),  # a move with length
    ("M5", False, False),
    ("T2 M6", False, False),
    ("G20", False, False),  # another unit
    ("G91", False, False),
    ("G54", False, False),
    ("G4 P0.5", False, False),  # a dwell
    ("#1 = 5", False, False),
])
def test_lines_a_chain_runs_on_across(tmp_path: Path, line: str, joins: bool,
                                      words: bool) -> None:
    program = tmp_path / "p.nc"
    program.write_text("G21 G90 G17 G94\nG0 X0 Y0 Z0\nG06.2 P2 K0. X0. Y0. Z0. F600.\n"
                       f"K0. X50. Y0.\nK1.\nK1.\n{line}\nM30\n")
    items = list(read_program(program, "fanuc"))
    at = items.index(next(i for i in items if isinstance(i, CurveBlock))) + 1
    passed = items[at]
    assert isinstance(passed, PassThrough) and passed.text == line + "\n"
    assert (passed.joins, passed.words) == (joins, words)


# ---- converted chains against the whole curve ---------------------------------------------------

def _convert(tmp_path: Path, name: str, text: str, machine: Machine = DEFAULT
             ) -> tuple[str, np.ndarray, float]:
    """The output text, the trace rows (N, 11) and the cycle of converting `text`."""
    source = tmp_path / name
    source.write_text(text)
    trace = tmp_path / (name + ".csv")
    report = convert_file(source, tmp_path / (name + ".out"), machine, trace_path=trace)
    rows = np.loadtxt(trace, delimiter=",", skiprows=1, ndmin=2)
    return (tmp_path / (name + ".out")).read_text(), rows, report.cycle_time_s


ZERO_MOVES = ["(joint)", "N7 G1 X{x} Y{y} F2400."]  # a zero-length G1 carrying a new F


@pytest.mark.parametrize(("name", "n", "dialect", "between", "profile"), [
    ("butterfly.json", 4, "fanuc", None, "paper-table1"),
    ("butterfly.json", 20, "linuxcnc", ZERO_MOVES, "paper-table1"),
    ("butterfly.json", 12, "fanuc", ["G0 X{x} Y{y} Z0."], "scurve"),
    ("butterfly.json", 8, "linuxcnc", ZERO_MOVES, "default"),
    ("circle.json", 4, "linuxcnc", None, "default"),
    ("circle.json", 8, "fanuc", ["G0 X{x} Y{y} Z0.", "(between)"], "default"),
    ("quarter-circle.json", 5, "fanuc", ZERO_MOVES, "default"),
])
def test_a_chain_converts_as_the_whole_curve(tmp_path: Path, name: str, n: int, dialect: str,
                                           between: list[str] | None, profile: str) -> None:
    """N pieces in G06.2 / G6.2 blocks, with or without zero-length moves between: within 1 %
    of the whole curve's cycle,
    every point on the whole curve, every axis's v, a, j from positions within 2 % of its
    limit, no rest at a joint, and the lines between the pieces where the motion crosses each
    joint."""
    machine = (load_machine("default", {"planner": "scurve"}) if profile == "scurve"
               else load_machine(profile))
    pieces, whole = _pieces(name, n)
    whole_text = gcode_chain([whole], 12000.0, dialect)
    _, _, whole_cycle = _convert(tmp_path, "whole.nc", whole_text, machine)
    joint_lines = None
    if between:
        joint_lines = []
        for piece in pieces[1:]:
            x, y = (f"{c:.9f}" for c in piece.points[0][:2])
            joint_lines.append([line.format(x=x, y=y) for line in between])
    text = gcode_chain(pieces, 12000.0, dialect, joint_lines)
    out, rows, cycle = _convert(tmp_path, "chain.nc", text, machine)
    assert out.count("(nurbsfeed: curves 0-") == 1  # one chain, one comment
    assert cycle <= (1.0 + CYCLE_REL) * whole_cycle
    # the trace runs on across the chain: k from 0, curve the piece each point lies in
    k, curve, u, xyz = rows[:, 1], rows[:, 0].astype(int), rows[:, 3], rows[:, 8:11]
    assert np.array_equal(k, np.arange(len(rows)))
    assert np.all(np.diff(curve) >= 0) and curve[-1] == n - 1
    # the same path: each point is the whole curve at that parameter (knot insertion keeps u)
    whole_curve = _built(whole)
    on_whole = whole_curve.point(np.array([whole_curve.unit_u(v) for v in u]))
    assert np.abs(on_whole - xyz).max() < 1e-7
    lim = machine.limits
    moved = path_motion(xyz, lim.period_s)
    assert moved.path.speed_mm_s.max() <= lim.feed_mm_s * (1 + POSITION_REL)
    for measured, limit in ((moved.axis_velocity_mm_s, lim.axis_vel_mm_s),
                            (moved.axis_acc_mm_s2, lim.axis_acc_mm_s2),
                            (moved.jerk_mm_s3, lim.axis_jerk_mm_s3)):
        assert np.all(np.abs(measured).max(axis=0) <= np.array(limit) * (1 + POSITION_REL))
    # no rest at a smooth joint: the speed across each is that of its neighbours
    speeds = np.linalg.norm(np.diff(xyz, axis=0), axis=1) / lim.period_s
    crossings = np.flatnonzero(np.diff(curve)) + 1
    assert np.all(speeds[crossings - 1] > 1.0)
    if between:
        _lines_in_place(out, between, xyz, crossings, len(pieces) - 1)


def _lines_in_place(out: str, between: list[str], xyz: np.ndarray, crossings: np.ndarray,
                    n_joints: int) -> None:
    """Each joint's lines come right after the move onto the last point at or before it."""
    lines = out.splitlines()
    chain = next(i for i, line in enumerate(lines) if line.startswith("(nurbsfeed: curves"))
    first = between[-1] if between[-1].startswith("(") else between[0]
    at = [i for i, line in enumerate(lines) if i > chain
          and line.startswith(first.split(" ")[0])]
    assert len(at) == n_joints
    for joint, i in enumerate(at):
        before = lines[i - 1] if first == between[0] else lines[i - len(between)]
        words = dict((w[0], float(w[1:])) for w in before.split() if w[0] in "XY")
        point = xyz[crossings[joint] - 1]
        for axis, value in words.items():
            assert value == pytest.approx(point["XY".index(axis)], abs=1e-4)


def test_a_corner_between_two_curves_ends_the_chain_and_rests(tmp_path: Path) -> None:
    """Two curves meeting at a right angle: the motion rests at the corner (v = 0 there) as two
    curves planned apart, and the line between them comes at the corner."""
    text = ("G21 G90 G17 G94\nG0 X0. Y0. Z0.\n"
            "G06.2 P4 K0. X0. Y0. Z0. F6000.\nK0. X10. Y0.\nK0. X20. Y0.\nK0. X30. Y0.\n"
            "K1.\nK1.\nK1.\nK1.\n(corner)\n"
            "G06.2 P4 K0. X30. Y0. Z0.\nK0. X30. Y10.\nK0. X30. Y20.\nK0. X30. Y30.\n"
            "K1.\nK1.\nK1.\nK1.\nM30\n")
    out, rows, _ = _convert(tmp_path, "corner.nc", text)
    assert "chained" not in out and "(nurbsfeed: curve 1 " in out
    at_corner = np.flatnonzero(np.all(np.abs(rows[:, 8:11] - [30.0, 0.0, 0.0]) < 1e-12, axis=1))
    assert at_corner.size == 2  # the first curve's end and the second's start
    assert np.all(np.abs(rows[at_corner, 5]) < 1e-12)
    lines = out.splitlines()
    at = lines.index("(corner)")
    assert lines[at - 2].startswith("X30.") and lines[at - 1] == "F6000."  # then F restored


def test_a_turn_below_the_corner_tolerance_chains(tmp_path: Path) -> None:
    """A turn of 1e-4 rad (below the planner's corner tolerance) joins, and the motion does not
    stop there; at 1e-3 rad the chain ends."""
    for turn, joined in ((1e-4, True), (1e-3, False)):
        a, b = _two_lines(turn)
        text = gcode_chain([Piece(3, c.knots, c.points, c.weights) for c in (a, b)], 6000.0)
        out, rows, _ = _convert(tmp_path, "turn.nc", text)
        assert ("chained" in out) == joined
        # the two points nearest the joint: one on each side where a period straddles it, the
        # two ends at rest where the chain ends there
        at_joint = np.argsort(np.linalg.norm(rows[:, 8:11], axis=1))[:2]
        assert (rows[at_joint, 5].min() > 50.0) == joined


def test_a_move_with_length_ends_a_chain(tmp_path: Path) -> None:
    pieces, _ = _pieces("circle.json", 2)
    x, y, _ = pieces[1].points[0]
    text = gcode_chain(pieces, 6000.0, "fanuc", [[f"G1 X{x + 0.01:.9f} Y{y:.9f}",
                                                   f"G1 X{x:.9f} Y{y:.9f}"]])
    out, _, _ = _convert(tmp_path, "two.nc", text)
    assert "(nurbsfeed: curve 0 " in out and "(nurbsfeed: curve 1 " in out
    assert "chained" not in out


def _kappa_at(piece: Piece, u: float) -> float:
    _, c1, c2 = evaluate(piece.degree, piece.knots, piece.points, piece.weights, u)
    return float(np.linalg.norm(np.cross(c1, c2)) / np.linalg.norm(c1) ** 3)


@pytest.mark.parametrize(("dialect", "profile"), [("fanuc", "default"), ("linuxcnc", "default"),
                                                  ("linuxcnc", "linuxcnc")])
def test_long_chains_are_planned_in_windows_that_run_on_into_each_other(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dialect: str, profile: str) -> None:
    """Windows of at most MAX_WINDOW_CURVES curves, each cut at the most curved joint in its
    second half (curvature from the textbook evaluator here), planned with the curves after
    its cut as look-ahead and written up to its last point before the cut; the next one runs on
    from there moving (nurbsfeed.windowed): the motion rests only at the chain's ends, the
    cycle is the whole curve's, every joint's lines are in place, the trace runs on across the
    windows, and `check` passes it; under the linuxcnc profile the moves beside its two rests
    are merged (rest_moves) and none at a hand-on."""
    from click.testing import CliRunner

    from nurbsfeed.cli import main

    monkeypatch.setattr(chains, "MAX_WINDOW_CURVES", 4)
    machine = DEFAULT if profile == "default" else load_machine(str(CONFIGS / "linuxcnc.yaml"))
    pieces, whole = _pieces("butterfly.json", 10)
    text = gcode_chain(pieces, 12000.0, dialect, [[f"(joint {j + 1})"] for j in range(9)])
    out, rows, cycle = _convert(tmp_path, "long.nc", text, machine)
    comments = [line for line in out.splitlines() if line.startswith("(nurbsfeed: curve")]
    assert len(comments) >= 3 and all("chained" in c for c in comments)
    assert all(c.endswith(", continued)") for c in comments[:-1])
    assert not comments[-1].endswith(", continued)")
    assert [out.count(f"(joint {j + 1})") for j in range(9)] == [1] * 9
    # the first window writes curves 0 to its cut, at joint 2 or 3 (its second half),
    # whichever is more curved: the next starts inside the cut's curve
    kappa = [max(_kappa_at(pieces[j], pieces[j].knots[-1]),
                 _kappa_at(pieces[j + 1], pieces[j + 1].knots[0])) for j in range(9)]
    cut_at = 2 + int(np.argmax(kappa[2:4]))
    assert comments[0].startswith(f"(nurbsfeed: curves 0-{cut_at} chained")
    assert comments[1].startswith(f"(nurbsfeed: curves {cut_at}-")
    # one trace row a period across the windows, k and t running on, the curve column counting
    # the pieces in file order; at rest only at the chain's two ends
    assert np.array_equal(rows[:, 1], np.arange(rows.shape[0]))
    assert sorted(set(rows[:, 0].astype(int))) == list(range(10))
    still = np.flatnonzero(np.abs(rows[:, 5]) < 1e-9)
    assert np.all((still < 3) | (still >= rows.shape[0] - 3)), still
    whole_cycle = _convert(tmp_path, "whole.nc", gcode_chain([whole], 12000.0, dialect),
                           machine)[2]
    assert cycle == pytest.approx(whole_cycle, rel=2e-3)
    ok = CliRunner().invoke(main, ["check", str(tmp_path / "long.nc"),
                                   str(tmp_path / "long.nc.out"), "--machine",
                                   str(CONFIGS / f"{profile}.yaml")], catch_exceptions=False)
    assert ok.exit_code == 0, ok.stdout


def test_check_judges_a_chain_and_its_joints_lines(tmp_path: Path) -> None:
    """`check` passes a converted chain (its limits read from positions across the joints) and
    fails it when a joint's line is gone from among the moves."""
    from click.testing import CliRunner

    from nurbsfeed.cli import main

    pieces, _ = _pieces("circle.json", 4)
    source = tmp_path / "chain.nc"
    source.write_text(gcode_chain(pieces, 6000.0, "fanuc", [[f"(joint {j})"] for j in range(3)]))
    target = tmp_path / "chain.out"
    convert_file(source, target, DEFAULT)
    ok = CliRunner().invoke(main, ["check", str(source), str(target)], catch_exceptions=False)
    assert ok.exit_code == 0, ok.stdout
    assert "X jerk from positions" in ok.stdout
    target.write_text(target.read_text().replace("(joint 1)\n", ""))
    broken = CliRunner().invoke(main, ["check", str(source), str(target)],
                                catch_exceptions=False)
    assert broken.exit_code == 1
    assert "the lines of joint 2 of the chain are missing among its moves: '(joint 1)'" in (
        broken.stdout)


# ---- pieces of different degrees, and the plan listing -----------------------------------------

def test_a_lower_degree_piece_is_raised_to_the_chains_degree() -> None:
    """The Fanuc multi-curve sample's second curve (quadratic) continues its first (cubic): the
    chain is cubic, the quadratic raised (`elevate`), and each piece is still what the
    textbook evaluator reads from the program's own control points."""
    blocks = [item.in_mm() for item in read_program(SAMPLES / "fanuc-multi-curve.nc")
              if isinstance(item, CurveBlock)][:2]
    assert [b.curve.degree for b in blocks] == [3, 2]
    chain = merge_curves([b.curve for b in blocks])
    assert chain.curve.degree == 3
    for i, block in enumerate(blocks):
        c = block.curve
        own_u = np.linspace(0.0, 1.0, 31)
        got = chain.curve.point(chain.merged_u(i, own_u))
        for u, point in zip(own_u, got):
            want, _, _ = evaluate(c.degree, c.knots, c.points, c.weights, u)
            assert point == pytest.approx(want, abs=1e-9)
    # the quadratic alone, raised twice: the same curve, its weights within its own
    raised = elevate(blocks[1].curve, 4)
    u = np.linspace(0.0, 1.0, 501)
    assert np.abs(raised.point(u) - blocks[1].curve.point(u)).max() < 1e-10
    assert raised.weights.min() >= blocks[1].curve.weights.min() * (1 - 1e-12)


def test_plan_lists_the_joints_of_a_chain(tmp_path: Path) -> None:
    """`plan`: one entry for the chain, a row per joint: a knot cut turns by 0, has no cap and
    is crossed at speed; the curve after the chain keeps its own index."""
    from click.testing import CliRunner

    from nurbsfeed.cli import main

    pieces, _ = _pieces("butterfly.json", 3)
    source = tmp_path / "three.nc"
    # the butterfly is closed, its seam smooth: an M5 keeps a fourth curve there apart
    source.write_text(gcode_chain(pieces, 12000.0).replace("M30\n", "M5\n")
                      + gcode_chain(pieces[:1], 12000.0).split("\n", 2)[2])
    result = CliRunner().invoke(main, ["plan", str(source)], catch_exceptions=False)
    assert result.exit_code == 0, result.stderr
    text = result.stdout
    assert "curves 0-2, a chain planned as one curve" in text and "\ncurve 3 " in text
    rows = [line.split() for line in text.split("joints (mm, mm/s")[1].splitlines()[2:4]]
    assert [row[:2] for row in rows] == [["0", "0|1"], ["1", "1|2"]]
    for row in rows:
        assert float(row[3]) < 1e-6 and row[5] == "-" and float(row[6]) > 20.0


# ---- seeded random chains -----------------------------------------------------------------------

def _random_piece(rng: np.random.Generator, start: np.ndarray, leave: np.ndarray | None
                  ) -> Piece:
    """A random rational curve of degree 2-4 from `start`; leaving along `leave` (a tangent
    joint: its second control point on that ray) when given."""
    degree = int(rng.integers(2, 5))
    n_ctrl = int(rng.integers(degree + 1, degree + 6))
    points = np.vstack([start, start + np.cumsum(rng.normal(0.0, 5.0, (n_ctrl - 1, 3)),
                                                 axis=0)])
    if leave is not None:
        points[1] = start + rng.uniform(1.0, 8.0) * leave
    inner = np.sort(rng.uniform(0.0, 1.0, n_ctrl - degree - 1))
    scale = rng.uniform(0.5, 20.0)
    knots = scale * np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])
    return Piece(degree, knots, points, rng.uniform(0.5, 2.0, n_ctrl))


@pytest.mark.parametrize("seed", range(12))
def test_random_chains_merge_exactly_and_their_joints_turn_as_their_polygons(seed: int) -> None:
    """Seeded random chains of 2-5 rational pieces of mixed degree, each joint tangent or
    turned: the merged curve is every piece (textbook evaluator), and each joint's turn is the
    angle between the control polygon's last leg and the next one's first (a clamped curve
    leaves and arrives along them)."""
    rng = np.random.default_rng(2900 + seed)
    pieces = [_random_piece(rng, np.zeros(3), None)]
    for _ in range(int(rng.integers(1, 5))):
        last = pieces[-1].points
        arrive = (last[-1] - last[-2]) / np.linalg.norm(last[-1] - last[-2])
        pieces.append(_random_piece(rng, last[-1], arrive if rng.random() < 0.5 else None))
    curves = [_built(p) for p in pieces]
    chain = merge_curves(curves)
    assert chain.curve.degree == max(p.degree for p in pieces)
    for i, (piece, curve) in enumerate(zip(pieces, curves)):
        own_u = np.linspace(0.0, 1.0, 17)
        got = chain.curve.point(chain.merged_u(i, own_u))
        for u, point in zip(curve.input_u(own_u), got):
            want, _, _ = evaluate(piece.degree, piece.knots, piece.points, piece.weights, u)
            assert point == pytest.approx(want, abs=1e-8)
    found = joints(chain, DEFAULT.limits)
    for j in range(len(pieces) - 1):
        a = pieces[j].points[-1] - pieces[j].points[-2]
        b = pieces[j + 1].points[1] - pieces[j + 1].points[0]
        cos = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
        turn = float(np.arccos(np.clip(cos, -1.0, 1.0)))
        assert found.turn_rad[j] == pytest.approx(turn, abs=1e-6)
        assert (found.cap_mm_s[j] == 0.0) == (turn > 1e-3)


def _incremental(text: str) -> str:
    """The program under G91 after its G0: every X Y Z the change from the point before."""
    out, prev = [], np.zeros(3)
    for line in text.splitlines():
        words = line.split()
        xyz = [w for w in words if w[0] in "XYZ"]
        if line.startswith("G0 "):
            prev = np.array([float(w[1:]) for w in xyz])
            out += [line, "G91"]
        elif len(xyz) == 3:
            point = np.array([float(w[1:]) for w in xyz])
            head = [w for w in words if w[0] in "GPK"]
            tail = [w for w in words if w[0] in "RF"]
            out.append(" ".join(head + [f"{a}{c:.9f}" for a, c in zip("XYZ", point - prev)]
                                + tail))
            prev = point
        else:
            out.append(line)
    return "\n".join(out) + "\n"


def test_a_long_chain_under_g91_runs_on_in_one_g90_bracket(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The butterfly in 10 G06.2 blocks under G91, in windows of 4 that run on: the absolute
    moves of all its windows lie between one G90 and one G91, the chain's cycle is the whole
    curve's, and `check` passes it (the G90/G91 bracket among its checks)."""
    from click.testing import CliRunner

    from nurbsfeed.cli import main

    monkeypatch.setattr(chains, "MAX_WINDOW_CURVES", 4)
    pieces, whole = _pieces("butterfly.json", 10)
    source = tmp_path / "g91.nc"
    source.write_text(_incremental(gcode_chain(pieces, 12000.0, "fanuc")))
    target = tmp_path / "g91.out"
    report = convert_file(source, target, DEFAULT)
    out = target.read_text().splitlines()
    assert sum(c.endswith(", continued)") for c in out) >= 2
    g90 = [i for i, line in enumerate(out) if line == "G90"]
    g91 = [i for i, line in enumerate(out) if line == "G91"]
    moves = [i for i, line in enumerate(out) if line.startswith(("G1 ", "X", "Y"))]
    assert len(g90) == 1 and len(g91) == 2  # the program's own G91, and the bracket's
    assert g90[0] < moves[0] and moves[-1] < g91[1]
    (tmp_path / "whole.nc").write_text(gcode_chain([whole], 12000.0, "fanuc"))
    whole_report = convert_file(tmp_path / "whole.nc", tmp_path / "whole.out", DEFAULT)
    assert report.cycle_time_s == pytest.approx(whole_report.cycle_time_s, rel=2e-3)
    ok = CliRunner().invoke(main, ["check", str(source), str(target)], catch_exceptions=False)
    assert ok.exit_code == 0, ok.stdout[-2000:]
