"""The motion guard (nurbsfeed/safety.py): the last look at the points before they are written."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.errors import CurveError
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import machine_from_mapping
from nurbsfeed.pipeline import plan_block
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.safety import (
    GUARD_ACC_REL,
    GUARD_FEED_REL,
    GUARD_JERK_REL,
    MotionGuard,
    difference_maxima,
)
from tests.conftest import default_paper_limits

PAPER = default_paper_limits()  # no per-axis limits: the guard holds the path's alone
SAMPLES = Path(__file__).resolve().parents[1] / "samples"


def line(speed_mm_s: float, n: int, direction=(1.0, 0.0, 0.0)) -> np.ndarray:
    """n points at constant speed along a direction from the origin, one period apart."""
    return np.arange(n)[:, None] * speed_mm_s * PAPER.period_s * np.asarray(direction)


def test_a_move_above_the_feed_cap_is_refused() -> None:
    # the collapse: a 29.2 mm curve written as one move of one period
    with pytest.raises(CurveError, match=r"curve 0: refused, point 1 would move at 29212 mm/s"):
        MotionGuard(PAPER, "curve 0").check(np.array([[0.0, 0, 0], [29.212, 0, 0]]))


def test_the_feed_cap_on_both_sides() -> None:
    MotionGuard(PAPER, "c").check(line(200.0 * (1 + 0.9 * GUARD_FEED_REL), 50))
    with pytest.raises(CurveError, match="above the feed cap of 200 mm/s"):
        MotionGuard(PAPER, "c").check(line(200.0 * (1 + 1.1 * GUARD_FEED_REL), 50))


def test_a_corner_at_speed_is_refused_across_chunks() -> None:
    # 100 mm/s along x, then along y: a second difference of 1.4e5 mm/s^2 at the corner,
    # which falls on the boundary between two chunks
    first = line(100.0, 20)
    second = first[-1] + line(100.0, 21, (0.0, 1.0, 0.0))[1:]
    guard = MotionGuard(PAPER, "curve 3")
    guard.check(first)
    with pytest.raises(CurveError, match=r"point 20 would accelerate at 141421 mm/s\^2"):
        guard.check(second)


def test_acceleration_bound_on_both_sides() -> None:
    # constant acceleration a along x: every second difference is a T^2
    bound = np.hypot(PAPER.acc_mm_s2, PAPER.normal_acc_mm_s2) * (1 + GUARD_ACC_REL)
    t = np.arange(30) * PAPER.period_s
    for acc, ok in ((bound * 0.999, True), (bound * 1.001, False)):
        points = np.zeros((30, 3))
        points[:, 0] = 0.5 * acc * t**2
        guard = MotionGuard(PAPER, "c")
        if ok:
            guard.check(points)
        else:
            with pytest.raises(CurveError, match="would accelerate"):
                guard.check(points)


def test_points_one_at_a_time_are_checked_like_a_chunk() -> None:
    first = line(100.0, 5)
    corner = first[-1] + np.array([0.0, 0.1, 0.0])
    guard = MotionGuard(PAPER, "c")
    for p in first:
        guard.check(p[None, :])
    with pytest.raises(CurveError, match="point 5 would accelerate"):
        guard.check(corner[None, :])


def test_a_nan_is_refused() -> None:
    points = line(10.0, 5)
    points[3, 1] = np.nan
    with pytest.raises(CurveError, match="point 3 is not a finite number"):
        MotionGuard(PAPER, "c").check(points)


def test_every_sample_curve_passes(butterfly, paper_limits) -> None:
    for lim in (paper_limits, PAPER):
        points = interpolate(plan_curve(butterfly, lim)).points
        MotionGuard(lim, "butterfly").check(points)


# ---- the jerk model `path`: the motion's own jerk, and each axis -------------------------------

PATH = dataclasses.replace(PAPER, jerk_model="path", axis_vel_mm_s=(150.0, 150.0, 50.0),
                           axis_acc_mm_s2=(1500.0, 1500.0, 800.0),
                           axis_jerk_mm_s3=(40000.0, 40000.0, 20000.0))


def constant_jerk(jerk: np.ndarray, n: int) -> np.ndarray:
    """n points from rest at a constant jerk vector: every third difference is jerk T^3."""
    t = np.arange(n) * PAPER.period_s
    return t[:, None] ** 3 / 6.0 * np.asarray(jerk, dtype=float)[None, :]


WIDE_AXES = dataclasses.replace(PATH, axis_jerk_mm_s3=(1e6, 1e6, 1e6))


@pytest.mark.parametrize(("lim", "jerk", "limit"),
                         [(PATH, (1.0, 0.0, 0.0), 40000.0), (PATH, (0.0, 0.0, 1.0), 20000.0),
                          (WIDE_AXES, (0.6, 0.8, 0.0), np.hypot(50000.0, 50000.0))],
                         ids=["x-axis", "z-axis", "vector"])
def test_the_path_model_guards_jerk_on_both_sides(lim, jerk, limit: float) -> None:
    """Along X and Z the axis limits bind; with axes wider than the path, the vector's
    sqrt(J_t^2 + J_n^2). The same points pass under the paper model, whose jerk limits are not
    the motion's."""
    direction = np.asarray(jerk)
    bound = limit * (1 + GUARD_JERK_REL)
    MotionGuard(lim, "c").check(constant_jerk(direction * bound * 0.999, 12))
    with pytest.raises(CurveError, match=r"point 3 would jerk at"):
        MotionGuard(lim, "c").check(constant_jerk(direction * bound * 1.001, 12))
    MotionGuard(PAPER, "c").check(constant_jerk(direction * bound * 1.001, 12))


