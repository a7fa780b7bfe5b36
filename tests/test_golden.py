"""Golden files of G-code programs (Fanuc G06.2, LinuxCNC G5.2 and G6.2) converted under both
built-in profiles, byte for byte, each one also checked by means that do not run nurbsfeed.

A golden file only says "the output has not changed"; by itself it would keep whatever the code
printed the day it was written. So every golden file is also read back here and checked
against the input and the profile alone:

- the lines outside the NURBS block are the input's, byte for byte and in order;
- the block became one comment, G1 moves and the restored modal F, every number with a decimal
  point;
- every move ends on the curve, evaluated by the textbook evaluator in tests/naive_nurbs.py from
  the control points written out below (within the output's rounding), and the last one on the
  curve's end;
- each move lasts a whole number of periods at its F, more than one only near standstill (where
  points round onto each other), no F is above the programmed feed or the profile's maximum
  (beyond the rounding of the written coordinates), and the moves add up to the planned cycle
  and the point count the comment states; the comment's length is the curve's.

Regenerate after a deliberate change of the output, then read the diff before committing:

    pytest tests/test_golden.py --update-golden

The checks above run on the regenerated files too, so a wrong output cannot become golden.
"""

from __future__ import annotations

import difflib
import functools
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from nurbsfeed.cli import main
from tests import naive_nurbs
from tests.conftest import ROOT, SAMPLES
from tests.gcode_parse import moves

GOLDEN = ROOT / "tests" / "golden"
MM_PER_INCH = 25.4
COMMENT = re.compile(r"\(nurbsfeed: curve 0 .*, (\d+) points, period 1 ms, rk2c, "
                     r"length ([\d.]+) (mm|in), planned cycle ([\d.]+) s\)")
MOVE = re.compile(r"(G1 )?(X-?\d*\.\d*)? ?(Y-?\d*\.\d*)? ?(Z-?\d*\.\d*)? ?(F\d*\.\d*)?")
CURVE_SAMPLES = 4 * 8_000  # of the naive curve, evenly in u (its sag is checked to be small)
# segments searched for a move's nearest (a move spans 30 at most): a window too narrow
# only finds a farther segment, never a nearer one, so it cannot hide a point off the curve
WINDOW, WINDOW_BACK = 200, 20


@dataclass(frozen=True)
class Case:
    """A sample and what its NURBS block says, read off its text by hand."""

    sample: str
    block: tuple[int, int]  # first and last line of the NURBS block, 1-based
    degree: int
    knots: tuple[float, ...]
    points: tuple[tuple[float, float, float], ...]  # the current position first
    weights: tuple[float, ...]
    feed_per_min: float  # the F in force over the curve, program units per minute
    restored: str  # the modal F line written after the moves
    inch: bool = False


CASES = {
    # G06.2 P3: a knot on every control point line, then `order` knot-only lines
    "fanuc-g06.2": Case("fanuc-quadratic.nc", (10, 16), 2, (0, 0, 0, 0.5, 1, 1, 1),
                        ((0, 0, -0.5), (20, 30, -0.5), (40, -10, -0.5), (60, 20, -0.5)),
                        (1, 1, 1, 1), 3000.0, "F3000."),
    # G5.2 L3 in inches: the current position prepended (weight P1 of the G5.2 line), uniform
    # clamped knots
    "linuxcnc-g5.2": Case("linuxcnc-docs.ngc", (13, 18), 2, (0, 0, 0, 1, 2, 3, 3, 3),
                          ((0, 0, -0.02), (0, 1, -0.02), (2, 2, -0.02), (2, 0, -0.02),
                           (0, 0, -0.02)),
                          (1, 1, 1, 1, 2), 60.0, "F60.", inch=True),
    # G6.2 P4 Q1: explicit knots, `G6.2 K` knot lines
    "linuxcnc-g6.2": Case("linuxcnc-g62.ngc", (11, 18), 3, (0, 0, 0, 0, 1, 1, 1, 1),
                          ((0, 0, -1), (10, 30, -1), (40, 30, -1), (50, 0, -1)),
                          (1, 1, 1, 1), 2500.0, "F2500."),
}
PROFILES = ("default", "paper-table1")


@functools.cache
def polyline(name: str) -> np.ndarray:
    """(CURVE_SAMPLES + 1, 3) points of the naive curve, evenly in u: C(u) by Cox-de Boor from
    the definition (tests/naive_nurbs.basis), all samples at once."""
    case = CASES[name]
    u = np.linspace(case.knots[0], case.knots[-1], CURVE_SAMPLES + 1)
    knots = np.array(case.knots, dtype=float)
    num, den = np.zeros((u.size, 3)), np.zeros(u.size)
    for i, (point, weight) in enumerate(zip(case.points, case.weights)):
        n = naive_nurbs.basis(i, case.degree, u, knots) * weight
        num += n[:, None] * np.array(point, dtype=float)
        den += n
    return num / den[:, None]


def distance_to_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Each point's (M, 3) distance to the polyline (S, 3) through the curve's samples, both in
    order along the curve: each point is compared with the segments from a little before the
    previous point's nearest on. (A point farther along would only be found farther away.)"""
    a = polyline[:-1]
    ab = polyline[1:] - a
    ab_ab = np.einsum("ij,ij->i", ab, ab)
    out = np.empty(len(points))
    nearest = 0
    for k, p in enumerate(points):
        lo = max(nearest - WINDOW_BACK, 0)
        sa, sab = a[lo:lo + WINDOW], ab[lo:lo + WINDOW]
        t = np.clip(np.einsum("ij,ij->i", p - sa, sab) / ab_ab[lo:lo + WINDOW], 0, 1)
        gap = np.linalg.norm(sa + t[:, None] * sab - p, axis=1)
        nearest = lo + int(np.argmin(gap))
        out[k] = gap[nearest - lo]
    return out


