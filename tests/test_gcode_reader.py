"""The G-code reader: curves read from Fanuc and LinuxCNC programs, pass-through lines, modal state
and every bad input (tests/data/bad_gcode, one file per case, its expected message on line 1)."""

from __future__ import annotations

import contextlib
import math
import random
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nurbsfeed.errors import CurveError, InputError
from nurbsfeed.files import InputFile
from nurbsfeed.gcode import point_lines
from nurbsfeed.gcode.fanuc import _POINT_LINE, NurbsCurveReader
from nurbsfeed.gcode.linuxcnc import uniform_knots
from nurbsfeed.gcode.point_lines import RUN_LINES, _number, scan_point_lines
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.program import CurveBlock, PassThrough
from nurbsfeed.readers.gcode import read_gcode
from tests.bench.programs import fanuc_program
from tests.conftest import examples

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples"
BAD = Path(__file__).resolve().parent / "data" / "bad_gcode"
PREAMBLE = "G17 G21 G90 G94\nG0 X0 Y0 Z0 F600\n"


def source_lines(text: str) -> list[str]:
    """The lines as the reader counts them: only "\\n" ends a line (a lone "\\r" does not)."""
    return re.findall(r"[^\n]*\n|[^\n]+\Z", text)


def load(path: Path) -> str:
    with open(path, encoding="utf-8", errors="surrogateescape", newline="") as handle:
        return handle.read()


def lines_of(text: str, name: str = "t.nc"):
    """The lines of `text` as the reader gets those of a file holding it."""
    return InputFile(Path(name), text.encode("utf-8", "surrogateescape")).lines()


def read(text: str, dialect: str = "auto", name: str = "t.nc") -> list:
    return list(read_gcode(Path(name), lines_of(text, name), dialect))


def test_lines_end_only_at_newline_and_keep_every_character() -> None:
    text = "%\r\nG0 X1\n\nG1\rY2\r\nM30"
    assert [item.text for item in read(text)] == ["%\r\n", "G0 X1\n", "\n", "G1\rY2\r\n", "M30"]


def curves(items: list) -> list[CurveBlock]:
    return [item for item in items if isinstance(item, CurveBlock)]


def only_curve(text: str, dialect: str = "auto") -> CurveBlock:
    found = curves(read(text, dialect))
    assert len(found) == 1
    return found[0]


def assert_curve(block: CurveBlock, degree: int, knots: list, points: list,
                 weights: list | None = None) -> None:
    """The block's curve is the one these fields build (its knots on [0, 1], the input's range
    in u_origin and u_scale; its weights scaled by a power of two)."""
    curve = block.curve
    expected = NurbsCurve.build(degree, knots, points, weights)
    assert curve.degree == degree
    assert (curve.u_origin, curve.u_scale) == (knots[0], knots[-1] - knots[0])
    np.testing.assert_array_equal(curve.knots, expected.knots)
    np.testing.assert_array_equal(curve.points, points)
    np.testing.assert_array_equal(curve.weights, expected.weights)


# ---- the samples, against hand-derived curves ---------------------------------------------------
def test_linuxcnc_docs_example() -> None:
    """The reference's G5.2 example: start point prepended, knots 0 0 0 1 2 3 3 3 (order 3)."""
    items = read(load(SAMPLES / "linuxcnc-docs.ngc"), name="linuxcnc-docs.ngc")
    (block,) = curves(items)
    z = -0.02
    assert_curve(block, 2, [0, 0, 0, 1, 2, 3, 3, 3],
                 [[0, 0, z], [0, 1, z], [2, 2, z], [2, 0, z], [0, 0, z]], [1, 1, 1, 1, 2])
    assert (str(block.location), block.units, block.eol) == ("linuxcnc-docs.ngc:13:1", "in", "\n")
    assert block.feed_word_after == "F60."
    np.testing.assert_array_equal(block.feed_mm_s, [1.0])  # F60 in/min = 1 in/s


def test_uniform_knots_follow_linuxcnc_knot_vector_creator() -> None:
    assert uniform_knots(5, 3) == [0, 0, 0, 1, 2, 3, 3, 3]
    assert uniform_knots(4, 4) == [0, 0, 0, 0, 1, 1, 1, 1]
    assert uniform_knots(7, 4) == [0, 0, 0, 0, 1, 2, 3, 4, 4, 4, 4]


def test_fanuc_quadratic() -> None:
    (block,) = curves(read(load(SAMPLES / "fanuc-quadratic.nc")))
    z = -0.5
    assert_curve(block, 2, [0, 0, 0, 0.5, 1, 1, 1],
                 [[0, 0, z], [20, 30, z], [40, -10, z], [60, 20, z]])
    assert block.location.line == 10 and block.location.col == 5
    assert block.feed_word_after == "F3000." and block.curve.name == "N70 line 10"
    np.testing.assert_array_equal(block.feed_u, [0.0])
    np.testing.assert_array_equal(block.feed_mm_s, [50.0])


def test_fanuc_rational_quarter_circle_is_exact() -> None:
    (block,) = curves(read(load(SAMPLES / "fanuc-rational-quarter-circle.nc")))
    assert_curve(block, 2, [0, 0, 0, 1, 1, 1], [[50, 0, -1], [50, 50, -1], [0, 50, -1]],
                 [1, 0.7071068, 1])
    points = block.curve.point(np.linspace(0.0, 1.0, 2001))
    radius = np.hypot(points[:, 0], points[:, 1])
    # the weight is written to 7 decimals: sqrt(2)/2 - 0.7071068 = -1.9e-8 moves the arc < 1 um
    assert np.max(np.abs(radius - 50.0)) < 1e-6
    assert np.max(np.abs(radius - 50.0)) > 1e-9  # ... and it is the written weight, not sqrt(2)/2