def test_the_path_model_guards_each_axis_velocity_and_acceleration_across_chunks() -> None:
    guard = MotionGuard(PATH, "curve 2")
    points = line(49.0, 10, (0.0, 0.0, 1.0))
    guard.check(points[:4])
    guard.check(points[4:])
    with pytest.raises(CurveError, match=r"curve 2: refused, point 7 would move at 51 mm/s "
                                         r"along Z, above the axis's 50 mm/s"):
        MotionGuard(PATH, "curve 2").check(np.concatenate(
            [line(49.0, 7, (0.0, 0.0, 1.0)), line(49.0, 7, (0.0, 0.0, 1.0))[6] + line(
                51.0, 3, (0.0, 0.0, 1.0))[1:]]))
    t = np.arange(30) * PAPER.period_s
    accelerating = np.zeros((30, 3))
    accelerating[:, 2] = 0.5 * 800.0 * (1 + GUARD_ACC_REL) * 1.001 * t**2
    guard = MotionGuard(dataclasses.replace(PATH, axis_jerk_mm_s3=(np.inf,) * 3), "c")
    guard.check(accelerating[:1])
    with pytest.raises(CurveError, match=r"point 2 would accelerate at .* along Z"):
        guard.check(accelerating[1:])


@pytest.mark.parametrize("name", ["butterfly.json", "fanuc-multi-curve.nc"])
def test_path_plans_of_the_samples_pass_the_path_guard(name: str) -> None:
    from tests.test_path_model import PATH_PROFILE  # the per-axis limits below the path's

    machine = machine_from_mapping(PATH_PROFILE, "test")
    for block in curve_blocks(SAMPLES / name):
        MotionGuard(machine.limits, "c").check(interpolate(plan_block(block, machine)).points)


def numpy_maxima(points: np.ndarray) -> np.ndarray:
    """The largest differences of points (N, 3) as numpy takes them (the readings
    `_difference_maxima` stands for): (13,), in its order."""
    out = np.zeros(13)
    out[0] = float(np.isfinite(points).all())
    diff = points
    for k, first in ((1, 1), (2, 5), (3, 9)):
        diff = np.diff(diff, axis=0)
        if diff.shape[0] == 0:
            break
        if k == 2:
            turn = points[2:] - 2.0 * points[1:-1] + points[:-2]
            norm = np.sqrt(turn[:, 0] ** 2 + turn[:, 1] ** 2 + turn[:, 2] ** 2)
        else:
            norm = np.linalg.norm(diff, axis=1)
        out[first] = np.max(norm)
        out[first + 1:first + 4] = np.max(np.abs(diff), axis=0)
    return out


def random_points(rng: np.random.Generator, n: int) -> np.ndarray:
    """A smooth run of n points one period apart, at any offset and scale."""
    t = np.arange(n)[:, None] * 1e-3
    return (rng.uniform(-500, 500, 3) + rng.uniform(-200, 200, 3) * t
            + rng.uniform(-2000, 2000, 3) * t**2 + rng.uniform(-5e4, 5e4, 3) * t**3)


def test_the_compiled_differences_are_numpys_to_the_last_bit() -> None:
    rng = np.random.default_rng(7)
    for n in [0, 1, 2, 3, 4, 5, *rng.integers(6, 3000, 40).tolist()]:
        points = random_points(rng, n)
        if n > 3 and rng.random() < 0.3:
            points[rng.integers(n)] += rng.normal(0, 1e-3, 3)  # a kink
        assert np.array_equal(difference_maxima(points), numpy_maxima(points)), n
    for bad in (np.nan, np.inf, -np.inf):
        points = random_points(rng, 9)
        points[4, 1] = bad
        assert np.array_equal(difference_maxima(points), numpy_maxima(points), equal_nan=True)


@pytest.mark.parametrize("lim", [PAPER, PATH], ids=["paper", "path"])
def test_the_guard_refuses_what_its_numpy_reading_refuses(lim) -> None:
    """Random runs with a step of random size somewhere, checked in random chunks: the guard
    refuses at the point, and with the message, that the numpy reading of the whole run at once
    finds, and passes what it passes."""
    rng = np.random.default_rng(11)
    step_mm = lim.feed_mm_s * lim.period_s
    outcomes = set()
    for _ in range(300):
        n = int(rng.integers(4, 400))
        points = np.arange(n)[:, None] * step_mm * 0.5 * np.array([0.6, 0.8, 0.0])
        points[int(rng.integers(1, n)):] += rng.normal(0, 10.0 ** rng.uniform(-10, -2), 3)
        expected = None
        try:
            MotionGuard(lim, "c")._numpy_reading(points)
        except CurveError as exc:
            expected = exc.message
        refused = None
        guard = MotionGuard(lim, "c")
        try:
            for chunk in np.split(points, np.sort(rng.integers(0, n, 3))):
                guard.check(chunk)
        except CurveError as exc:
            refused = exc.message
        assert refused == expected
        outcomes.add(expected is None)
    assert outcomes == {True, False}  # both sides of the bounds were drawn
