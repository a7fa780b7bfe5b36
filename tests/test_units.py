"""An inch program is the same motion as the mm program of the same curve: planned and stepped in
mm, written back in inches with one more decimal."""

from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.machine import load_machine
from nurbsfeed.program import MM_PER_INCH
from tests.gcode_parse import moves

PERIOD_S = 0.001  # the default profile's
DECIMALS = load_machine("default").decimals  # in mm programs; one more in inch programs
CURVE_IN = {"name": "s-curve", "degree": 3, "knots": [0, 0, 0, 0, 0.5, 1, 1, 1, 1],
            "control_points": [[0, 0, -0.02], [0.4, 0.8, -0.02], [1.2, 0.8, -0.03],
                               [1.6, 0.0, -0.02], [2.0, 0.4, -0.01]],
            "weights": [1, 0.8, 1.2, 1, 1], "feed": 120.0}  # in/min


def convert(tmp_path: Path, units: str, scale: float) -> tuple[str, np.ndarray]:
    """The program and the trace's x, y, z of CURVE_IN with its lengths times `scale`."""
    curve = dict(CURVE_IN, control_points=(np.array(CURVE_IN["control_points"]) * scale).tolist(),
                 feed=CURVE_IN["feed"] * scale)
    source = tmp_path / f"{units}.json"
    source.write_text(json.dumps({"units": units, "curves": [curve]}))
    out, trace = tmp_path / f"{units}.nc", tmp_path / f"{units}.csv"
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(out), "--trace",
                                       str(trace)], catch_exceptions=False)
    assert result.exit_code == 0, result.stderr
    rows = list(csv.DictReader(io.StringIO(trace.read_text())))
    return out.read_text(), np.array([[float(r[a]) for a in "xyz"] for r in rows])


def written_at_periods(text: str, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every written point and the period it ends on (from its length and F)."""
    points, feeds, _ = moves(text, start)
    steps = np.linalg.norm(np.diff(np.vstack([start, points]), axis=0), axis=1)
    periods = np.rint(steps / (feeds / 60.0) / PERIOD_S).astype(int)
    return points, np.cumsum(periods)


def test_an_inch_program_moves_as_the_same_curve_in_mm(tmp_path: Path) -> None:
    inch_text, inch_trace = convert(tmp_path, "in", 1.0)
    mm_text, mm_trace = convert(tmp_path, "mm", MM_PER_INCH)
    # one plan, in mm: the same points, period for period (the trace is in mm for both)
    assert inch_trace.shape == mm_trace.shape
    assert np.allclose(inch_trace, mm_trace, rtol=0, atol=1e-9)
    start = np.array(CURVE_IN["control_points"][0], dtype=float)
    for text, unit_mm, decimals in ((inch_text, MM_PER_INCH, DECIMALS + 1),
                                    (mm_text, 1.0, DECIMALS)):
        points, k = written_at_periods(text, start * MM_PER_INCH / unit_mm)
        assert k[-1] == len(mm_trace) - 1  # every period, the last move onto the curve end
        assert all(len(w) - w.index(".") - 1 <= decimals
                   for w in re.findall(r"[XYZ](-?[\d.]+)", text))
        rounding_mm = 0.5 * 10.0**-decimals * unit_mm * (1 + 1e-9)
        assert np.abs(points * unit_mm - mm_trace[k]).max() <= rounding_mm
    # the cycle comment, in the program's unit
    inch_length = float(re.search(r"length ([\d.]+) in,", inch_text)[1])
    mm_length = float(re.search(r"length ([\d.]+) mm,", mm_text)[1])
    assert math.isclose(inch_length, mm_length / MM_PER_INCH, abs_tol=0.0005)


def test_check_reads_an_inch_program_in_mm(tmp_path: Path) -> None:
    convert(tmp_path, "in", 1.0)
    convert(tmp_path, "mm", MM_PER_INCH)
    reports = {}
    for units in ("in", "mm"):
        result = CliRunner().invoke(main, ["check", str(tmp_path / f"{units}.json"),
                                           str(tmp_path / f"{units}.nc"), "--json"])
        assert result.exit_code == 0, result.stdout
        reports[units] = json.loads(result.stdout)
    assert reports["in"]["units"] == "mm, s"
    limits = {units: {c["name"]: c["limit"] for c in report["checks"]}
              for units, report in reports.items()}
    assert limits["in"]["feed"] == limits["mm"]["feed"] == CURVE_IN["feed"] * MM_PER_INCH / 60
    # the inch program's rounding, half its last written digit per axis, in mm
    rounding_mm = reports["in"]["estimation"][0]["rounding_mm"]
    assert math.isclose(rounding_mm, 0.5 * 10.0**-(DECIMALS + 1) * math.sqrt(3) * MM_PER_INCH)


def test_plan_reports_an_inch_program_in_mm(tmp_path: Path) -> None:
    inch_text, _ = convert(tmp_path, "in", 1.0)
    result = CliRunner().invoke(main, ["plan", str(tmp_path / "in.json")])
    assert result.exit_code == 0
    planned_mm = float(re.search(r"length ([\d.]+) mm\n", result.stdout)[1])
    inch_length = float(re.search(r"length ([\d.]+) in,", inch_text)[1])
    assert math.isclose(planned_mm / MM_PER_INCH, inch_length, abs_tol=0.0005)
    # the default profile's planner lists stretches between rests, the S-curve planner segments
    assert "(mm, mm/s)" in result.stdout and " in" not in result.stdout
