"""Curves whose control points all coincide, with weights != 1: zero-length curves.

Found by the fuzzing tier (tests/fuzz): a weight != 1 leaves rounding noise in C' where it is 0,
and a degree-1 curve of two equal points never finished converting (the arc length split the
noise without end, inside compiled code); with an interior knot a chord of length 0 was
divided by (internal error). Both convert to the zero-length comment and no move.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.planning.grid import build_grid

CASES = Path(__file__).parent / "data" / "zero-length"
ZERO_LENGTH_LINE = "(nurbsfeed: zero-length curve, no move written)"


@pytest.mark.parametrize("name", ["two-equal-points-weighted.nc", "equal-points-interior-knot.nc",
                                  "equal-points-interior-knot.json"])
def test_coincident_points_convert_to_no_move(name: str, tmp_path: Path) -> None:
    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["convert", str(CASES / name), "-o", str(out)])
    assert result.exit_code == 0, result.output
    lines = out.read_text().splitlines()
    assert ZERO_LENGTH_LINE in lines
    assert "length 0.000 mm, planned cycle 0.000 s" in lines[lines.index(ZERO_LENGTH_LINE) - 1]
    assert not any(line.startswith("G1") for line in lines)


def test_zero_length_grid_keeps_the_knots_and_feed_changes_as_nodes() -> None:
    curve = NurbsCurve.build(2, [0, 0, 0, 0.5, 1, 1, 1], [[3.0, -2.0, 1.0]] * 4, [1, 0.5, 0.7, 1])
    grid = build_grid(curve, 0.1, np.array([0.3]))
    assert list(grid.u) == [0.0, 0.3, 0.5, 1.0]
    assert not grid.s_mm.any() and not grid.kappa_1_mm.any()
    assert grid.stop_index.size == 0 and grid.peak_index.size == 0


def test_arc_length_of_noise_is_refused_at_the_block_not_endless(tmp_path: Path) -> None:
    """Points 1e-13 mm apart: |C'| is of the order of its own rounding noise, and the arc length
    cannot meet a tolerance relative to it. Refused at the block (FILE:LINE), no output file,
    in bounded time; it once never ended."""
    source = tmp_path / "near.nc"
    source.write_text((CASES / "two-equal-points-weighted.nc").read_text().replace(
        "K0 X2.905 Y-2.043 Z2.913 R0.751", "K0 X2.9050000000001 Y-2.043 Z2.913 R0.751"))
    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(out)])
    assert result.exit_code == 2
    assert f"{source}:3:" in result.output
    assert "arc length does not converge between u = 0 and" in result.output
    assert not out.exists()