def test_fanuc_multi_curve_crlf_modal_continuation_and_feed_steps() -> None:
    items = read(load(SAMPLES / "fanuc-multi-curve.nc"))
    first, second, third = curves(items)
    assert_curve(first, 3, [0, 0, 0, 0, 0.3, 0.6, 1, 1, 1, 1],
                 [[0, 0, -1], [10, 15, -1], [25, 15, -1], [35, 0, -1], [45, -15, -1],
                  [60, -15, -1]], [1, 1, 1.2, 1, 1, 1])
    np.testing.assert_array_equal(first.feed_u, [0.0, 0.6])  # F2500. on the knot-0.6 point
    np.testing.assert_allclose(first.feed_mm_s, [4000 / 60, 2500 / 60], rtol=1e-15)
    # N170 has no G06.2: the modal curve starts at the end of the first, at the F in force
    assert_curve(second, 2, [0, 0, 0, 1, 2, 2, 2],
                 [[60, -15, -1], [75, -15, -1.5], [75, 0, -2], [65, 10, -2]])
    np.testing.assert_allclose(second.feed_mm_s, [2500 / 60], rtol=1e-15)
    assert (second.location.line, second.location.col) == (22, 6)
    assert_curve(third, 3, [0, 0, 0, 0, 0.5, 1, 1, 1, 1],
                 [[0, 30, -0.5], [15, 45, -0.5], [30, 20, -0.5], [45, 45, -0.5], [60, 30, -0.5]])
    assert [c.feed_word_after for c in (first, second, third)] == ["F2500.", "F2500.", "F5000."]
    assert {c.eol for c in (first, second, third)} == {"\r\n"}


def test_linuxcnc_g62_with_q_and_g62_knot_lines() -> None:
    (block,) = curves(read(load(SAMPLES / "linuxcnc-g62.ngc")))
    assert_curve(block, 3, [0, 0, 0, 0, 1, 1, 1, 1],
                 [[0, 0, -1], [10, 30, -1], [40, 30, -1], [50, 0, -1]])
    assert block.feed_word_after == "F2500."


def test_orders_at_the_envelope_edge_are_read() -> None:
    """P10 / L10 (degree 9), the highest order nurbsfeed accepts (docs/refusals.md, "Input
    envelope");
    P11 / L11 are refused at the word (tests/data/bad_gcode/*-order-above-envelope.nc)."""
    points = [[float(i), float(i % 3), 0.0] for i in range(10)]
    g62 = PREAMBLE + "G6.2 P10 Q1 K0 X0 Y0 F1200\n" + "".join(
        f"K0 X{x:g} Y{y:g}\n" for x, y, _ in points[1:]) + "G6.2 K1\n" * 10 + "G0 Z5\n"
    assert_curve(only_curve(g62), 9, [0.0] * 10 + [1.0] * 10, points)
    g52 = PREAMBLE + "G5.2 L10\n" + "".join(f"X{x:g} Y{y:g} P1\n" for x, y, _ in points[1:]) + \
        "G5.3\nG0 Z5\n"
    assert_curve(only_curve(g52), 9, uniform_knots(10, 10), points)


def test_inch_program_keeps_inches() -> None:
    (block,) = curves(read(load(SAMPLES / "inch-program.nc")))
    assert block.units == "in"
    assert_curve(block, 3, [0, 0, 0, 0, 1, 1, 1, 1],
                 [[0, 0, -0.02], [0.4, 0.8, -0.02], [1.2, 0.8, -0.02], [1.6, 0, -0.02]])
    np.testing.assert_allclose(block.feed_mm_s, [80 / 60], rtol=1e-15)  # in/s here


# The lines each sample's NURBS blocks occupy (1-based, inclusive), counted by hand.
BLOCK_LINES = {
    "linuxcnc-docs.ngc": [(13, 18)],
    "fanuc-quadratic.nc": [(10, 16)],
    "fanuc-rational-quarter-circle.nc": [(9, 14)],
    "fanuc-multi-curve.nc": [(11, 20), (22, 28), (41, 49)],
    "linuxcnc-g62.ngc": [(11, 18)],
    "inch-program.nc": [(9, 16)],
}


@pytest.mark.parametrize("name", sorted(BLOCK_LINES))
def test_every_other_line_passes_through_byte_for_byte(name: str) -> None:
    text = load(SAMPLES / name)
    lines = source_lines(text)
    ranges = BLOCK_LINES[name]
    inside = {n for first, last in ranges for n in range(first, last + 1)}
    expected = [line for n, line in enumerate(lines, start=1) if n not in inside]
    items = read(text)
    assert [item.text for item in items if isinstance(item, PassThrough)] == expected
    assert [c.location.line for c in curves(items)] == [first for first, _ in ranges]
    # ... and in file order: each curve sits where its block was
    order = [("C" if isinstance(item, CurveBlock) else "P") for item in items]
    expected_order = []
    for n in range(1, len(lines) + 1):
        if any(n == first for first, _ in ranges):
            expected_order.append("C")
        elif n not in inside:
            expected_order.append("P")
    assert order == expected_order
    if name == "fanuc-multi-curve.nc":
        assert all(line.endswith("\r\n") for line in expected)


# ---- one curve, three dialects ------------------------------------------------------------------
G06_2 = PREAMBLE + """G06.2 P3 K0. X0. Y0. R2. F1200.
K0. X10. Y20. R1.
K0. X30. Y20. R0.5
K1. X40. Y0. R1.
K2. X50. Y10. R1.
K3.
K3.
K3.
"""
G6_2 = PREAMBLE + """G6.2 P3 Q2 K0 X0 Y0 R2 F1200
K0 X10 Y20 R1
K0 X30 Y20 R0.5
K1 X40 Y0 R1
K2 X50 Y10 R1
G6.2 K3
G6.2 K3
G6.2 K3
"""
G5_2 = PREAMBLE + """F1200
G5.2 P2 L3
X10 Y20 P1
X30 Y20 P0.5
X40 Y0 P1
X50 Y10 P1
G5.3
"""


@pytest.mark.parametrize("dialect", ["auto", "linuxcnc"])
def test_same_curve_as_g06_2_g6_2_and_g5_2(dialect: str) -> None:
    fanuc = only_curve(G06_2)
    linuxcnc_g62 = only_curve(G6_2, dialect)
    linuxcnc_g52 = only_curve(G5_2, dialect)
    for other in (linuxcnc_g62, linuxcnc_g52):
        for field in ("knots", "points", "weights"):
            np.testing.assert_array_equal(getattr(other.curve, field),
                                          getattr(fanuc.curve, field))
        np.testing.assert_array_equal(other.feed_mm_s, fanuc.feed_mm_s)
    assert_curve(fanuc, 2, [0, 0, 0, 1, 2, 3, 3, 3],
                 [[0, 0, 0], [10, 20, 0], [30, 20, 0], [40, 0, 0], [50, 10, 0]],
                 [2, 1, 0.5, 1, 1])


