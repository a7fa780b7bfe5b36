"""A converted sample run end to end on a headless simulated LinuxCNC mill, and the measurement
that turns its recorded positions into a cycle ratio and a path error.

The simulation test asserts what does not depend on how busy the computer is: the machine runs
the program to its end, follows the curve within 1 µm, and is never faster than the plan. How
close it comes to the planned cycle is measured by `python -m tests.bench.linuxcnc`, not
asserted: LinuxCNC's queue is filled in real time, so a loaded machine can slow it down.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SAMPLES
from tests.linuxcnc.measure import measure
from tests.linuxcnc.programs import convert_for_linuxcnc, written_curves
from tests.linuxcnc.run_sim import SERVO_PERIOD_S, simulate, unavailable_reason

SHORT_SAMPLE = SAMPLES / "quarter-circle.json"  # 0.38 s of moves


@pytest.fixture(scope="module")
def program(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return convert_for_linuxcnc(SHORT_SAMPLE, tmp_path_factory.mktemp("sim"))


def planned_positions(program: Path, every_s: float, offset_mm: float = 0.0) -> np.ndarray:
    """Where the plan puts the tool every `every_s` seconds: the written polyline walked at
    the written feeds, held a while at both ends as a machine would be; shifted by offset_mm
    along Z."""
    [written] = written_curves(program.read_text())
    start = np.array([10.0, 0.0, 0.0])  # the quarter circle's first control point
    vertices = np.vstack([start, np.where(np.isnan(written.ends), start, written.ends)])
    lengths = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
    times = np.concatenate([[0.0], np.cumsum(lengths / written.feeds_per_min * 60.0)])
    at = np.arange(-0.02, times[-1] + 0.02, every_s)
    positions = np.column_stack([np.interp(at, times, vertices[:, axis]) for axis in range(3)])
    return positions + [0.0, 0.0, offset_mm]


@pytest.mark.parametrize("pace", [1.0, 1.5])
def test_a_machine_on_the_planned_points_measures_the_planned_cycle(program: Path,
                                                                    pace: float) -> None:
    """Positions taken from the plan itself, at the plan's pace or 1.5 times slower."""
    [run] = measure(SHORT_SAMPLE, program, planned_positions(program, SERVO_PERIOD_S / pace))
    assert run.cycle_ratio == pytest.approx(pace, rel=1e-9)
    assert run.path_error_mm < 1e-3  # the written chords: δ = 0.9 µm, rounding 0.001 µm


def test_a_machine_that_stops_mid_curve_measures_the_time_it_stood(program: Path) -> None:
    """As when LinuxCNC's queue runs empty: 50 periods held halfway, then on as planned."""
    positions = planned_positions(program, SERVO_PERIOD_S)
    halfway = len(positions) // 2
    held = np.vstack([positions[:halfway], np.repeat(positions[halfway - 1:halfway], 50, axis=0),
                      positions[halfway:]])
    [steady] = measure(SHORT_SAMPLE, program, positions)
    [run] = measure(SHORT_SAMPLE, program, held)
    assert (steady.standstill_periods, run.standstill_periods) == (0, 50)
    assert run.measured_s - steady.measured_s == pytest.approx(50 * SERVO_PERIOD_S, rel=1e-9)


def test_a_machine_beside_the_curve_measures_its_distance(program: Path) -> None:
    """Sampled every 8 servo periods: each sample off the curve costs the projection a search
    along the whole curve, and every one of them is 5 um off (one would show a wrong distance)."""
    [run] = measure(SHORT_SAMPLE, program, planned_positions(program, 8 * SERVO_PERIOD_S, 5e-3))
    assert run.path_error_mm == pytest.approx(5e-3, abs=0.5e-3)


def test_the_simulated_machine_runs_a_converted_sample_on_its_curve(program: Path) -> None:
    if reason := unavailable_reason():
        pytest.skip(f"LinuxCNC simulation cannot start: {reason}")
    [run] = measure(SHORT_SAMPLE, program, simulate(program, acc_mm_s2=5000.0))
    assert run.path_error_mm <= 1e-3
    # F is computed from the written coordinates; LinuxCNC never runs a move faster than its F
    assert run.cycle_ratio >= 1.0 - 1e-3


def test_without_linuxcnc_the_reason_names_what_is_missing(monkeypatch: pytest.MonkeyPatch,
                                                           tmp_path: Path) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))
    assert unavailable_reason() == ("LinuxCNC not installed (linuxcnc, halsampler not found; "
                                    "apt-get install linuxcnc-uspace)")
