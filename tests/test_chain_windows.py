"""The planning half of a chain planned in overlapping windows (design §3b, "Long chains";
planning.window, planner.plan_window, chain.curve_after): a curve's plan handed on at one of
its points, the rest of the curve planned from there moving, and the two joined read from their
points as one motion. The pipeline does not plan windows so yet."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nurbsfeed import chains
from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import POSITION_REL, convert_file
from nurbsfeed.planning.basis import ChainEnds
from nurbsfeed.planning.chain import curve_after
from nurbsfeed.planning.planner import plan_curve, plan_window
from nurbsfeed.planning.window import hand_on
from nurbsfeed.safety import slowdown_from_points
from tests.bench import programs
from tests.bench.dense_curves import dense_curves

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = load_machine("default")
PAPER_PATH = load_machine("paper-table1", {"jerk_model": "path", "planner": "optimal"})
NONE = np.empty(0)


def curve_named(name: str):
    if name.endswith(".json"):
        [block] = curve_blocks(ROOT / "samples" / name)
        return block.curve
    return next(c for c in dense_curves(quick=True) if c.name == name)


@pytest.mark.parametrize("u", [0.3, 0.50001, 0.9])
def test_the_curve_after_a_parameter_is_the_same_path(u: float) -> None:
    curve = curve_named("butterfly.json")
    tail = curve_after(curve, u)
    t = np.linspace(0.0, 1.0, 1001)
    assert np.abs(tail.point(t) - curve.point(u + t * (1.0 - u))).max() < 1e-12
    assert tail.input_u(0.0) == pytest.approx(curve.input_u(u), abs=1e-15)
    assert tail.input_u(1.0) == pytest.approx(curve.input_u(1.0), abs=1e-15)


@pytest.mark.parametrize(("name", "machine", "share"), [
    ("butterfly.json", DEFAULT, 0.27),  # braking at its limits: planned with the slack
    ("butterfly.json", DEFAULT, 0.5),
    ("butterfly.json", DEFAULT, 0.7),
    ("star", PAPER_PATH, 0.4),
    ("figure-eight", PAPER_PATH, 0.6),
])
def test_a_plan_handed_on_at_a_point_runs_on_as_one_motion(name: str, machine,
                                                           share: float) -> None:
    """The rest of the curve, planned from the state the plan had at its point k, joined to
    the plan's points up to k: the same cycle within 1 % (the rest is planned on cells and
    sets of its own, inner approximations of another size: measured -0.3 % to +0.6 %, the
    star's rest losing most at its slow tips), and from the points no more than what the
    conversion allows any plan."""
    lim = machine.limits
    curve = curve_named(name)
    plan = plan_curve(curve, lim)
    steps = interpolate(plan)
    k = int(share * plan.n_periods)
    made = hand_on(plan, k)
    assert made is not None
    ends, seed = made
    assert ends.start is not None and seed is not None
    rest = plan_window(curve_after(curve, float(steps.u[k])), lim, NONE, NONE, ends, seed)
    assert rest is not None and rest.uniform_slowdown <= 1.0 + 1e-6
    after = interpolate(rest)
    assert np.linalg.norm(after.points[0] - steps.points[k]) < 1e-12
    joined = np.concatenate([steps.points[:k + 1], after.points[1:]])
    assert (joined.shape[0] - 1) * lim.period_s == pytest.approx(plan.cycle_time_s, rel=1e-2)
    # the speed, each axis's acceleration and jerk across the hand-on read from the points
    speed, asks = slowdown_from_points(lim, [joined])
    assert speed <= 1.0 + 0.5 * 1e-3 and asks <= 1.0 + POSITION_REL


def test_what_cannot_be_handed_on_says_so() -> None:
    """An S-curve plan has no spline to hand on (None); at rest, the next window starts at
    rest (no state, no seed)."""
    lim = DEFAULT.limits
    curve = curve_named("butterfly.json")
    scurve = plan_curve(curve, dataclasses.replace(lim, planner="scurve"))
    assert hand_on(scurve, scurve.n_periods // 2) is None
    plan = plan_curve(curve, lim)
    assert hand_on(plan, 0) == (ChainEnds(), None)


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 10**6), n_curves=st.integers(6, 40), window=st.integers(2, 8),
       turn=st.floats(0.0, 0.3), step=st.floats(0.5, 6.0), feed=st.sampled_from([600, 6000]))
def test_random_long_chains_run_on_within_every_limit(tmp_path: Path, seed: int, n_curves: int,
                                                      window: int, turn: float, step: float,
                                                      feed: int) -> None:
    """Chained programs of random smooth paths (tests/bench/programs.py's, heading and span
    drawn), in windows of 2 to 8 curves: each converts, `check` passes it (every limit from the
    written positions, every joint's lines in place, one result per curve), and it is never
    slower than the same program in windows that rest at their cuts."""
    from click.testing import CliRunner

    from nurbsfeed import windowed
    from nurbsfeed.cli import main

    with pytest.MonkeyPatch.context() as patch:  # (per example: hypothesis runs many in one)
        patch.setattr(chains, "MAX_WINDOW_CURVES", window)
        patch.setattr(programs, "CHAIN_TURN_RAD", turn)
        patch.setattr(programs, "CHAIN_STEP_MM", step)
        text = programs.chained_program(n_curves, seed).replace("F6000.", f"F{feed}.")
        source = tmp_path / "chain.nc"
        source.write_text(text)
        target = tmp_path / "chain.out"
        report = convert_file(source, target, DEFAULT)
        assert [c.index for c in report.curves] == list(range(n_curves))
        assert sum(c.n_points for c in report.curves) == report.n_points
        ok = CliRunner().invoke(main, ["check", str(source), str(target)],
                                catch_exceptions=False)
        assert ok.exit_code == 0, ok.stdout[-3000:]
        patch.setattr(windowed, "RUN_ON", False)
        resting = convert_file(source, tmp_path / "rest.out", DEFAULT)
    assert report.cycle_time_s <= resting.cycle_time_s + DEFAULT.limits.period_s