def test_g6_2_without_q_is_fanuc_in_auto_and_linuxcnc_when_told() -> None:
    text = PREAMBLE + "G91\nG6.2 P3 K0 X0 Y0 Z0\nK0 X1 Y1\nK0 X1 Y-1\nK1\nK1\nK1\n"
    assert only_curve(text).incremental  # Fanuc rules accept G91
    with pytest.raises(InputError, match="G6.2 under G91 is not supported"):
        read(text, "linuxcnc")


def test_unknown_dialect_is_refused_at_the_call() -> None:
    with pytest.raises(InputError) as caught:
        read_gcode(Path("t.nc"), lines_of(""), "heidenhain")
    assert str(caught.value) == ("unknown G-code dialect 'heidenhain' (use auto, fanuc, linuxcnc, "
                                 "siemens)")


# ---- modal state --------------------------------------------------------------------------------
def test_fanuc_g91_control_points_are_relative_to_the_previous_one() -> None:
    block = only_curve("G21 G90 G0 X1 Y2 Z3\nG91\nG06.2 P3 K0 X0 Y0 Z0 F1000\n"
                       "K0 X1 Y1\nK0 X1 Y-1 Z2\nK1\nK1\nK1\nG1 X1\n")
    assert_curve(block, 2, [0, 0, 0, 1, 1, 1], [[1, 2, 3], [2, 3, 3], [3, 2, 5]])
    assert block.incremental


def test_linuxcnc_g5_2_g91_points_are_relative_to_the_block_start() -> None:
    """interp_convert.cc find_ends adds the current position, which moves only at G5.3."""
    block = only_curve("G21 G90 G0 X1 Y2 Z3\nG91\nG5.2\nX1 Y1 P1\nX2 Y0 P1 F60\nG5.3\n")
    assert_curve(block, 2, [0, 0, 0, 1, 1, 1], [[1, 2, 3], [2, 3, 3], [3, 2, 3]])
    assert block.incremental and block.feed_word_after == "F60."


@pytest.mark.parametrize("plane, words, points", [
    ("G18", ["X1 Z1", "X2 Z0"], [[1, 2, 3], [1, 2, 1], [2, 2, 0]]),
    ("G19", ["Y1 Z1", "Y2 Z0"], [[1, 2, 3], [1, 1, 1], [1, 2, 0]]),
])
def test_g5_2_plane_holds_the_third_axis(plane: str, words: list, points: list) -> None:
    text = f"G21 G90 G0 X1 Y2 Z3 F600\n{plane}\nG5.2\n{words[0]} P1\n{words[1]} P1\nG5.3\n"
    assert_curve(only_curve(text), 2, [0, 0, 0, 1, 1, 1], points)


def test_g5_2_line_with_a_point_keeps_the_start_weight_1_and_f_on_g5_3_wins() -> None:
    block = only_curve(PREAMBLE + "F500\nG5.2 X10 Y20 P3 L3\nX30 Y20 P1 F800\nX40 Y0 P1\n"
                                  "G5.3 F900\n")
    assert_curve(block, 2, [0, 0, 0, 1, 2, 2, 2],
                 [[0, 0, 0], [10, 20, 0], [30, 20, 0], [40, 0, 0]], [1, 3, 1, 1])
    np.testing.assert_array_equal(block.feed_mm_s, [15.0])  # F900, in force at G5.3
    assert block.feed_word_after == "F900."


def test_reference_return_and_dwell_between_fanuc_curves_pass_through() -> None:
    text = (PREAMBLE + "G06.2 P3 K0 X0 Y0 F500\nK0 X1 Y1\nK0 X2 Y0\nK1\nK1\nK1\n"
            "G04 X1.5\nG06.2 P3 K0 X2 Y0 F500\nK0 X3 Y1\nK0 X4 Y0\nK1\nK1\nK1\n"
            "G91 G28 Z0.\nG90\n")
    items = read(text)
    assert [type(item).__name__[0] for item in items] == list("PPCPCPP")
    assert items[3] == PassThrough("G04 X1.5\n")  # a dwell: X is a time, the tool stays at X2


def test_curve_end_is_the_next_start() -> None:
    text = (PREAMBLE + "G5.2\nX10 Y10 P1\nX20 Y0 P1\nG5.3\n"
            "G06.2 P3 K0 X20 Y0 Z0 F900\nK0 X30 Y10\nK0 X40 Y0\nK1\nK1\nK1\n")
    first, second = curves(read(text))
    np.testing.assert_array_equal(second.curve.points[0], first.curve.points[-1])


@pytest.mark.parametrize("position, first_point, ok", [
    ("X10.123", "X10.1234", True),  # 3 vs 4 decimals: half a unit of the 3rd, 0.0005
    ("X10.123", "X10.1236", False),
    ("X10.5", "X10.549", True),  # 1 decimal: 0.05
    ("X10.5", "X10.551", False),
    ("X10.", "X10.0004", True),  # no fractional digits, no precision: the IS-B floor, 0.0005
    ("X10.", "X10.0006", False),
])
def test_first_control_point_tolerance_both_sides(position: str, first_point: str,
                                                  ok: bool) -> None:
    text = (f"G21 G90 G0 {position} Y0 Z0\nG06.2 P3 K0 {first_point} Y0 F900\n"
            "K0 X30 Y10\nK0 X40 Y0\nK1\nK1\nK1\n")
    if ok:
        assert only_curve(text).curve.points[0][0] == float(first_point[1:])
    else:
        with pytest.raises(InputError, match="Fanuc alarm PS1009"):
            read(text)


def test_unknown_position_skips_the_check_for_programmed_axes() -> None:
    text = ("G21 G90 G0 X0 Y0 Z5\nG91 G28 Z0\nG90\n"
            "G06.2 P3 K0 X0 Y0 Z-1 F900\nK0 X10 Y10\nK0 X20 Y0\nK1\nK1\nK1\n")
    assert only_curve(text).curve.points[0].tolist() == [0, 0, -1]
    moved_later = text.replace("Z-1 F900", "F900").replace("K0 X20 Y0", "K0 X20 Y0 Z-1")
    with pytest.raises(InputError, match=r"^t.nc:4:1: Z is unknown here \(after G28 on line 2\)"):
        read(moved_later)