def profile(name: str) -> dict:
    return yaml.safe_load((ROOT / "configs" / f"{name}.yaml").read_text())


def convert(case: Case, profile_name: str, folder: Path) -> str:
    out = folder / "out.nc"
    result = CliRunner().invoke(main, ["convert", str(SAMPLES / case.sample), "-m", profile_name,
                                       "-o", str(out), "-q"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return out.read_bytes().decode()


def check_independently(name: str, profile_name: str, text: str) -> None:
    """The golden file's content against the input, the curve and the profile (module
    docstring)."""
    case = CASES[name]
    source = (SAMPLES / case.sample).read_text().splitlines(True)
    golden = text.splitlines(True)
    first, last = case.block
    before, after = source[:first - 1], source[last:]
    assert golden[:len(before)] == before
    assert golden[len(golden) - len(after):] == after
    made = [line.rstrip("\n") for line in golden[len(before):len(golden) - len(after)]]
    limits = profile(profile_name)
    record = [line for line in made if line.startswith("(nurbsfeed profile: ")]
    assert made[:len(record)] == record  # the profile record first, then the comment
    recorded = dict(pair.split(" ") for line in record
                    for pair in line[len("(nurbsfeed profile: "):-1].split(", "))
    assert recorded["name"] == profile_name
    assert all(float(recorded[key]) == value if isinstance(value, (int, float))
               else recorded[key] == value for key, value in limits.items())
    made = made[len(record):]
    comment = COMMENT.fullmatch(made[0])
    assert comment, made[0]
    assert made[-1] == case.restored
    lines = made[1:-1]
    assert lines[0].startswith("G1 ") and all(line and MOVE.fullmatch(line) for line in lines)
    # a profile without `decimals` lets nurbsfeed choose them (machine.auto_decimals): the
    # rounding allowance then follows the finest digit written, which the check below bounds
    written_digits = max(len(number.split(".")[1]) for line in lines
                         for number in re.findall(r"[XYZ](-?[0-9.]+)", line))
    decimals = (limits["decimals"] + case.inch if "decimals" in limits else written_digits)
    assert written_digits <= decimals <= 8 + case.inch
    unit_mm = MM_PER_INCH if case.inch else 1.0
    period_s = limits["period_s"]
    start = np.array(case.points[0], dtype=float)
    written, feeds, _ = moves("\n".join(lines), start)

    # on the curve, within the rounding of the written coordinates; the last move on its end
    curve = polyline(name)
    rounding = math.sqrt(3) / 2 * 10.0**-decimals
    # the polyline lies off the curve by at most its sag, which a second difference bounds (on
    # a circle it is 8 times the sag of a segment); small beside the rounding
    sag = np.max(np.linalg.norm(curve[2:] - 2 * curve[1:-1] + curve[:-2], axis=1))
    assert sag < 0.2 * rounding
    assert np.max(distance_to_polyline(written, curve)) <= rounding + sag
    assert np.array_equal(written[-1], np.round(curve[-1], decimals))
    length = np.sum(np.linalg.norm(np.diff(curve, axis=0), axis=1))
    assert float(comment.group(2)) == pytest.approx(length, abs=1e-3)

    # whole periods at each F, none faster than the feed allows (the rounding of both ends
    # lengthens a move by up to 2 * rounding)
    cap_per_min = min(case.feed_per_min, limits["max_feed_mm_s"] * 60.0 / unit_mm)
    step = np.linalg.norm(np.diff(np.vstack([start, written]), axis=0), axis=1)
    periods = step / (feeds / 60.0) / period_s
    whole = np.round(periods)
    assert np.all(whole >= 1) and np.allclose(periods, whole, rtol=5e-3)
    assert np.all(step / whole <= cap_per_min / 60.0 * period_s + 2 * rounding)
    # a point is left out only where it rounds onto the one before (near standstill): its
    # period moved each axis by less than one unit of the last digit, so a move of n periods
    # (speed near rest, rising by less than that per period) covers under (n + 1) units per axis
    several = whole > 1
    assert np.all(step[several] <= (whole[several] + 1) * math.sqrt(3) * 10.0**-decimals)
    n_points, cycle_s = int(comment.group(1)), float(comment.group(4))
    assert int(whole.sum()) == n_points - 1 == round(cycle_s / period_s)


@pytest.mark.parametrize("profile_name", PROFILES)
@pytest.mark.parametrize("name", sorted(CASES))
def test_golden_program(name: str, profile_name: str, request: pytest.FixtureRequest,
                        tmp_path: Path) -> None:
    case = CASES[name]
    golden = GOLDEN / f"{Path(case.sample).stem}.{profile_name}.nc"
    produced = convert(case, profile_name, tmp_path)
    if request.config.getoption("--update-golden"):
        golden.write_bytes(produced.encode())
    expected = golden.read_bytes().decode()
    check_independently(name, profile_name, expected)
    diff = "".join(difflib.unified_diff(expected.splitlines(True), produced.splitlines(True),
                                        "golden", "produced", n=1))
    assert produced == expected, diff[:4000]
