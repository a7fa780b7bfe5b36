"""How planning time grows with a curve's duration, under the default profile. Run from the
repository root:

    python -m tests.bench.scaling            # curves of 16 to 2,048 control points
    python -m tests.bench.scaling --quick    # 16 to 128

Each curve is one of the benchmark's CAM-like curves (tests/bench/programs.py `random_curves`,
seed 7) with more and more control points, so that its length and its duration grow in
proportion, at the benchmark's 100 mm/s. Printed per curve: its cycle, the planner's cells,
the CPU time of `planner.plan_curve` (in one process, warm cache, the least of RUNS), and that
time per period of the motion, which stays flat where planning is linear in the duration (a
curve whose schedule needs cells cut is planned again whole, once or twice: design §2e).
Speed is measured here, never asserted in the test suite.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

import nurbsfeed.planning.path_plan as path_plan
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine
from nurbsfeed.planning.planner import plan_curve
from tests.bench.programs import random_curves

RUNS = 3
FEED_MM_S = 100.0
SIZES = (16, 32, 64, 128, 256, 512, 768, 1024, 1536, 2048)


def curve_of(n_ctrl: int) -> NurbsCurve:
    spec = random_curves(1, seed=7, n_ctrl=n_ctrl)[0]
    return NurbsCurve.build(spec["degree"], np.array(spec["knots"]),
                            np.array(spec["control_points"]), np.array(spec["weights"]),
                            f"cam-{n_ctrl}")


def measure(curve: NurbsCurve) -> tuple[float, int, float]:
    """(cycle s, the cells of the last schedule planned, least CPU seconds of a plan)."""
    lim = dataclasses.replace(load_machine("default").limits, feed_mm_s=FEED_MM_S)
    cells = []
    planned = path_plan.plan_schedule

    def counted(layout, *args, **kwargs):
        cells.append(layout.cells.shape[0])
        return planned(layout, *args, **kwargs)

    path_plan.plan_schedule = counted
    try:
        best = np.inf
        for _ in range(RUNS):
            start = time.process_time()
            plan = plan_curve(curve, lim)
            best = min(best, time.process_time() - start)
    finally:
        path_plan.plan_schedule = planned
    return plan.cycle_time_s, cells[-1] if cells else 0, best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="curves of 16 to 128 points")
    args = parser.parse_args()
    sizes = [n for n in SIZES if not args.quick or n <= 128]
    plan_curve(curve_of(8), load_machine("default").limits)  # the kernels, loaded
    print("| control points | cycle (s) | cells | plan (ms CPU) | µs per period |")
    print("| ---: | ---: | ---: | ---: | ---: |")
    for n in sizes:
        cycle, cells, seconds = measure(curve_of(n))
        period = load_machine("default").limits.period_s
        print(f"| {n:,} | {cycle:.3f} | {cells:,} | {seconds * 1e3:.1f} | "
              f"{seconds / (cycle / period) * 1e6:.2f} |")


if __name__ == "__main__":
    main()