@pytest.mark.parametrize("before", [
    "G0 X25.4 Y0 Z0\nG20\n",  # G20 converts the known position
    "G20\nG92 X1 Y0 Z0\n",  # G92 sets it
    "G20\nG0 X0 Y0 Z0\n/G0 X1\n",  # a block-delete line counts as executed
    "G20\nG54 G0 X1 Y0 Z0\n",  # a move in the block of a frame change sets its axes
    "G20\nG0 X0.5 Y0 Z0\nG91 G0 X0.5\nG90\n",
    "G20\nG0 X0 Y0 Z0\nG43 H1 Z0\nG0 X1\n",  # G43 loses Z, its Z word sets it again
])
def test_position_tracking(before: str) -> None:
    text = before + "G06.2 P3 K0 X1. Y0 F40\nK0 X2 Y1\nK0 X3 Y0\nK1\nK1\nK1\n"
    assert only_curve(text).curve.points[0].tolist() == [1, 0, 0]


@pytest.mark.parametrize("before, lost", [
    ("G0 X1 Y0 Z0\nG10 L2 P1 X5\n", "after G10 on line 3"),
    ("G0 X1 Y0 Z0\nG68 X0 Y0 R30\n", "after G68 on line 3"),
    ("G0 X1 Y0 Z0\nG53 G0 Z0\n", "after G53 on line 3"),
    ("G0 X1 Y0 Z0\nG81 X1 Y0 Z-5 R1 F100\nG80\n", "after canned cycle G81 on line 3"),
    ("G0 X1 Y0 Z0\nG38.2 Z-10 F100\n", "after probing G38.2 on line 3"),
    ("G0 X1 Y0 Z0\nG31 Z-10 F100\n", "after G31 on line 3"),
    ("G0 X1 Y0 Z0\nM98 P100\n", "after M98 on line 3"),
    ("G0 X1 Y0 Z0\nG200 Z4\n", "after G200 on line 3, a G code nurbsfeed does not interpret"),
    ("G0 X1 Y0 Z0 F600\nG5.2\nX2 Y1 P1\nX1 Y0 P1\nG5.3\nZ1\n",
     "after axis words with no motion mode in effect on line 7"),
])
def test_what_loses_z(before: str, lost: str) -> None:
    text = "G21 G90\n" + before + "G06.2 P3 K0 X1 Y0 F40\nK0 X2 Y1\nK0 X3 Y0 Z1\nK1\nK1\nK1\n"
    with pytest.raises(InputError, match=rf"Z is unknown here \({re.escape(lost)}\)"):
        read(text)


def test_feed_from_a_parameter_is_restored_as_its_value() -> None:
    block = only_curve(PREAMBLE + "#1=1500.\nG06.2 P3 K0 X0 Y0 F#1\nK0 X1 Y1\nK0 X2 Y0\n"
                                  "K1\nK1\nK1\n")
    assert block.feed_word_after == "F1500."
    np.testing.assert_array_equal(block.feed_mm_s, [25.0])


def test_feed_in_force_before_the_block_holds_until_a_control_point_changes_it() -> None:
    block = only_curve(PREAMBLE + "G1 X0 F600\nG06.2 P3 K0 X0 Y0\nK0 X1 Y1\nK0 X2 Y0\n"
                                  "K0.25 X3 Y1 F1200\nK0.5 X4 Y0 F1200\nK0.75 X5 Y1 F300\n"
                                  "K1\nK1\nK1\n")
    np.testing.assert_array_equal(block.feed_u, [0.0, 0.25, 0.75])  # repeated F1200 merged
    np.testing.assert_array_equal(block.feed_mm_s, [10.0, 20.0, 5.0])
    assert block.feed_word_after == "F300."


def test_comment_lines_inside_a_block_are_kept_before_it() -> None:
    text = PREAMBLE + "G06.2 P3 K0 X0 Y0 F500\n(mid-curve note)\n\nK0 X1 Y1\nK0 X2 Y0\nK1\nK1\nK1\n"
    items = read(text)
    assert [type(item).__name__ for item in items] == ["PassThrough"] * 3 + ["CurveBlock"]
    assert items[2] == PassThrough("(mid-curve note)\n\n")


def test_the_reader_streams() -> None:
    """Items come out before the rest of the file is read: an error on line 4 comes after."""
    stream = read_gcode(Path("t.nc"), lines_of("G21\nG90\nG0 X0\nG1 X[1]\n"))
    assert next(stream) == PassThrough("G21\n")
    assert next(stream) == PassThrough("G90\n")
    assert next(stream) == PassThrough("G0 X0\n")
    with pytest.raises(InputError, match="^t.nc:4:5: expressions"):
        next(stream)


# ---- declarative bad inputs ---------------------------------------------------------------------
BAD_FILES = sorted(BAD.glob("*.nc"))


def test_there_are_bad_input_cases() -> None:
    assert len(BAD_FILES) >= 70


@pytest.mark.parametrize("path", BAD_FILES, ids=[p.stem for p in BAD_FILES])
def test_bad_input(path: Path) -> None:
    text = load(path)
    lines = text.splitlines()
    assert lines[0].startswith("; expect: ")
    expected = lines[0][len("; expect: "):]
    dialect = lines[1][len("; dialect: "):] if lines[1].startswith("; dialect: ") else "auto"
    with pytest.raises(InputError) as caught:
        read(text, dialect, name=str(path))
    assert str(caught.value) == f"{path}:{expected}"


CURVE_ERRORS = {"fanuc-fewer-control-points", "fanuc-knot-decreasing", "fanuc-end-not-clamped",
                "fanuc-weight-zero", "linuxcnc-g5-2-weight-zero",
                "fanuc-control-point-beyond-envelope", "fanuc-control-point-beyond-envelope-in-run",
                "fanuc-current-position-beyond-envelope", "fanuc-knot-span-beyond-envelope",
                "fanuc-weight-ratio-beyond-envelope",
                "linuxcnc-g5-2-current-position-beyond-envelope"}


