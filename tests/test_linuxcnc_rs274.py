"""LinuxCNC's own interpreter reads every converted sample as we meant it.

rs274 (LinuxCNC's standalone interpreter) turns a program into the canonical moves a LinuxCNC
machine would plan. For every sample converted with the linuxcnc profile (the one for such a
machine) and with the default profile: no interpreter error;
its feed moves are the points we wrote, in order, with the F we wrote; and summed as
distance / F they last the planned cycle of each curve, so the machine is asked for the feed
the plan computed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.linuxcnc.canon import (
    CanonCurve,
    interpreted_cycle_s,
    printed_tolerance,
    rs274_path,
    run_rs274,
)
from tests.linuxcnc.programs import (
    WrittenCurve,
    convert_for_linuxcnc,
    fanuc_only_lines,
    samples,
    written_curves,
)

CYCLE_TOLERANCE = 1e-3  # the interpreted cycle within 0.1 % of the planned one

pytestmark = pytest.mark.skipif(
    rs274_path() is None,
    reason="rs274 not installed: LinuxCNC's interpreter comes with the linuxcnc-uspace package")


PROFILES = ("linuxcnc", "default")


@pytest.fixture(scope="module")
def converted_with(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, Path]]:
    return {profile: {source.name: convert_for_linuxcnc(source,
                                                        tmp_path_factory.mktemp(profile),
                                                        profile=profile)
                      for source in samples()}
            for profile in PROFILES}


@pytest.fixture(scope="module")
def converted(converted_with: dict[str, dict[str, Path]]) -> dict[str, Path]:
    return converted_with["linuxcnc"]


def cycle_error(canon: CanonCurve, written: WrittenCurve) -> float:
    """Relative difference between the interpreted and the planned cycle of one curve."""
    return interpreted_cycle_s(canon, written) / canon.planned_cycle_s - 1.0


def check_read_as_written(canon: CanonCurve, written: WrittenCurve) -> None:
    assert len(canon.ends) == len(written.ends)
    tolerance = printed_tolerance(written.decimals)
    known = ~np.isnan(written.ends)
    assert np.all(np.abs(canon.ends - written.ends)[known] <= tolerance)
    feed_tolerance = printed_tolerance(6)  # F keeps 5 significant digits when small
    assert np.all(np.abs(canon.feeds_per_min - written.feeds_per_min) <= feed_tolerance)
    assert abs(canon.planned_cycle_s - canon.comment_cycle_s) <= 0.5e-3


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("name", [source.name for source in samples()])
def test_linuxcnc_reads_the_moves_and_feeds_we_wrote(converted_with: dict[str, dict[str, Path]],
                                                     profile: str, name: str,
                                                     tmp_path: Path) -> None:
    program = converted_with[profile][name]
    canon = run_rs274(program, tmp_path)
    assert canon.returncode == 0 and canon.errors() == [], canon.errors()
    written = written_curves(program.read_text())
    interpreted = canon.curves()
    assert len(interpreted) == len(written) >= 1
    for canon_curve, written_curve in zip(interpreted, written):
        check_read_as_written(canon_curve, written_curve)
        assert abs(cycle_error(canon_curve, written_curve)) <= CYCLE_TOLERANCE


def test_the_fanuc_only_lines_left_out_are_the_ones_linuxcnc_stops_at(
        converted: dict[str, Path], tmp_path: Path) -> None:
    """The LinuxCNC copies leave out exactly the lines rs274 refuses, and nothing else."""
    left_out = {}
    for source in samples():
        with_them = tmp_path / f"{source.stem}.as-converted.nc"
        with_them.write_text(converted[source.name].with_suffix(".converted.nc").read_text())
        lines = fanuc_only_lines(with_them.read_text())
        if lines:
            left_out[source.name] = lines[0]
            canon = run_rs274(with_them, tmp_path)
            assert canon.returncode != 0
            assert canon.errors() == ["All axes missing with motion code", lines[0]]
    assert left_out == {"fanuc-multi-curve.nc": "N60 G05 P10000",
                        "fanuc-quadratic.nc": "N60 G05.1 Q1"}


@pytest.mark.parametrize("feed_scale, within", [(1.0006, True), (1.0015, False)])
def test_the_cycle_check_fails_a_program_whose_feeds_are_off(
        converted: dict[str, Path], tmp_path: Path, feed_scale: float, within: bool) -> None:
    """Both sides of the 0.1 % tolerance: every F scaled by 1.0006 passes, by 1.0015 fails."""
    text = converted["butterfly.json"].read_text()
    scaled = "\n".join(_scale_feed(line, feed_scale) for line in text.splitlines()) + "\n"
    program = tmp_path / "butterfly-scaled.ngc"
    program.write_text(scaled)
    canon = run_rs274(program, tmp_path)
    [curve] = canon.curves()
    [written] = written_curves(scaled)
    check_read_as_written(curve, written)
    assert (abs(cycle_error(curve, written)) <= CYCLE_TOLERANCE) is within


def _scale_feed(line: str, scale: float) -> str:
    head, f, value = line.partition(" F")
    if not f or line.startswith("("):
        return line
    return f"{head} F{float(value) * scale:.4f}"
