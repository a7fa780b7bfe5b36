"""The limits the machine feels (issue 15), printed as markdown tables. From the repository root:

    python -m tests.bench.path_jerk            # every sample and dense curve, both profiles
    python -m tests.bench.path_jerk --quick    # the short dense curves only

Every curve of each file in samples/ and of tests/bench/dense_curves is planned under the
`default` profile (path model, per-axis limits) and again under the paper model with its path
limits and no axis limits ("default paper"), and under `paper-table1` (paper model) and again
under `jerk_model: path`, stepped with rk2c, and its interpolation points (full precision, one
period apart) are differenced (tests/motion_from_positions): the motion a controller executing
them produces, not the planner's own v, a, j. The first table sets each
path quantity against the profile's limit for it: tangential acceleration and jerk against A_t
and J_t, normal acceleration against A_n, the part of the jerk vector across the path against
J_n (the planner limits the proxy v^3 kappa^2 instead), and the jerk vector's norm against
sqrt(J_t^2 + J_n^2), what the two limits allow together. The second gives each axis's largest
|velocity|, |acceleration| and |jerk|, against the default's per-axis limits under it. A file of
several
curves shows the largest value over its curves and the sum of their cycle times. Measured
here, never asserted.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import Machine, load_machine
from nurbsfeed.pipeline import plan_block
from nurbsfeed.planning.plan import Plan
from nurbsfeed.planning.planner import plan_curve
from tests.bench.dense_curves import dense_curves
from tests.conftest import default_paper_machine
from tests.motion_from_positions import path_motion

ROOT = Path(__file__).resolve().parents[2]
# each profile again under the path jerk model (planning.path_model), named "<profile> path"
PATH_MODEL = " path"
PAPER_MODEL = " paper"  # the default's path limits under the paper model, without its axes


@dataclass(frozen=True)
class Peaks:
    """The largest values over one or more curves, in mm and s."""

    cycle_s: float
    tangential_acc: float
    tangential_jerk: float
    normal_acc: float
    normal_jerk: float
    jerk_norm: float
    axis_velocity: np.ndarray  # (3,) X, Y, Z
    axis_acc: np.ndarray  # (3,)
    axis_jerk: np.ndarray  # (3,)

    def __or__(self, other: Peaks) -> Peaks:
        """Both curves run one after the other: times add, peaks take the larger."""
        return Peaks(self.cycle_s + other.cycle_s,
                     *(np.maximum(getattr(self, name), getattr(other, name))
                       for name in ("tangential_acc", "tangential_jerk", "normal_acc",
                                    "normal_jerk", "jerk_norm", "axis_velocity", "axis_acc",
                                    "axis_jerk")))


def peaks(plan: Plan) -> Peaks:
    result = interpolate(plan, "rk2c")
    if len(result.points) < 4:  # too short to difference three times: no motion to speak of
        return Peaks(plan.cycle_time_s, 0.0, 0.0, 0.0, 0.0, 0.0, *np.zeros((3, 3)))
    m = path_motion(result.points, result.period_s)
    return Peaks(plan.cycle_time_s, float(m.path.tangential_acc_mm_s2.max()),
                 float(np.abs(m.tangential_jerk_mm_s3).max()),
                 float(m.path.normal_acc_mm_s2.max()), float(m.normal_jerk_mm_s3.max()),
                 float(np.linalg.norm(m.jerk_mm_s3, axis=1).max()),
                 np.abs(m.axis_velocity_mm_s).max(axis=0), np.abs(m.axis_acc_mm_s2).max(axis=0),
                 np.abs(m.jerk_mm_s3).max(axis=0))


def sample_peaks(path: Path, machine: Machine) -> Peaks | None:
    plans = [plan_block(block, machine) for block in curve_blocks(path)]
    if not plans:
        return None
    total = peaks(plans[0])
    for plan in plans[1:]:
        total = total | peaks(plan)
    return total


def dense_peaks(curve: NurbsCurve, machine: Machine) -> Peaks:
    return peaks(plan_curve(curve, machine.limits))


def _over(value: float, limit: float) -> str:
    return f"{value:,.0f} ({value / limit:.2f})"


def path_row(name: str, profile: str, p: Peaks, machine: Machine) -> str:
    lim = machine.limits
    return " | ".join([name, profile, f"{p.cycle_s:.3f}", _over(p.tangential_acc, lim.acc_mm_s2),
                       _over(p.tangential_jerk, lim.jerk_mm_s3),
                       _over(p.normal_acc, lim.normal_acc_mm_s2),
                       _over(p.normal_jerk, lim.normal_jerk_mm_s3),
                       _over(p.jerk_norm, math.hypot(lim.jerk_mm_s3, lim.normal_jerk_mm_s3))])


def axis_row(name: str, profile: str, p: Peaks, machine: Machine) -> str:
    lim = machine.limits
    cells = []
    for values, limits, fmt in ((p.axis_velocity, lim.axis_vel_mm_s, "{:.1f}"),
                                (p.axis_acc, lim.axis_acc_mm_s2, "{:,.0f}"),
                                (p.axis_jerk, lim.axis_jerk_mm_s3, "{:,.0f}")):
        cells += [_over(v, limit) if math.isfinite(limit) else fmt.format(v)
                  for v, limit in zip(values, limits)]
    return " | ".join([name, profile, *cells])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the short dense curves only")
    args = parser.parse_args()
    machines = {"default": load_machine("default"),
                "default" + PAPER_MODEL: default_paper_machine(),
                "paper-table1": load_machine("paper-table1"),
                "paper-table1" + PATH_MODEL: load_machine("paper-table1", {"jerk_model": "path"})}
    rows: list[tuple[str, str, Peaks]] = []
    if not args.quick:
        for path in sorted((ROOT / "samples").iterdir()):
            for profile, machine in machines.items():
                found = sample_peaks(path, machine)
                if found is not None:
                    rows.append((path.name, profile, found))
    for curve in dense_curves(quick=args.quick):
        for profile, machine in machines.items():
            rows.append((curve.name, profile, dense_peaks(curve, machine)))
    print("Path: measured (measured / limit); mm, s. Limits: tangential acceleration A_t, "
          "tangential jerk J_t, normal acceleration A_n, normal jerk J_n, jerk norm "
          "sqrt(J_t^2 + J_n^2).\n")
    print("| curve | profile | cycle s | a_t | j_t | a_n | j_n | \\|j\\| |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for name, profile, found in rows:
        print(f"| {path_row(name, profile, found, machines[profile])} |")
    print("\nAxes: largest |velocity| mm/s, |acceleration| mm/s², |jerk| mm/s³, with "
          "(measured / limit) where the profile limits the axis (the default's per-axis "
          "limits).\n")
    print("| curve | profile | vX | vY | vZ | aX | aY | aZ | jX | jY | jZ |")
    print("|---|---|" + "---:|" * 9)
    for name, profile, found in rows:
        print(f"| {axis_row(name, profile, found, machines[profile])} |")


if __name__ == "__main__":
    main()