@pytest.mark.parametrize("name", sorted(CURVE_ERRORS))
def test_curve_definition_errors_are_curve_errors(name: str) -> None:
    path = BAD / f"{name}.nc"
    with pytest.raises(CurveError):
        read(load(path), name=str(path))


# ---- fuzz: mutated programs fail only with InputError -------------------------------------------
SAMPLE_TEXTS = [load(p) for p in sorted(SAMPLES.glob("*.n*c")) + sorted(SAMPLES.glob("*.mpf"))
                ] + [G06_2, G6_2, G5_2, fanuc_program(1)]
TOKENS = ["K1.", "K0", "K3", "X5.", "Y-2", "Z0", "R0.5", "R0", "P3", "P2", "P1", "Q1", "L4", "F0",
          "F1000.", "G06.2", "G6.2", "G5.2", "G5.3", "G1", "G0", "G91", "G90", "G41", "G40",
          "G28", "G93", "G92 X0", "G81", "G80", "G20", "G21", "M6", "#1=2.", "X#1", "(c)", ";",
          "/", "%", "N5", "G18", "G19", "G17.1", "[", "#", "\r", "G5", "G5.1", "I3.", "J-2",
          "Q-1.", "#<a>=1", "X#<a>", "#<", "BSPLINE", "PL=1.", "PW=0.5", "SD=2", "ASPLINE",
          "X=2.", "G70", "G710", "M30"]


@st.composite
def mutated_programs(draw: st.DrawFn) -> tuple[str, str]:
    text = draw(st.sampled_from(SAMPLE_TEXTS))
    rng = random.Random(draw(st.integers(0, 2**32 - 1)))
    lines = source_lines(text)
    for _ in range(draw(st.integers(1, 4))):
        if not lines:
            break
        i = rng.randrange(len(lines))
        kind = rng.randrange(6)
        if kind == 0:
            del lines[i]
        elif kind == 1:
            lines.insert(i, lines[rng.randrange(len(lines))])
        elif kind == 2:
            j = rng.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == 3:
            pos = rng.randrange(len(lines[i]) + 1)
            lines[i] = lines[i][:pos] + rng.choice(TOKENS) + " " + lines[i][pos:]
        elif kind == 4:
            lines[i] = " ".join(rng.choices(TOKENS, k=rng.randrange(1, 3))) + "\n"
        else:
            pos = rng.randrange(max(len(lines[i]) - 1, 1))
            lines[i] = lines[i][:pos] + rng.choice("0123456789.-+ XKYRFP") + lines[i][pos + 1:]
    return "".join(lines), draw(st.sampled_from(["auto", "fanuc", "linuxcnc", "siemens"]))


