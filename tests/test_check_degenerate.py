"""check on degenerate geometry (C'(u) = 0 at corners, cusps, reversals and coincident control
points): the converter's outputs pass under both profiles, and a point off the curve right after
a corner still fails path-deviation."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from nurbsfeed.analysis import check_files
from nurbsfeed.analysis.check import project_points
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file
from tests.conftest import convert_each, default_paper_machine

DEGENERATE = Path(__file__).parent / "data" / "degenerate"
CORNER = DEGENERATE / "corner-tripled-point.json"
DECIMALS = 4  # the offsets below are in units of the 4th decimal
R_MM = 0.5 * 10.0**-DECIMALS * math.sqrt(3.0)  # output rounding at DECIMALS


def corner_curve() -> NurbsCurve:
    raw = json.loads(CORNER.read_text())["curves"][0]
    return NurbsCurve.build(raw["degree"], raw["knots"], raw["control_points"], None,
                            raw["name"])


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, str], Path]:
    return convert_each(sorted(DEGENERATE.glob("*.json")), tmp_path_factory.mktemp("degenerate"))


@pytest.mark.parametrize("profile", ["default", "paper-table1", "linuxcnc"])
@pytest.mark.parametrize("source", sorted(p.name for p in DEGENERATE.glob("*.json")))
def test_every_degenerate_file_converted_passes(converted, source: str, profile: str) -> None:
    report = check_files(DEGENERATE / source, converted[(source, profile)], load_machine(profile))
    assert report.ok, "\n".join(map(str, report.violations))


@pytest.mark.parametrize("offset_r, fails", [(0.0, False), (0.9, False), (1.1, True),
                                             (3.0, True)])
def test_projection_through_a_corner_measures_an_offset_after_it(offset_r: float,
                                                                  fails: bool) -> None:
    """The corner at (20, 0), u = 0.5, where the curve stops and leaves along +y: points on the
    curve through it, the first one after it moved off the outgoing leg (along x) by offset_r r.
    Its distance is the offset, and the points after it are followed on."""
    curve = corner_curve()
    u = np.linspace(0.45, 0.6, 61)
    points = curve.point(u)
    k = int(np.searchsorted(u, 0.5, side="right"))
    points[k, 0] += offset_r * R_MM
    foot, dist = project_points(curve, points, 2.0 * R_MM, R_MM, 10.0 * R_MM)
    assert dist[k] == pytest.approx(offset_r * R_MM, rel=1e-6, abs=1e-11)
    assert (dist[k] > R_MM) == fails
    others = np.delete(np.arange(u.size), k)
    assert np.max(dist[others]) < 1e-11
    assert np.all(np.diff(foot[others]) > 0.0)  # at the corner u itself is ill-posed


def test_a_point_moved_off_the_curve_right_after_a_corner_fails(tmp_path: Path) -> None:
    """The first point after the corner, Y0.0001 on the line X20, moved to X20.0003 (3.5 r off
    the curve, which never passes x = 20): path-deviation at that line and no other."""
    # (the paper model: its first moves from the corner are the ones this was written for)
    machine = default_paper_machine(decimals=DECIMALS)
    good = tmp_path / "corner.nc"
    convert_file(CORNER, good, machine)
    assert check_files(CORNER, good, machine).ok
    lines = good.read_text().splitlines(keepends=True)
    k = next(i for i, line in enumerate(lines) if line.startswith("Y0.0001 "))
    assert lines[k + 1].startswith("Y0.0002 ")
    lines[k] = "X20.0003 " + lines[k]
    lines[k + 1] = "X20. " + lines[k + 1]
    bad = tmp_path / "corner-off.nc"
    bad.write_text("".join(lines))
    report = check_files(CORNER, bad, machine)
    deviations = [v for v in report.violations if v.check == "path-deviation"]
    assert [v.where for v in deviations] == [f"{bad}:{k + 1}"], "\n".join(
        map(str, report.violations))
    assert "0.0003 mm from the curve" in deviations[0].message
