"""LinuxCNC G5 / G5.1 splines: read as the Bézier curves of LinuxCNC's reference, converted to
moves that lie on them.

The reference here is independent of nurbsfeed's NURBS code: the control points are worked out
in the test from the words (I J from the start, P Q from the end, -P -Q of the previous G5) and
the curve is evaluated with Bernstein polynomials.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.errors import InputError
from nurbsfeed.files import InputFile
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file
from nurbsfeed.program import CurveBlock, PassThrough
from nurbsfeed.readers.gcode import read_gcode
from tests.conftest import SAMPLES
from tests.gcode_parse import moves

ON_CURVE_MM = 1e-3  # every written point within 1 um of the spline
PREAMBLE = "G17 G21 G90 G94\nG0 X1. Y2. Z-3. F600.\n"


def read(text: str, dialect: str = "auto") -> list:
    lines = InputFile(Path("t.ngc"), text.encode()).lines()
    return list(read_gcode(Path("t.ngc"), lines, dialect))


def curves(text: str) -> list[CurveBlock]:
    return [item for item in read(text) if isinstance(item, CurveBlock)]


def bernstein(points: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The Bézier curve of control points (k+1, d) at u (N,) -> (N, d), term by term."""
    k = len(points) - 1
    basis = np.array([math.comb(k, i) * u**i * (1.0 - u) ** (k - i) for i in range(k + 1)])
    return basis.T @ points


def distance_to(points: np.ndarray, written: np.ndarray) -> np.ndarray:
    """Distance of each written point (M, d) to the Bézier curve of `points`: nearest of 2*10^5
    samples (spacing well under 0.01 um on these curves of a few cm), then the chord to its
    neighbour."""
    dense = bernstein(points, np.linspace(0.0, 1.0, 200_001))
    best = np.empty(len(written))
    for i, p in enumerate(written):
        d = np.linalg.norm(dense - p, axis=1)
        best[i] = d.min()
    return best


def test_g5_is_the_cubic_bezier_of_its_offsets() -> None:
    (block,) = curves(PREAMBLE + "G5 X10. Y0. I3. J5. P-2. Q4.\n")
    expected = np.array([[1, 2, -3], [4, 7, -3], [8, 4, -3], [10, 0, -3]], dtype=float)
    assert block.curve.degree == 3
    np.testing.assert_array_equal(block.curve.points, expected)
    u = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(block.curve.point(u), bernstein(expected, u), atol=1e-12)


def test_g5_1_is_the_quadratic_bezier_of_its_offset() -> None:
    (block,) = curves(PREAMBLE + "G5.1 X10. Y10. I9. J0.\n")
    expected = np.array([[1, 2, -3], [10, 2, -3], [10, 10, -3]], dtype=float)
    assert block.curve.degree == 2
    np.testing.assert_array_equal(block.curve.points, expected)
    u = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(block.curve.point(u), bernstein(expected, u), atol=1e-12)


def test_g5_without_i_j_leaves_in_the_direction_the_previous_g5_arrived() -> None:
    first, second = curves(PREAMBLE + "G5 X10. Y0. I3. J5. P-2. Q4.\nF900.\n(c)\n"
                                      "G5 X20. Y2. P-1. Q-1.\n")
    np.testing.assert_array_equal(second.curve.points[:2, :2], [[10, 0], [12, -4]])
    # the joint is tangent: the end tangent of the first is the start tangent of the second
    end_tangent = first.curve.points[3] - first.curve.points[2]
    start_tangent = second.curve.points[1] - second.curve.points[0]
    assert np.cross(end_tangent, start_tangent) == pytest.approx(np.zeros(3))
    assert np.dot(end_tangent, start_tangent) > 0


def test_g5_under_g91_ends_relative_to_its_start_and_an_omitted_axis_holds() -> None:
    (block,) = curves(PREAMBLE + "G91\nG5 X10. I3. J5. P-2. Q4.\n")
    np.testing.assert_array_equal(block.curve.points[:, :2], [[1, 2], [4, 7], [9, 6], [11, 2]])
    assert block.incremental