@settings(max_examples=examples(1500), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(mutated_programs())
def test_mutated_programs_fail_only_with_input_errors(case: tuple[str, str]) -> None:
    text, dialect = case
    try:
        items = read(text, dialect)
    except InputError as exc:
        assert exc.location is not None and exc.location.file == "t.nc"
        return
    passed = iter(source_lines(text))
    for item in items:
        if isinstance(item, PassThrough):  # (the inert lines inside a block come as one)
            assert all(line in passed for line in source_lines(item.text))  # in order
        else:
            curve = item.curve
            assert len(curve.knots) == curve.n_ctrl + curve.degree + 1
            assert item.feed_u[0] == curve.u_min and len(item.feed_u) == len(item.feed_mm_s)
            assert all(v > 0 for v in item.feed_mm_s) and not any(math.isnan(v)
                                                                  for v in item.feed_mm_s)


# ---- the control-point fast paths read like the words ------------------------------------------
def outcome(text: str, dialect: str) -> object:
    """Everything a read yields (or the error it raises), comparable with ==."""
    try:
        items = read(text, dialect)
    except InputError as exc:
        return type(exc).__name__, str(exc)
    return [item.text if isinstance(item, PassThrough) else
            (item.curve.degree, item.curve.knots.tolist(), item.curve.points.tolist(),
             item.curve.weights.tolist(), item.curve.name, item.location, item.units, item.eol,
             item.incremental, item.feed_word_after, item.feed_u.tolist(),
             item.feed_mm_s.tolist()) for item in items]


def with_fast_paths(text: str, dialect: str) -> object:
    """`outcome` with point runs read even where the scan is not compiled (NURBSFEED_NO_JIT=1
    runs the very same scan as plain Python)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(point_lines, "RUNS_ENABLED", True)
        return outcome(text, dialect)


def without_fast_path(text: str, dialect: str) -> object:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(NurbsCurveReader, "take_line", lambda self, line_text, line: False)
        patch.setattr(NurbsCurveReader, "take_run", lambda self, program, pos, line: (0, pos))
        patch.setattr(NurbsCurveReader, "take_knot_line", lambda self, line_text, line: None)
        return outcome(text, dialect)


def lines_read_in_runs(text: str) -> int:
    read_in_runs = 0
    take_run = NurbsCurveReader.take_run

    def counting(self: NurbsCurveReader, program: object, pos: int, line: int) -> tuple[int, int]:
        nonlocal read_in_runs
        n, end = take_run(self, program, pos, line)  # type: ignore[arg-type]
        read_in_runs += n
        return n, end

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(point_lines, "RUNS_ENABLED", True)
        patch.setattr(NurbsCurveReader, "take_run", counting)
        with contextlib.suppress(InputError):
            read(text)
    return read_in_runs


def points_curve(lines: list[str], order: int = 4, close: str = "K9\n", start: str = "X0 Y0 Z0",
                 opening: str = PREAMBLE + "G06.2 P{order} ") -> str:
    """A G06.2 curve of order `order` from `start`: `opening`, its clamped start, `lines`, and
    `order` closing knots `close`."""
    head = [f"{opening.format(order=order)}K0 {start} F600\n"] + [f"K0 {start}\n"] * (order - 1)
    return "".join(head + lines) + close * order


RUN = [f"K{j / 8:g} X{j * 1.25:.4f} Y{-j * 0.1:.3f} Z{j % 3 * 0.05:.2f} R{1 + j % 2 * 0.25}\n"
       for j in range(1, 13)]  # 12 lines a run reads, knots 0.125 .. 1.5


def run_with(index: int, line: str) -> list[str]:
    lines = list(RUN)
    lines[index] = line
    return lines


FAST_PATH_CASES = {
    "canonical": PREAMBLE + "G06.2 P4 K0. X0. Y0. Z0. R1. F600.\nK0. X1. Y2. Z0.5 R0.8\n"
                 "K0. X2.5 Y2. Z0.5\nK0. X4. Y0.000 Z-.5 R1.25\nk.5 x5. y1. z0. r1.\n"
                 "K1.\nK1.\nK1.\nK1.\nG1 X0.\n",
    "crlf and two curves": (PREAMBLE + "G06.2 K0 X0 Y0 Z0\nK0 X1 Y1 Z0\nK0 X2 Y0 Z0\n"
                            "K0 X3 Y1 Z0\nK1\nK1\nK1\nK1\nK0 X3 Y1 Z0\nK0 X4 Y2 Z0\nK0 X5 Y1 Z0"
                            "\nK0 X6 Y0 Z0\nK1\nK1\nK1\nK1\nG0 Z5\n").replace("\n", "\r\n"),
    "incremental": (PREAMBLE + "G91\nG06.2 K0 X0 Y0 Z0\nK0 X1. Y1. Z0\nK0 X1 Y-1 Z0\n"
                    "K0 X1. Y1. Z0.\nK1\nK1\nK1\nK1\nG90\n"),
    "weight zero": PREAMBLE + "G06.2 K0 X0 Y0 Z0\nK0 X1 Y1 Z0 R0\nK0 X2 Y0 Z0\n",
    "knot decreasing": PREAMBLE + "G06.2 K0.5 X0 Y0 Z0\nK0.5 X1 Y1 Z0\nK0.2 X2 Y0 Z0\n",
    "start not clamped": PREAMBLE + "G06.2 K0 X0 Y0 Z0\nK0.1 X1 Y1 Z0\nK0.2 X2 Y0 Z0\n",
    "interior knot splits": PREAMBLE + ("G06.2 P3 K0 X0 Y0 Z0\nK0 X1 Y1 Z0\nK0 X2 Y0 Z0\n"
                                        "K0.5 X3 Y1 Z0\nK0.5 X4 Y0 Z0\nK0.5 X5 Y1 Z0\n"),
    "knots after closing": PREAMBLE + ("G06.2 P2 K0 X0 Y0 Z0\nK0 X1 Y1 Z0\nK1\nK0 X2 Y0 Z0\n"),
    "file ends among the points": PREAMBLE + ("G06.2 K0 X0 Y0 Z0\nK0 X1 Y1 Z0\nK0 X2 Y0 Z0\n"
                                              "K0 X3 Y0 Z0"),
    "points split by a comment": (PREAMBLE + "G06.2 K0 X0 Y0 Z0\nK0 X1 Y1 Z0\n(note)\nK0 X2 Y0 Z0\n"
                               "K0 X3 Y1 Z0\nK1\nK1\nK1\nK1\n"),
    "bad weight among the points": (PREAMBLE + "G06.2 K0 X0 Y0 Z0\nK0 X1 Y1 Z0\nK0 X2 Y0 Z0\n"
                                "K0 X3 Y1 Z0 R-1.\nK.5 X4 Y1 Z0\nK1\nK1\nK1\nK1\n"),
    # runs: what a scan reads, and every line where it must stop
    "run": points_curve(RUN) + "G1 X0\n",
    "run, order 2 and 3": points_curve(RUN, 2) + points_curve(RUN[5:], 3, opening="G06.2 P3 ",
                                                              start="X15 Y-1.2 Z0"),
    "run, crlf": (points_curve(RUN) + "G1 X0\n").replace("\n", "\r\n"),
    "run, lower case": points_curve([line.lower() for line in RUN]),
    "run, mixed case": points_curve([line.swapcase() if j % 3 else line
                                     for j, line in enumerate(RUN)]),
    "run, mixed R and no R": points_curve([line.split(" R")[0] + "\n" if j % 2 else line
                                           for j, line in enumerate(RUN)]),
    "run, G91": points_curve([f"K{j} X0.1 Y0.2 Z-0.3 R0.7\n" for j in range(1, 30)], close="K99\n",
                             opening=PREAMBLE + "G0 X0.3 Y0.7 Z-.1\nG91\nG06.2 P{order} ")
                + "G90\n",
    "run, longer than one scan": points_curve([f"K{j} X{j}.5 Y-{j}.25 Z0 R1\n"
                                               for j in range(1, RUN_LINES * 2 + 7)], 3,
                                              close=f"K{RUN_LINES * 2 + 9}\n"),
    "run, more than one curve": (points_curve(RUN) + points_curve(RUN, start="X15 Y-1.2 Z0",
                                                                  opening="")
                                 + "M30\n"),
    "run at the end of the file, no newline": points_curve(RUN, close="")[:-1],
    "run at the end of the file, lone CR": points_curve(RUN, close="")[:-1] + "\r",
    "run ends before knot-only blocks, no newline": points_curve(RUN)[:-1],
    "run, knot decreasing in the middle": points_curve(run_with(6, "K.100 X1 Y1 Z1\n")),
    "run, knot repeated twice": points_curve(run_with(6, RUN[5].split(" X")[0] + " X1 Y2 Z3\n")),
    "run, knot repeated the order": points_curve(
        RUN[:6] + ["K0.75 X1 Y1 Z1\n", "K0.75 X1 Y2 Z1\n", "K0.75 X1 Y3 Z1\n"] + RUN[6:]),
    "run, weight zero in the middle": points_curve(run_with(6, "K0.8 X1 Y1 Z1 R0\n")),
    "run, weight negative in the middle": points_curve(run_with(6, "K0.8 X1 Y1 Z1 R-0.5\n")),
    "run, F word in the middle": points_curve(run_with(6, "K0.8 X1 Y1 Z1 R1 F300\n")),
    "run, G91 line in the middle": points_curve(run_with(6, "G91\n")),
    "run, comment in the middle": points_curve(run_with(6, "K0.8 X1 Y1 Z1 (c)\n")),
    "run, line with spaces": points_curve(run_with(6, "K0.8  X1 Y1 Z1\n")),
    "run, trailing space": points_curve(run_with(6, "K0.8 X1 Y1 Z1 \n")),
    "run, tab": points_curve(run_with(6, "K0.8\tX1 Y1 Z1\n")),
    "run, omitted axis": points_curve(run_with(6, "K0.8 X1 Y1\n")),
    "run, empty line": points_curve(run_with(6, "\n")),
    "run, lone CR inside": points_curve(run_with(6, "K0.8 X1\r Y1 Z1\n")),
    "run, exponent": points_curve(run_with(6, "K0.8 X1e3 Y1 Z1\n")),
    "run, two points": points_curve(run_with(6, "K0.8 X1.2.3 Y1 Z1\n")),
    "run, 17 significant digits": points_curve(run_with(6, "K0.8 X1.2345678901234567 Y1 Z1\n")),
    "run, 16 digits above 2**53": points_curve(run_with(6, "K0.8 X9007199254740993 Y1 Z1\n")),
    "run, 16 digits": points_curve(run_with(6, "K0.8 X0.1234567890123456 Y1 Z1\n")),
    "run, 23 fraction digits": points_curve(run_with(6, "K0.8 X0.00000000000000000000001 Y1 Z1\n")),
    "run, 22 fraction digits": points_curve(run_with(6, "K0.8 X0.0000000000000000000001 Y1 Z1\n")),
    "run, signed zeros and bare points": points_curve(run_with(6, "K+.8 X-0 Y-0. Z+0.0 R.5\n")),
    "run, not ASCII": points_curve(RUN) + "(fin \u00e9)\n",
    "run, not ASCII inside": points_curve(RUN[:6] + ["(\u00e9tape 2)\n"] + RUN[6:]),
    # the next curve starts within half a unit in the coarser last decimal of X1.2 / X1.24
    "run, decimals of its last point": (points_curve(run_with(11, "K1.5 X1.2 Y-1.25 Z0.05\n"))
                                        + points_curve(RUN, start="X1.24 Y-1.25 Z0.05",
                                                       opening="")),
    "run, clamped end after it": points_curve(RUN, close="K9\nK9\nK10\nK10\n"),
    "run, too few knot-only blocks": points_curve(RUN, close="") + "K9\nK9\nG1 X0\n",
    # knot-only lines: what take_knot_line reads, and the lines it leaves to the words
    "knot-only, lower case and signs": points_curve(RUN, close="k+9.\n"),
    "knot-only, bare point": points_curve(RUN[:4], close="K.5\n"),
    "knot-only, crlf, no newline at the end": points_curve(RUN, close="K9\r\n")[:-2],
    "knot-only, lone CR at the end": points_curve(RUN, close="K9\n")[:-1] + "\r",
    "knot-only, comment": points_curve(RUN, close="K9 (end)\n"),
    "knot-only, N word": points_curve(RUN, close="N10 K9\n"),
    "knot-only, trailing space": points_curve(RUN, close="K9 \n"),
    "knot-only, exponent": points_curve(RUN, close="K9e0\n"),
    "knot-only, decreasing": points_curve(RUN, close="") + "K9\nK8\nK8\nK8\n",
    "knot-only, below the last knot": points_curve(RUN, close="K1\n"),
    "knot-only, too early": PREAMBLE + "G06.2 K0 X0 Y0 Z0\nK0 X1 Y1 Z0\nK1\nK1\nK1\nK1\n",
    "knot-only, one too many": points_curve(RUN) + "K9\n",
    "knot-only, then a point": points_curve(RUN, close="") + "K9\nK0.5 X1 Y1 Z1\n",
    "knot-only, G6.2 with Q": ("G21 G90 G17\nG0 X0 Y0 Z0\nG6.2 P3 K0 X0 Y0 Q0\nK0 X1 Y1\n"
                               "K0 X2 Y0\nK0.5 X3 Y1\nK1\nK1\nK1\nG1 X0\n"),
}


@pytest.mark.parametrize("name", sorted(FAST_PATH_CASES))
def test_control_point_fast_paths_read_like_the_words(name: str) -> None:
    text = FAST_PATH_CASES[name]
    assert with_fast_paths(text, "auto") == without_fast_path(text, "auto")


def test_runs_read_the_point_lines_past_the_clamped_start() -> None:
    assert lines_read_in_runs(FAST_PATH_CASES["run"]) == len(RUN)
    assert lines_read_in_runs(FAST_PATH_CASES["run, knot decreasing in the middle"]) == 6
    assert lines_read_in_runs(FAST_PATH_CASES["run, 17 significant digits"]) == len(RUN) - 1
    # a scan reads ASCII lines only (string and byte positions agree), up to the first line
    # that is not; a line elsewhere in the file does not matter. (After the comment, take_line
    # reads a line before the next scan.)
    assert lines_read_in_runs(FAST_PATH_CASES["run, not ASCII"]) == len(RUN)
    assert lines_read_in_runs(FAST_PATH_CASES["run, not ASCII inside"]) == len(RUN) - 1
    text = fanuc_program(3)
    assert lines_read_in_runs(text) == 3 * (50 - 4)  # all but each curve's first 4 lines
    assert with_fast_paths(text, "auto") == without_fast_path(text, "auto")


def test_closing_knot_lines_are_read_from_their_text() -> None:
    read_from_text = 0
    take_knot_line = NurbsCurveReader.take_knot_line

    def counting(self: NurbsCurveReader, line_text: str, line: int) -> bool | None:
        nonlocal read_from_text
        closed = take_knot_line(self, line_text, line)
        read_from_text += closed is not None
        return closed

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(NurbsCurveReader, "take_knot_line", counting)
        read(fanuc_program(3))
    assert read_from_text == 3 * 4  # every closing knot of the three curves


def test_an_error_after_a_run_names_its_line_and_the_run_s_last_knot() -> None:
    text = FAST_PATH_CASES["run, knot decreasing in the middle"]
    with pytest.raises(CurveError) as caught, pytest.MonkeyPatch.context() as patch:
        patch.setattr(point_lines, "RUNS_ENABLED", True)
        read(text)
    assert str(caught.value) == ("t.nc:13:1: K.100: knots must not decrease (K0.75 on line 12 "
                                 "before it) (Mitsubishi error P551)")


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_programs())
def test_control_point_fast_paths_read_mutated_programs_like_the_words(case: tuple[str, str]
                                                                        ) -> None:
    text, dialect = case
    assert with_fast_paths(text, dialect) == without_fast_path(text, dialect)


# ---- the run scan's numbers are float()'s, bit for bit ------------------------------------------
def codes(text: str) -> np.ndarray:
    return np.frombuffer(text.encode("ascii"), dtype=np.uint8)


def same_double(a: float, b: float) -> bool:
    return bool(np.float64(a).view(np.int64) == np.float64(b).view(np.int64))


def significant_digits(number: str) -> int:
    return len(re.sub(r"[^0-9]", "", number).lstrip("0"))


def fraction_digits(number: str) -> int:
    return len(number.partition(".")[2])


NUMBER_EDGES = ["0", "-0", "+0", "-0.0", "0.", "-0.", ".5", "-.5", "+.5", "5.", "000123.4500",
                "0.1", "0.3", "2.675", "1.005", "9.999999999999999", "123456789012345",
                "1234567890123456", "9007199254740992", "9007199254740993", "12345678901234567",
                "0.000000000000000000001", "0.0000000000000000000001", "0.00000000000000000000001",
                "1.0000000000000000000000", "0.1234567890123456", "0.12345678901234567",
                "-123.456789012345", "0000000000000000000000000001.5", "4503599627370497.5"]


# the strategies drawn from, built once: hypothesis validates every new one at its first draw,
# and a number is drawn thousands of times a run
SIGNS = st.sampled_from(["", "+", "-"])
WHOLES = st.text("0123456789", max_size=20)
FRACTIONS = {True: st.text("0123456789", max_size=25),  # after a whole part
             False: st.text("0123456789", min_size=1, max_size=25)}


@st.composite
def plain_numbers(draw: st.DrawFn) -> str:
    """`[+-]?(\\d+(\\.\\d*)?|\\.\\d+)` with up to 20 digits each side, leading zeros included."""
    sign = draw(SIGNS)
    whole = draw(WHOLES)
    point = draw(st.booleans()) or not whole
    fraction = draw(FRACTIONS[bool(whole)])
    return sign + whole + ("." + fraction if point else "")


def check_number(number: str) -> None:
    value, end = _number(codes(number), 0)
    significant, fraction = significant_digits(number), fraction_digits(number)
    if significant <= 15 and fraction <= 22:
        assert end == len(number), number  # Clinger's fast path covers it
    if significant > 16 or fraction > 22:
        assert end == -1, number  # beyond it: left to float()
    if end != -1:
        assert end == len(number) and same_double(value, float(number)), number


@pytest.mark.parametrize("number", NUMBER_EDGES)
def test_scan_numbers_are_float_s_at_the_edges(number: str) -> None:
    check_number(number)


@settings(max_examples=examples(2000), deadline=None)
@given(plain_numbers())
def test_scan_numbers_are_float_s(number: str) -> None:
    check_number(number)


def test_scan_numbers_are_float_s_seeded() -> None:
    """Shop-shaped numbers, 4 and 6 decimals as CAM posts write them, and every digit count."""
    rng = random.Random(20260522)
    for _ in range(20000):
        digits = rng.randrange(1, 16)
        mantissa = rng.randrange(10 ** digits)
        point = rng.randrange(0, min(digits, 22) + 1)
        text = str(mantissa).rjust(digits, "0")
        number = rng.choice(["", "-"]) + text[:len(text) - point] + "." + text[len(text) - point:]
        check_number(number)


LETTER_ORDERS = st.sampled_from(["KXYZ", "KXYZR", "KXYZR", "KXY", "KXYZF", "XKYZ"])
ONE_IN_16 = st.integers(0, 15)
OTHER_LETTERS = st.sampled_from("KXYZRFG")
EITHER_CASE = {letter: st.sampled_from([letter, letter.lower()]) for letter in "KXYZRFG"}
NUMBERS = plain_numbers()
SEPARATORS = st.sampled_from([" "] * 12 + ["", "  ", "\t", "\r"])
ENDINGS = st.sampled_from(["\n", "\r\n", "", "\r", " \n", "\n\r", "\r\r\n"])


@st.composite
def point_line_texts(draw: st.DrawFn) -> str:
    """Lines near the point-line grammar: its words, letters, separators and endings, varied."""
    words = []
    for letter in draw(LETTER_ORDERS):
        if draw(ONE_IN_16) == 0:
            letter = draw(OTHER_LETTERS)
        words.append(draw(EITHER_CASE[letter]) + draw(NUMBERS))
    seps = [draw(SEPARATORS) for _ in words[1:]]
    line = words[0] + "".join(sep + word for sep, word in zip(seps, words[1:]))
    return line + draw(ENDINGS)


@settings(max_examples=examples(2000), deadline=None)
@given(point_line_texts(), st.sampled_from(["", "K9 X1 Y2 Z3\n", "G1 X0\n"]))
def test_scan_reads_exactly_the_point_lines(line: str, after: str) -> None:
    """A scan reads the line iff _POINT_LINE matches it, its numbers are within Clinger's fast
    path, its knot is above the one before and its weight positive; then float()'s values."""
    text = line + after
    values = np.empty((RUN_LINES, 5))
    n, last_start, end = scan_point_lines(codes(text), 0, -1.0, values)
    first_line = text[:text.find("\n") + 1 or len(text)]
    match = _POINT_LINE.fullmatch(first_line)
    numbers = [] if match is None else [g for g in match.groups() if g is not None]
    readable = match is not None and all(
        significant_digits(g) <= 15 and fraction_digits(g) <= 22 for g in numbers)
    if readable and float(numbers[0]) > -1.0 and (len(numbers) == 4 or float(numbers[4]) > 0):
        assert n >= 1 and end >= len(first_line)
        expected = [float(g) for g in numbers] + [1.0] * (5 - len(numbers))
        assert all(same_double(a, b) for a, b in zip(values[0].tolist(), expected))
    if match is None:
        assert n == 0 and end == 0
    if n:
        assert match is not None and text[:end] == first_line + (after if n == 2 else "")
        assert last_start == (len(first_line) if n == 2 else 0)
