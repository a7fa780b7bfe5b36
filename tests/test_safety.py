"""The motion guard (nurbsfeed/safety.py): the last look at the points before they are written."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.errors import CurveError
from nurbsfeed.interpolate import interpolate
from nurbsfeed.machine import machine_from_mapping
from nurbsfeed.pipeline import plan_block
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.safety import GUARD_ACC_REL, GUARD_FEED_REL, GUARD_JERK_REL, MotionGuard
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
