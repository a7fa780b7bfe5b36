"""The schedule's nodes (planning.nodes): cells merge to CRUISE_CELL_PERIODS only where the
motion cruises at the feed, far from where it must slow, and the plan on them is the plan on
the shorter cells."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from nurbsfeed.machine import load_machine
from nurbsfeed.planning import nodes, path_plan
from nurbsfeed.planning.planner import plan_curve
from tests.test_reach_planner import BEND

FEED = 100.0
LIM = dataclasses.replace(load_machine("default").limits, feed_mm_s=FEED)


def _no_cruise(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(path_plan, "_cruise_speed",
                        lambda grid, lim, limit, feed_at_u: np.full(grid.u.size, np.nan))


def _arc_speed(plan, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The law's arc length and speed at the first n + 1 periods."""
    piece, local, v, _, _ = plan.law.sample(np.arange(n + 1) * LIM.period_s)
    return plan.law.s0_mm[piece] + local, v


def test_cells_are_long_only_where_the_plan_cruises_at_the_feed_far_from_the_bend() -> None:
    """Cells over MIN_CELL_PERIODS + 2 periods at the feed (the merge keeps a node at the first
    grid node past the least length) lie where the plan itself runs at the feed, and farther
    than F A / J (the distance over which jerk turns the acceleration round) from every point
    where it does not; and there are such cells. (The nodes keep CRUISE_MARGIN F A / J from
    where the speed estimate, which knows no jerk, is below the feed: the plan leaves a rest
    and reaches the feed later than it.)"""
    plan = plan_curve(BEND, LIM)
    layout = plan.schedule.layout
    s = layout.s_mm
    long = np.flatnonzero(np.diff(s) > (nodes.MIN_CELL_PERIODS + 2.0) * FEED * LIM.period_s)
    assert long.size > 20
    arc, speed = _arc_speed(plan, plan.n_periods)
    # the law is stretched to whole periods: its cruise runs a share of a period below the feed
    slow = arc[speed < FEED * (1.0 - 1e-3)]
    margin = FEED * LIM.acc_mm_s2 / LIM.jerk_mm_s3
    for k in long:
        inside = (arc >= s[k]) & (arc <= s[k + 1])
        assert np.all(speed[inside] >= FEED * (1.0 - 1e-3)), (s[k], s[k + 1])
        assert np.min(np.abs(slow - s[k])) > margin and np.min(np.abs(slow - s[k + 1])) > margin


def test_cruise_cells_keep_the_plan(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan on cruise cells runs as the plan without them: the same cycle within a period,
    the same speed within 0.1 % at every period, on fewer cells."""
    plan = plan_curve(BEND, LIM)
    _no_cruise(monkeypatch)
    short = plan_curve(BEND, LIM)
    assert plan.schedule.layout.cells.shape[0] < 0.8 * short.schedule.layout.cells.shape[0]
    assert abs(plan.n_periods - short.n_periods) <= 1
    n = min(plan.n_periods, short.n_periods)
    assert np.max(np.abs(_arc_speed(plan, n)[1] - _arc_speed(short, n)[1])) <= 1e-3 * FEED
