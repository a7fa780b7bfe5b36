"""Sinumerik programs: BSPLINE read as the NURBS of its control points, SD, PL and PW, converted
to moves that start at the current position, end on the last control point and stay inside the
control polygon's hull; every other line passes through byte for byte.

The reference curve is the textbook evaluator of tests/naive_nurbs.py, on knots worked out here
from the PL values.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nurbsfeed.errors import InputError
from nurbsfeed.files import InputFile
from nurbsfeed.gcode.siemens import tokenize_siemens_line
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file
from nurbsfeed.program import CurveBlock, PassThrough
from nurbsfeed.readers.gcode import read_gcode
from tests import naive_nurbs
from tests.conftest import SAMPLES
from tests.gcode_parse import moves

SAMPLE = SAMPLES / "sinumerik-bspline.mpf"
HULL_MM = 1e-5  # the written points are rounded to 0.01 um: inside the hull to that


def read(text: str, name: str = "t.mpf", dialect: str = "auto") -> list:
    lines = InputFile(Path(name), text.encode()).lines()
    return list(read_gcode(Path(name), lines, dialect))


def curves(text: str, name: str = "t.mpf") -> list[CurveBlock]:
    return [item for item in read(text, name) if isinstance(item, CurveBlock)]


PROGRAM = ("N10 G17 G710 G90 G94\nN20 G1 X0. Y0. Z-1. F600.\n"
           "N30 BSPLINE SD=3 X5. Y10. PL=1.\nN40 X15. Y12. PL=2.\nN50 X20. Y0. PW=1.5 PL=0.5\n"
           "N60 X30. Y-8. PL=1.\nN70 X40. Y2. PW=0.5 PL=7.\nN80 X50. Y0. PL=9.\n"
           "N90 G1 X55.\nN100 M30\n")
CONTROL = [[0, 0], [5, 10], [15, 12], [20, 0], [30, -8], [40, 2], [50, 0]]
WEIGHTS = [1, 1, 1, 1.5, 1, 0.5, 1]
# P1..P6 carry PL 1, 2, 0.5, 1, 7, 9; n = 6, p = 3: the spans are the first n - p + 1 = 4
KNOTS = [0, 0, 0, 0, 1, 3, 3.5, 4.5, 4.5, 4.5, 4.5]


def test_bspline_is_the_nurbs_of_its_control_points_pl_and_pw() -> None:
    (block,) = curves(PROGRAM)
    curve = block.curve
    assert curve.degree == 3
    np.testing.assert_array_equal(curve.points[:, :2], CONTROL)
    assert curve.points[:, 2].tolist() == [-1.0] * 7  # Z holds
    for u in np.linspace(0.0, 4.5, 37):
        expected, _, _ = naive_nurbs.evaluate(3, KNOTS, np.column_stack(
            [CONTROL, np.full(7, -1.0)]), WEIGHTS, u)
        np.testing.assert_allclose(curve.point(curve.unit_u(u)), expected, atol=1e-9)


def test_sd_2_is_quadratic_and_its_spans_use_one_more_pl() -> None:
    text = PROGRAM.replace("SD=3", "SD=2")
    (block,) = curves(text)
    assert block.curve.degree == 2
    knots = [0, 0, 0, 1, 3, 3.5, 4.5, 11.5, 11.5, 11.5]
    for u in np.linspace(0.0, 11.5, 24):
        expected, _, _ = naive_nurbs.evaluate(2, knots, np.column_stack(
            [CONTROL, np.full(7, -1.0)]), WEIGHTS, u)
        np.testing.assert_allclose(block.curve.point(block.curve.unit_u(u)), expected,
                                   atol=1e-9)


def test_g91_points_are_relative_to_the_previous_point() -> None:
    text = ("N10 G17 G710 G90 G94\nN20 G1 X1. Y2. Z0. F600.\nN25 G91\n"
            "N30 BSPLINE X5. Y10. PL=1.\nN40 X10. Y2. PL=1.\nN50 X5. Y-12. PL=1.\n"
            "N60 G1 X1.\n")
    (block,) = curves(text)
    np.testing.assert_array_equal(block.curve.points[:, :2], [[1, 2], [6, 12], [16, 14],
                                                             [21, 2]])
    assert block.incremental


def test_the_spline_ends_at_a_motion_command_the_program_end_or_the_file_end() -> None:
    assert len(curves(PROGRAM)) == 1
    ended_by_m30 = PROGRAM.replace("N90 G1 X55.\n", "")
    assert len(curves(ended_by_m30)) == 1
    at_file_end = ended_by_m30.replace("N100 M30\n", "")
    (block,) = curves(at_file_end)
    np.testing.assert_array_equal(block.curve.points[-1, :2], [50, 0])


def test_every_line_but_the_spline_passes_through_byte_for_byte() -> None:
    text = PROGRAM.replace("\n", "\r\n").replace("N60", "; a comment inside\r\nN60")
    items = read(text)
    lines = text.splitlines(keepends=True)
    passed = [item.text for item in items if isinstance(item, PassThrough)]
    inside = [line for line in lines if line.startswith(("N3", "N4", "N5", "N6", "N7", "N8"))]
    assert "".join(passed) == "".join(line for line in lines if line not in inside)
    (block,) = [item for item in items if isinstance(item, CurveBlock)]
    assert block.eol == "\r\n" and block.semicolon_comments


@pytest.mark.parametrize("name, dialect, siemens", [
    ("t.mpf", "auto", True), ("t.SPF", "auto", True), ("t.nc", "auto", True),
    ("t.nc", "siemens", True), ("t.nc", "linuxcnc", False), ("t.nc", "fanuc", False)])
def test_the_dialect_comes_from_the_suffix_the_words_or_the_option(name: str, dialect: str,
                                                                    siemens: bool) -> None:
    if siemens:
        assert len([i for i in read(PROGRAM, name, dialect) if isinstance(i, CurveBlock)]) == 1
    else:
        with pytest.raises(InputError, match=r"^t.nc:3:5: B has no number"):
            read(PROGRAM, name, dialect)


def test_inert_sinumerik_commands_pass_through_and_g4_f_is_no_feed() -> None:
    text = ("N10 G17 G710 G90 G94\nN20 T=\"EM10\" M6\nN30 SOFT FFWON G642\n"
            "N40 CYCLE832(0.01,_FINISH,1)\nN50 G0 X0. Y0. Z0.\nN55 G4 F2.\n"
            "N60 BSPLINE X5. Y10. PL=1.\nN70 X15. Y12. PL=1.\nN80 X20. Y0. PL=1.\n")
    with pytest.raises(InputError, match="no feed is in force"):
        read(text)  # the F of G4 is the dwell time


# ---- converted --------------------------------------------------------------------------------
def hull(points: np.ndarray) -> np.ndarray:
    """The convex hull (K, 2) of points (N, 2), counter-clockwise (monotone chain)."""
    pts = sorted(map(tuple, points))

    def half(seq: list) -> list:
        out: list = []
        for p in seq:
            while len(out) >= 2 and _turn(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1], dtype=float)


def _turn(a: tuple, b: tuple, c: tuple) -> float:
    """> 0 when a -> b -> c turns counter-clockwise."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def outside_hull_mm(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """How far each point (M, 2) lies outside the hull (0 inside): the largest distance past
    an edge line."""
    edges = np.roll(corners, -1, axis=0) - corners
    normals = np.column_stack([edges[:, 1], -edges[:, 0]]) / np.linalg.norm(edges, axis=1)[:, None]
    past = ((points[:, None, :] - corners[None, :, :]) * normals[None, :, :]).sum(axis=2)
    return np.maximum(past.max(axis=1), 0.0)


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> str:
    target = tmp_path_factory.mktemp("siemens") / "out.mpf"
    convert_file(SAMPLE, target, load_machine("default"))
    return target.read_text()


def sample_control() -> np.ndarray:
    (block,) = curves(SAMPLE.read_text())
    return block.curve.points[:, :2]


def test_the_sample_starts_at_the_current_position_ends_on_its_last_point_inside_the_hull(
        converted: str) -> None:
    control = sample_control()
    lines = converted.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("; nurbsfeed: curve 0 "))
    block = [lines[start + 1]]
    for line in lines[start + 2:]:
        if line[:1] not in ("X", "Y", "Z", "F"):
            break
        block.append(line)
    points, feeds, _ = moves("\n".join(block), [0.0, 0.0, -1.0])
    assert block[0].startswith("G1 ")
    np.testing.assert_array_equal(points[-1, :2], control[-1])
    first_step = np.linalg.norm(points[0, :2] - control[0])
    assert first_step < 1e-3  # the first move leaves the current position (0, 0)
    corners = hull(control)
    assert outside_hull_mm(corners, points[:, :2]).max() <= HULL_MM
    # the measure can fail: the hull without the farthest control point leaves points out
    assert outside_hull_mm(hull(np.delete(control, 4, axis=0)), points[:, :2]).max() > 0.1
    assert np.all(feeds <= 1500.0 * (1 + 1e-3))


def test_the_sample_passes_every_other_line_through_and_comments_with_semicolons(
        converted: str) -> None:
    source = SAMPLE.read_text().splitlines()
    out = converted.splitlines()
    spline = [line for line in source if line.split(" ")[0] in ("N90", "N100", "N110", "N120",
                                                                 "N130", "N140", "N150")]
    assert len(spline) == 7
    kept = [line for line in source if line not in spline]
    assert [line for line in out if line in source] == kept
    assert not any(line.startswith("(") for line in out)
    # the profile record, in ';' comments too, then the curve's comment line
    after = out[out.index("N80 G1 Z-1. F600.") + 1:]
    record = [line for line in after if line.startswith("; nurbsfeed profile: ")]
    assert record and after[:len(record)] == record
    assert after[len(record)].startswith("; nurbsfeed: curve 0 N90 ")
    assert out[out.index("N160 G1 X55. Y0.") - 1] == "F1500."


# ---- the line syntax ------------------------------------------------------------------------
@pytest.mark.parametrize(("line", "expected"), [
    ("N10 G1 X=10.5 Y-2 F300 ; feed", [("N", 10.0), ("G", 1.0), ("X", 10.5), ("Y", -2.0),
                                        ("F", 300.0)]),
    (":100 x1.5y2", [("X", 1.5), ("Y", 2.0)]),
    ("N20 T=\"EM 10\" M6 SOFT G642", [("N", 20.0), ("M", 6.0), ("G", 642.0)]),
    ("N30 bspline sd=2 X1 PL=0.5 PW=2", [("N", 30.0), ("BSPLINE", 0.0), ("SD", 2.0),
                                         ("X", 1.0), ("PL", 0.5), ("PW", 2.0)]),
    ("N40 G710 G700 G71 G70", [("N", 40.0), ("G", 21.0), ("G", 20.0), ("G", 21.0), ("G", 20.0)]),
    ("N50 G4 F2.5 S10", [("N", 50.0), ("G", 4.0)]),
    ("N60 CYCLE832(0.01, _FINISH, 1) MSG(\"go\")", [("N", 60.0)]),
])
def test_sinumerik_lines_read_as_words(line: str, expected: list) -> None:
    block = tokenize_siemens_line(line + "\n", 3, "t.mpf")
    assert [(word.letter, word.value) for word in block.words] == expected


def test_a_skip_block_is_read_as_executed_and_keeps_its_words() -> None:
    block = tokenize_siemens_line("/1 N10 G0 X1.\n", 3, "t.mpf")
    assert block.block_delete and [w.letter for w in block.words] == ["N", "G", "X"]


@pytest.mark.parametrize(("line", "col", "message"), [
    ("N10 G1.25 X1", 5, "G1.25 is not a valid G code: a whole number or one decimal from 0 to "
                        "10000"),
    ("N10 R1=5", 5, "'R1=' assigns an R parameter or a variable; nurbsfeed reads literal "
                    "Sinumerik programs only (no R parameters, variables or expressions)"),
    ("N10 X=R1", 5, "X has no number after it (found '=R1'); expressions, AC(), IC() and R "
                    "parameters are not supported: write e.g. X=10.5"),
    ("N10 TRAORI", 5, "'TRAORI' is not a Sinumerik command nurbsfeed reads: it reads words "
                      "(X10.5, G1, F300), BSPLINE with SD, PL, PW, and BRISK, CFC, CFIN, CFTCP, "
                      "COMPCAD, COMPCURV, COMPOF, COMPON, DRIVE, FFWOF, FFWON, FNORM, SOFT, "
                      "SPATH, SUPA, UPATH"),
    ("N10 WORKPIECE(,,,)", 5, "'WORKPIECE(...)' is not read by nurbsfeed (it reads CYCLE832, MSG "
                              "calls, which change no position)"),
    ("N10 G1 X1 @", 11, "unexpected character '@' (a Sinumerik word is an address and a number, "
                        "e.g. X10.5)"),
])
def test_bad_sinumerik_lines_are_located(line: str, col: int, message: str) -> None:
    with pytest.raises(InputError) as caught:
        tokenize_siemens_line(line + "\n", 3, "t.mpf")
    assert str(caught.value) == f"t.mpf:3:{col}: {message}"
