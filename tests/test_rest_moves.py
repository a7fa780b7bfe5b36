"""Moves from and into a rest made of several planned periods (profile key rest_move_s,
rest_moves.RestMoves): which points merge, that every written point is a planned point, and that
the F words still add up to the planned cycle."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest

from nurbsfeed.gcode.writer import MoveWriter, round_ticks
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate.stepping import PointChunk, interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file, plan_block
from nurbsfeed.program import CurveBlock
from nurbsfeed.readers import read_program
from nurbsfeed.rest_moves import RestMoves, rest_move_periods
from tests.conftest import SAMPLES
from tests.gcode_parse import moves

RADIUS_MM = 10.0
SQRT_HALF = math.sqrt(0.5)


def quarter_circle() -> NurbsCurve:
    """The exact quarter circle of radius 10 from (10, 0) to (0, 10), u in [0, 1]."""
    return NurbsCurve.build(2, [0, 0, 0, 1, 1, 1], [[10, 0, 0], [10, 10, 0], [0, 10, 0]],
                            [1, SQRT_HALF, 1])


def sag_mm(angle_rad: float) -> float:
    """How far an arc of the circle spanning `angle_rad` gets from its chord."""
    return RADIUS_MM * (1.0 - math.cos(angle_rad / 2.0))


def chunk(u: np.ndarray, curve: NurbsCurve, stretch: object) -> PointChunk:
    return PointChunk(0, u, curve.point(u), np.zeros(u.size), stretch, 1, 0.0)  # type: ignore[arg-type]


def feed_through(rest: RestMoves, curve: NurbsCurve, u: np.ndarray, sizes: list[int],
                 stretch: object) -> np.ndarray:
    """The points RestMoves hands on for the curve's points at u[1:] (u[0]: the start), given
    in chunks of `sizes`, then finished."""
    out = [rest.take(PointChunk(0, u[:1], curve.point(u[:1]), np.zeros(1), None, 0, 0.0))]
    lo = 1
    for size in sizes:
        out.append(rest.take(chunk(u[lo:lo + size], curve, stretch)))
        lo += size
    assert lo == u.size
    out.append(rest.finish())
    return np.concatenate(out)


def merged_spans(handed: np.ndarray, planned: np.ndarray, start: np.ndarray) -> list[int]:
    """The periods of each move the writer makes of the handed points (after `start`), read
    as it reads them: a point equal to the last written one is dropped and its period goes to
    the next move, the run onto the end to the last move. Checks that each move ends on the
    planned point of its period."""
    assert handed.shape == planned.shape
    spans: list[int] = []
    written = []
    last, pending = start, 0
    for point in handed:
        pending += 1
        if np.array_equal(point, last):
            continue
        spans.append(pending)
        written.append(point)
        last, pending = point, 0
    if pending:
        spans[-1] += pending
    np.testing.assert_array_equal(np.array(written), planned[np.cumsum(spans) - 1])
    return spans


def test_the_first_and_last_moves_take_as_many_periods_as_fit_the_chord_tolerance() -> None:
    curve = quarter_circle()
    u = np.linspace(0.0, 1.0, 41)
    points = curve.point(u)
    angles = np.arctan2(points[:, 1], points[:, 0])
    # a tolerance between the sags of 3 and of 4 periods at both ends: 3 fit, 4 do not
    three = max(sag_mm(angles[3] - angles[0]), sag_mm(angles[-1] - angles[-4]))
    four = min(sag_mm(angles[4] - angles[0]), sag_mm(angles[-1] - angles[-5]))
    chord_mm = three * 1.001
    assert chord_mm < four
    handed = feed_through(RestMoves(curve, chord_mm, 6), curve, u, [40], object())
    assert merged_spans(handed, points[1:], points[0]) == [3] + [1] * 34 + [3]
    # inside a merged move: copies of its start, which the writer drops; else as given
    np.testing.assert_array_equal(handed[:2], np.repeat(points[:1], 2, axis=0))
    np.testing.assert_array_equal(handed[2:-3], points[3:-3])
    np.testing.assert_array_equal(handed[-3:-1], np.repeat(points[-4:-3], 2, axis=0))
    np.testing.assert_array_equal(handed[-1], points[-1])


def test_a_loose_tolerance_merges_the_full_periods_and_a_tight_one_none() -> None:
    curve = quarter_circle()
    u = np.linspace(0.0, 1.0, 31)
    points = curve.point(u)
    loose = feed_through(RestMoves(curve, 1.0, 5), curve, u, [30], object())
    assert merged_spans(loose, points[1:], points[0]) == [5] + [1] * 20 + [5]
    tight = feed_through(RestMoves(curve, 1e-9, 5), curve, u, [30], object())
    np.testing.assert_array_equal(tight, points[1:])


@pytest.mark.parametrize("sizes", [[30], [1] * 30, [2, 3, 25], [7, 7, 7, 9], [26, 1, 3],
                                   [29, 1]])
def test_where_the_chunks_are_cut_does_not_change_what_is_handed_on(sizes) -> None:
    curve = quarter_circle()
    u = np.linspace(0.0, 1.0, 31)
    whole = feed_through(RestMoves(curve, 1.0, 5), curve, u, [30], object())
    cut = feed_through(RestMoves(curve, 1.0, 5), curve, u, sizes, object())
    np.testing.assert_array_equal(cut, whole)


@pytest.mark.parametrize("n_periods", [1, 2, 3, 5, 7, 9, 10, 11])
def test_a_stretch_shorter_than_two_rest_moves_keeps_every_period(n_periods) -> None:
    curve = quarter_circle()
    u = np.linspace(0.0, 1.0, n_periods + 1)
    points = curve.point(u)
    handed = feed_through(RestMoves(curve, 100.0, 5), curve, u, [n_periods], object())
    spans = merged_spans(handed, points[1:], points[0])
    assert sum(spans) == n_periods
    assert spans[0] == min(5, n_periods)
    assert spans[-1] <= 5
    np.testing.assert_array_equal(handed[-1], points[-1])


def test_a_rest_inside_the_curve_ends_one_stretch_and_starts_the_next() -> None:
    curve = quarter_circle()
    u = np.linspace(0.0, 1.0, 41)
    rest = RestMoves(curve, 1.0, 4)
    first, second = object(), object()
    out = [rest.take(PointChunk(0, u[:1], curve.point(u[:1]), np.zeros(1), None, 0, 0.0)),
           rest.take(chunk(u[1:21], curve, first)),  # stops at u[20]
           rest.take(chunk(u[21:], curve, second)), rest.finish()]
    spans = merged_spans(np.concatenate(out), curve.point(u[1:]), curve.point(u[:1])[0])
    assert spans == [4] + [1] * 12 + [4] + [4] + [1] * 12 + [4]


def converted(profile: str, overrides: dict, tmp_path) -> str:
    target = tmp_path / f"{profile}.nc"
    convert_file(SAMPLES / "quarter-circle.json", target, load_machine(profile, overrides))
    return target.read_text()


def test_linuxcnc_output_merges_ten_ms_at_each_rest_on_the_planned_law(tmp_path) -> None:
    machine = load_machine("linuxcnc")
    assert rest_move_periods(machine) == 5  # 10 ms of 2 ms moves
    block = next(item for item in read_program(SAMPLES / "quarter-circle.json")
                 if isinstance(item, CurveBlock)).in_mm()
    plan = plan_block(block, machine)
    planned = interpolate(plan)
    start = block.curve.points[0]
    points, feeds, _ = moves(converted("linuxcnc", {}, tmp_path), start)
    move_s = machine.limits.period_s
    lengths = np.linalg.norm(np.diff(np.vstack([start, points]), axis=0), axis=1)
    durations = lengths / (feeds / 60.0)
    periods = np.rint(durations / move_s).astype(int)
    # F = |dP| / duration to the 5 significant digits F is written with
    np.testing.assert_allclose(durations, periods * move_s, rtol=1e-4)
    assert periods[0] == 5 and periods[-1] == 5
    assert np.all(periods[1:-1] == 1)
    # every written point is the planned point of its period, rounded as written
    reached = np.cumsum(periods)
    np.testing.assert_array_equal(round_ticks(points, 6),
                                  round_ticks(planned.points[reached], 6))
    # the F words add up to the planned cycle (the rs274 tier holds them to 0.1 %)
    assert math.isclose(float(durations.sum()), plan.cycle_time_s, rel_tol=1e-4)
    assert int(reached[-1]) == plan.n_periods


def test_without_the_key_every_period_is_its_own_move(tmp_path) -> None:
    assert rest_move_periods(load_machine("default")) == 1
    off = converted("linuxcnc", {"rest_move_s": 0.0}, tmp_path)
    on = converted("linuxcnc", {}, tmp_path)
    start = np.array([10.0, 0.0, 0.0])
    points_off, _, _ = moves(off, start)
    points_on, _, _ = moves(on, start)
    # merging drops the 4 points inside each merged move and changes nothing else
    np.testing.assert_array_equal(points_on, np.vstack([points_off[4:-5], points_off[-1:]]))


def test_merged_moves_reach_the_writer_as_one_move_each() -> None:
    curve = quarter_circle()
    u = np.linspace(0.0, 1.0, 31)
    handed = feed_through(RestMoves(curve, 1.0, 5), curve, u, [30], object())
    out = io.BytesIO()
    writer = MoveWriter(out, 6, 3, 0.002, "\n", curve.points[0])
    writer.add_points(handed)
    writer.end_curve()
    points, feeds, _ = moves(out.getvalue().decode(), curve.points[0])
    assert writer.moves == 22
    lengths = np.linalg.norm(np.diff(np.vstack([curve.points[0], points]), axis=0), axis=1)
    durations = lengths / (feeds / 60.0)
    np.testing.assert_allclose(durations, [0.010] + [0.002] * 20 + [0.010], rtol=1e-4)


def test_check_accepts_a_move_from_rest_only_as_long_as_the_jerk_allows(tmp_path) -> None:
    # check's rule: a move of n <= ceil(rest_move_s / T) periods may be longer than a rounding
    # merge only up to J_t (n T)^3 / 6 + 2 r, what any motion from (or into) rest covers
    from nurbsfeed.analysis import check_files

    machine = load_machine("linuxcnc")
    target = tmp_path / "out.ngc"
    convert_file(SAMPLES / "quarter-circle.json", target, machine)

    def skipped(report) -> list[str]:
        return [v.where for v in report.violations if v.check == "skipped-periods"]

    source = SAMPLES / "quarter-circle.json"
    assert skipped(check_files(source, target, machine)) == []
    # the same moves judged without the key: the two rest moves are periods skipped
    without = load_machine("linuxcnc", {"rest_move_s": 0.0})
    assert len(skipped(check_files(source, target, without))) == 2
    # a rest move stretched by a period beyond the jerk's reach is caught
    lines = target.read_text().splitlines(keepends=True)
    first = next(i for i, line in enumerate(lines) if line.startswith("G1 "))
    words = dict((w[0], float(w[1:])) for w in lines[first].split()[1:])
    longer = {k: v * 1.2 for k, v in words.items() if k in "XY"}
    lines[first] = "G1 " + " ".join(f"{k}{v:.6f}" for k, v in longer.items()) + \
        f" F{words['F'] * 1.2:.4f}\n"
    target.write_text("".join(lines))
    assert f"{target}:{first + 1}" in skipped(check_files(source, target, machine))