def test_an_unknown_z_is_held_and_stays_unknown() -> None:
    items = read("G17 G21 G90 G94\nG0 X0. Y0. F600.\nG5.1 X10. Y10. I10. J0.\nG0 Z1.\n"
                 "G5.1 X20. Y0. I0. J-10.\n")
    blocks = [item for item in items if isinstance(item, CurveBlock)]
    assert blocks[0].curve.points[:, 2].tolist() == [0.0, 0.0, 0.0]
    assert blocks[1].curve.points[:, 2].tolist() == [1.0, 1.0, 1.0]


def test_the_spline_lines_are_replaced_and_every_other_line_passes_through() -> None:
    text = ("(head)\r\n#<f> = 900\r\nG17 G21 G90 G94\r\nG0 X0. Y0.\r\n"
            "G5 X10. Y0. I3. J5. P-2. Q4. F#<f>\r\nG5 X20. Y0. P-2. Q4.\r\nG1 X30.\r\nM2\r\n")
    items = read(text)
    kinds = ["C" if isinstance(item, CurveBlock) else item.text for item in items]
    lines = text.splitlines(keepends=True)
    assert kinds == lines[:4] + ["C", "C"] + lines[6:]
    assert all(item.eol == "\r\n" for item in items if isinstance(item, CurveBlock))
    assert items[4].feed_word_after == "F900."


def test_the_mode_before_the_spline_holds_for_linuxcnc_and_g1_is_accepted() -> None:
    after_g1 = read("G17 G21 G90 G94\nG1 X0. Y0. F600.\nG5.1 X10. Y10. I10. J0.\nX20. Y0.\n")
    assert isinstance(after_g1[-1], PassThrough)
    with pytest.raises(InputError, match=r"^t.ngc:4:1: X20\. without a G code after the G5\.1"):
        read("G17 G21 G90 G94\nG0 X0. Y0. F600.\nG5.1 X10. Y10. I10. J0.\nX20. Y0.\n")
    # a motion code in between ends the question
    read("G17 G21 G90 G94\nG0 X0. Y0. F600.\nG5.1 X10. Y10. I10. J0.\nG0 Z1.\nX20. Y0.\n")


@pytest.mark.parametrize("line", ["G05 P10000", "G05.1 Q1", "G5.1 Q3 X0 Y0 Z0", "G05 P0"])
def test_fanuc_modes_written_as_g5_pass_through(line: str) -> None:
    items = read(PREAMBLE + line + "\n")
    assert [item.text for item in items] == PREAMBLE.splitlines(keepends=True) + [line + "\n"]


def test_the_fanuc_dialect_does_not_read_g5_as_a_spline() -> None:
    items = read(PREAMBLE + "G5 X10. Y0. I3. J5. P-2. Q4.\n", dialect="fanuc")
    assert not any(isinstance(item, CurveBlock) for item in items)


# ---- converted: every written point on the spline ------------------------------------------
def control_polygons(program: str) -> list[np.ndarray]:
    """The Bézier control points of each G5 / G5.1 of a sample, worked out from its words
    (named parameters substituted first): the reference the moves are measured against."""
    params: dict[str, float] = {}
    pos = np.zeros(2)
    exit_offset = np.zeros(2)
    polygons = []
    for raw in program.splitlines():
        line = re.sub(r"\(.*?\)", "", raw)
        assign = re.fullmatch(r"\s*#<(\w+)>\s*=\s*(\S+)\s*", line)
        if assign:
            params[assign.group(1).lower()] = float(assign.group(2))
            continue
        line = re.sub(r"#<(\w+)>", lambda m: str(params[m.group(1).lower()]), line)
        words = {letter: float(value) for letter, value in re.findall(r"([A-Z])(-?[\d.]+)", line)}
        end = np.array([words.get("X", pos[0]), words.get("Y", pos[1])])
        spline = re.search(r"\bG5(\.1)?\s", line)
        if spline:
            first = (pos + np.array([words["I"], words["J"]]) if "I" in words
                     else pos + exit_offset)
            if spline.group(1):
                polygons.append(np.array([pos, first, end]))
            else:
                second = end + np.array([words["P"], words["Q"]])
                polygons.append(np.array([pos, first, second, end]))
                exit_offset = -np.array([words["P"], words["Q"]])
        pos = end
    return polygons


