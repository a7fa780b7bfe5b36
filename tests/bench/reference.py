"""How far the planner is from the jerk-limited optimum (issue 15), as a markdown table. From the
repository root:

    python -m tests.bench.reference            # the JSON samples and the short dense curves
    python -m tests.bench.reference --quick    # the quarter circle and the figure-eight only

Each curve is planned under `paper-table1`, and under `paper-table1` with `jerk_model: path` by
both planners (`planner: scurve`, the paper's key points and S-curves, and `planner: optimal`,
docs/design.md §2d), and three cycle times are set side by side:

- the time-optimal bound (`analysis.common.time_optimal_bound_s`): rest to rest under the
  pointwise speed limit and |a| <= A_t alone, a lower bound on every schedule that keeps the
  limits (jerk only makes it slower);
- the jerk-limited reference (`analysis.bound`, `plan --reference`): a schedule found by its own
  code that keeps every limit of the same model, so the optimum is no slower than it;
- the planner's.

The optimum lies between the bound and the smaller of the other two. planned / reference above 1
says the planner is at least that far from the optimum; below 1, the reference is the looser
(it is within 1.5 % of the closed form on a straight line, tests/test_bound.py). Measured here,
never asserted; the reference and the optimal planner take seconds to minutes a curve (HiGHS,
one process).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from nurbsfeed.analysis.bound import jerk_limited_schedule
from nurbsfeed.analysis.common import curve_blocks, time_optimal_bound_s
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine
from nurbsfeed.planning.planner import plan_curve
from tests.bench.dense_curves import dense_curves
from tests.bench.path_jerk import ROOT

SAMPLES = ("quarter-circle.json", "circle.json", "butterfly.json")
PROFILE = "paper-table1"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="the quarter circle and the figure-eight only")
    args = parser.parse_args()
    machines = {"paper": load_machine(PROFILE),
                "path": load_machine(PROFILE, {"jerk_model": "path"}),
                "path optimal": load_machine(PROFILE, {"jerk_model": "path",
                                                       "planner": "optimal"})}
    cases: list[tuple[str, NurbsCurve, np.ndarray, np.ndarray]] = []  # with programmed feeds
    for name in SAMPLES[:1] if args.quick else SAMPLES:
        for block in curve_blocks(ROOT / "samples" / name):
            cases.append((name, block.curve, block.feed_u, block.feed_mm_s))
    dense = dense_curves(quick=True)
    for curve in dense[:1] if args.quick else dense:
        cases.append((curve.name, curve, np.empty(0), np.empty(0)))
    print(f"Cycle times in s under {PROFILE}'s limits; ratio = planned / reference.\n")
    print("| curve | model | planner | bound | reference | planned | ratio | planner CPU s "
          "| reference CPU s |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|")
    ratios: dict[str, list[float]] = {setting: [] for setting in machines}
    for name, curve, feed_u, feed in cases:
        references: dict[str, tuple[float, float]] = {}
        for setting, machine in machines.items():
            model = machine.limits.jerk_model
            start = time.process_time()
            plan = plan_curve(curve, machine.limits, feed_u, feed)
            plan_cpu = time.process_time() - start
            if model not in references:
                start = time.process_time()
                ref = jerk_limited_schedule(curve, machine.limits, feed_u, feed)
                references[model] = (ref.cycle_s, time.process_time() - start)
            ref_s, ref_cpu = references[model]
            ratio = plan.cycle_time_s / ref_s
            ratios[setting].append(ratio)
            print(f"| {name} | {model} | {plan.planner} | {time_optimal_bound_s(plan):.3f} | "
                  f"{ref_s:.3f} | {plan.cycle_time_s:.3f} | {ratio:.3f} | {plan_cpu:.1f} | "
                  f"{ref_cpu:.1f} |", flush=True)
    print()
    for setting, values in ratios.items():
        print(f"{setting}: median ratio {statistics.median(values):.3f}, "
              f"largest {max(values):.3f} over {len(values)} curves")


if __name__ == "__main__":
    main()
