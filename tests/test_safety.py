"""The motion guard (nurbsfeed/safety.py): the last look at the points before they are written."""

from __future__ import annotations

import numpy as np
import pytest

from nurbsfeed.errors import CurveError
from nurbsfeed.interpolate import interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.safety import GUARD_ACC_REL, GUARD_FEED_REL, MotionGuard

DEFAULT = load_machine("default").limits  # 200 mm/s, 2000 mm/s^2, 1 ms


def line(speed_mm_s: float, n: int, direction=(1.0, 0.0, 0.0)) -> np.ndarray:
    """n points at constant speed along a direction from the origin, one period apart."""
    return np.arange(n)[:, None] * speed_mm_s * DEFAULT.period_s * np.asarray(direction)


def test_a_move_above_the_feed_cap_is_refused() -> None:
    # the collapse: a 29.2 mm curve written as one move of one period
    with pytest.raises(CurveError, match=r"curve 0: refused, point 1 would move at 29212 mm/s"):
        MotionGuard(DEFAULT, "curve 0").check(np.array([[0.0, 0, 0], [29.212, 0, 0]]))


def test_the_feed_cap_on_both_sides() -> None:
    MotionGuard(DEFAULT, "c").check(line(200.0 * (1 + 0.9 * GUARD_FEED_REL), 50))
    with pytest.raises(CurveError, match="above the feed cap of 200 mm/s"):
        MotionGuard(DEFAULT, "c").check(line(200.0 * (1 + 1.1 * GUARD_FEED_REL), 50))


def test_a_corner_at_speed_is_refused_across_chunks() -> None:
    # 100 mm/s along x, then along y: a second difference of 1.4e5 mm/s^2 at the corner,
    # which falls on the boundary between two chunks
    first = line(100.0, 20)
    second = first[-1] + line(100.0, 21, (0.0, 1.0, 0.0))[1:]
    guard = MotionGuard(DEFAULT, "curve 3")
    guard.check(first)
    with pytest.raises(CurveError, match=r"point 20 would accelerate at 141421 mm/s\^2"):
        guard.check(second)


def test_acceleration_bound_on_both_sides() -> None:
    # constant acceleration a along x: every second difference is a T^2
    bound = np.hypot(DEFAULT.acc_mm_s2, DEFAULT.normal_acc_mm_s2) * (1 + GUARD_ACC_REL)
    t = np.arange(30) * DEFAULT.period_s
    for acc, ok in ((bound * 0.999, True), (bound * 1.001, False)):
        points = np.zeros((30, 3))
        points[:, 0] = 0.5 * acc * t**2
        guard = MotionGuard(DEFAULT, "c")
        if ok:
            guard.check(points)
        else:
            with pytest.raises(CurveError, match="would accelerate"):
                guard.check(points)


def test_points_one_at_a_time_are_checked_like_a_chunk() -> None:
    first = line(100.0, 5)
    corner = first[-1] + np.array([0.0, 0.1, 0.0])
    guard = MotionGuard(DEFAULT, "c")
    for p in first:
        guard.check(p[None, :])
    with pytest.raises(CurveError, match="point 5 would accelerate"):
        guard.check(corner[None, :])


def test_a_nan_is_refused() -> None:
    points = line(10.0, 5)
    points[3, 1] = np.nan
    with pytest.raises(CurveError, match="point 3 is not a finite number"):
        MotionGuard(DEFAULT, "c").check(points)


def test_every_sample_curve_passes(butterfly, paper_limits) -> None:
    for lim in (paper_limits, DEFAULT):
        points = interpolate(plan_curve(butterfly, lim)).points
        MotionGuard(lim, "butterfly").check(points)