SPLINE_SAMPLES = ["linuxcnc-g5-chain.ngc", "linuxcnc-g5-1-quadratic.ngc",
                  "linuxcnc-named-parameters.ngc"]


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    folder = tmp_path_factory.mktemp("splines")
    out = {}
    for name in SPLINE_SAMPLES:
        target = folder / name
        convert_file(SAMPLES / name, target, load_machine("default"))
        out[name] = target.read_text()
    return out


def written_per_curve(text: str, starts: list[np.ndarray]) -> list[tuple[range, np.ndarray]]:
    """Per curve comment: the curves it stands for (one, or a chain's, design §3b) and the XY
    (M, 2) of the moves after it, starting at the start of its first curve (XY; the moves
    write the axes that change)."""
    found = []
    for chunk in text.split("(nurbsfeed: curve")[1:]:
        chained = re.match(r"s (\d+)-(\d+) chained", chunk)
        first = int(chained[1]) if chained else int(re.match(r" (\d+)", chunk)[1])  # type: ignore[index]
        last = int(chained[2]) if chained else first
        start = starts[first]
        block: list[str] = []
        for line in chunk.splitlines()[1:]:
            # our moves: "G1 " on the first only (a G1 after them is the program's own)
            if not re.match(r"[XYZF]" if block else r"(G1 )?[XYZF]", line):
                break
            block.append(line)
        points, _, _ = moves("\n".join(block), [start[0], start[1], 0.0])
        found.append((range(first, last + 1), points[:, :2]))
    return found


@pytest.mark.parametrize("name", SPLINE_SAMPLES)
def test_every_written_point_lies_on_the_spline(converted: dict[str, str], name: str) -> None:
    polygons = control_polygons((SAMPLES / name).read_text())
    written = written_per_curve(converted[name], [polygon[0] for polygon in polygons])
    assert [i for curves, _ in written for i in curves] == list(range(len(polygons)))
    assert len(polygons) >= 2
    for curves, points in written:
        # ends on the end point of its last curve; every point on one of its curves (a chain
        # runs on across its joints)
        np.testing.assert_array_equal(points[-1], polygons[curves[-1]][-1])
        near = np.min([distance_to(polygons[i], points) for i in curves], axis=0)
        assert near.max() <= ON_CURVE_MM
        # the measure can fail: a control point moved by 0.1 mm puts moves off the curve
        moved = polygons[curves[0]].copy()
        moved[1] += [0.0, 0.1]
        others = [distance_to(polygons[i], points) for i in curves[1:]]
        assert np.min([distance_to(moved, points), *others], axis=0).max() > ON_CURVE_MM


# ---- through the command line: refused late, nothing written -----------------------------------
LATE_ERRORS = [
    ("late.ngc", PREAMBLE + "G5 X10. Y0. I3. J5. P-2. Q4.\nG18\nG5 X20. Y0. I3. J5. P-2. Q4.\n",
     "5:1: G5 in plane G18: Splines must be in the XY plane (LinuxCNC); select G17 first"),
    ("late.ngc", PREAMBLE + "G5.1 X10. Y10. I9. J0.\nG1 X#<x>\n",
     "4:5: Named parameter #<x> not defined (LinuxCNC): assign it (#<x> = value) on an earlier "
     "line"),
    ("late.mpf", "N10 G17 G710 G90 G94\nN20 G1 X0. Y0. Z0. F600.\nN30 BSPLINE X5. Y10. PL=1.\n"
     "N40 X15. Y12. PL=1.\nN50 X20. Y0. PL=1.\nN60 X30. Y5. PL=1.\nN70 ASPLINE X40. Y0.\n",
     "7:5: ASPLINE (Akima spline) is not supported: nurbsfeed reads BSPLINE, whose control points "
     "and knots make a NURBS"),
]


@pytest.mark.parametrize(("name", "program", "message"), LATE_ERRORS)
def test_a_late_bad_block_is_located_exits_2_and_leaves_no_output(tmp_path: Path, name: str,
                                                                  program: str,
                                                                  message: str) -> None:
    source = tmp_path / name
    source.write_text(program)
    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(out)],
                                catch_exceptions=False)
    assert result.exit_code == 2
    assert result.stderr == f"{source}:{message}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]
