"""How far the planners are from the jerk-limited optimum (issue 28), as a markdown table. From
the repository root:

    python -m tests.bench.reference            # every curve of samples/ and the dense curves
    python -m tests.bench.reference --quick    # the quarter circle and the figure-eight only

Each curve is planned under two settings, both on the path model: the default profile
(configs/default.yaml: path and per-axis limits) and paper-table1's limits with `jerk_model:
path`; under each by the path planner (`planner: optimal`, the default's, docs/design.md §2d)
and by the S-curve planner (`planner: scurve`, the paper's key points and S-curves), each plan
as a conversion makes it (`pipeline.verified_plan`: its points read and the law slowed where
they ask). Beside each plan stand:

- the time-optimal bound (`analysis.common.time_optimal_bound_s`): rest to rest under the
  pointwise speed limit and |a| <= A_t alone, a lower bound on every schedule that keeps the
  limits (jerk only makes it slower);
- the jerk-limited reference (`analysis.bound`, `plan --reference`): a schedule found by its own
  code (linear programs) that keeps every limit of the same model, so the optimum is no slower.

The optimum lies between the bound and the smaller of the other two. planned / reference above 1
says the planner is at least that far from the optimum; below 1, the reference is the looser.
Measured here, never asserted; the reference takes seconds to minutes a curve (HiGHS, one
process), the planners milliseconds to a second. Where HiGHS gives up on one of the
reference's programs the row says "failed" and has no ratio.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from nurbsfeed.analysis.bound.solve import jerk_limited_schedule
from nurbsfeed.analysis.common import curve_blocks, time_optimal_bound_s
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import Machine, load_machine
from nurbsfeed.pipeline import verified_plan
from tests.bench.dense_curves import dense_curves
from tests.bench.path_jerk import ROOT

PLANNERS = ("optimal", "scurve")
SUFFIXES = (".json", ".nc", ".ngc", ".mpf")


def settings() -> dict[str, dict[str, Machine]]:
    """Per setting, a machine per planner."""
    return {
        "default": {planner: load_machine("default", {"planner": planner})
                    for planner in PLANNERS},
        "paper-table1 path": {planner: load_machine("paper-table1", {"jerk_model": "path",
                                                                     "planner": planner})
                              for planner in PLANNERS},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="the quarter circle and the figure-eight only")
    args = parser.parse_args()
    cases: list[tuple[str, NurbsCurve, np.ndarray, np.ndarray]] = []  # with programmed feeds
    samples = sorted(p for p in (ROOT / "samples").iterdir() if p.suffix in SUFFIXES)
    for path in samples[:0] if args.quick else samples:
        blocks = curve_blocks(path)
        for i, block in enumerate(blocks):
            name = path.name if len(blocks) == 1 else f"{path.name} #{i}"
            cases.append((name, block.curve, block.feed_u, block.feed_mm_s))
    if args.quick:
        [block] = curve_blocks(ROOT / "samples" / "quarter-circle.json")
        cases.append(("quarter-circle.json", block.curve, block.feed_u, block.feed_mm_s))
    dense = dense_curves(quick=True)
    for curve in dense[:1] if args.quick else dense:
        cases.append((curve.name, curve, np.empty(0), np.empty(0)))
    print("Cycle times in s; ratio = planned / reference; CPU in s of one process.\n")
    print("| curve | setting | bound | reference | optimal | ratio | scurve | ratio "
          "| optimal CPU | scurve CPU | reference CPU |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    ratios: dict[tuple[str, str], list[float]] = {}
    for name, curve, feed_u, feed in cases:
        for setting, machines in settings().items():
            planned = {}
            for planner, machine in machines.items():
                start = time.process_time()
                plan = verified_plan(curve, machine.limits, feed_u, feed)
                planned[planner] = (plan, time.process_time() - start)
            start = time.process_time()
            try:
                ref_s = jerk_limited_schedule(curve, machines["optimal"].limits, feed_u,
                                              feed).cycle_s
            except RuntimeError:  # HiGHS gave up on one of the reference's programs
                ref_s = math.nan
            ref_cpu = time.process_time() - start
            row = [name, setting, f"{time_optimal_bound_s(planned['optimal'][0]):.3f}",
                   f"{ref_s:.3f}" if math.isfinite(ref_s) else "failed"]
            for planner in PLANNERS:
                ratio = planned[planner][0].cycle_time_s / ref_s
                if math.isfinite(ratio):
                    ratios.setdefault((setting, planner), []).append(ratio)
                row += [f"{planned[planner][0].cycle_time_s:.3f}",
                        f"{ratio:.3f}" if math.isfinite(ratio) else "-"]
            row += [f"{planned[p][1]:.2f}" for p in PLANNERS] + [f"{ref_cpu:.1f}"]
            print("| " + " | ".join(row) + " |", flush=True)
    print()
    for (setting, planner), values in ratios.items():
        print(f"{setting}, {planner}: median ratio {statistics.median(values):.3f}, "
              f"largest {max(values):.3f} over {len(values)} curves")


if __name__ == "__main__":
    main()
