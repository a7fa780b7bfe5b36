"""Measurements of a plan or an interpolation, and the independent check of a converted program.

- `common.time_optimal_bound_s`: a lower bound on any schedule's cycle time (used by `plan`).
- `bound.solve.jerk_limited_schedule`: a schedule keeping every limit, jerk included, found by
  its own code (`plan --reference`, design §2c); imported on demand (scipy).
- `compare.compare_file`: the paper's Table 2 on any input: per interpolator the feed fluctuation
  (design §3) and the compiled kernel's time per step.
- `check.check_files`: verifies a converted program against its source without running the
  planner; every definition and tolerance is in the comment that opens `check.curve_checks`.
- `series.run_series`: what `nurbsfeed plot` draws for one interpolated curve.
- `geometry`: chord errors, arc length and curvature on the true curve, shared by check and plot.

Lengths are in mm (the curves come in mm, `CurveBlock.in_mm`), times in seconds. No printing:
`render_*` return text for the command line.
"""

from nurbsfeed.analysis.check import CHECKS, CheckReport, check_files, render_check
from nurbsfeed.analysis.common import curve_blocks, time_optimal_bound_s
from nurbsfeed.analysis.compare import PAPER_TABLE2, compare_file, render_comparison
from nurbsfeed.analysis.series import RunSeries, curve_run, run_series

__all__ = ["CHECKS", "CheckReport", "PAPER_TABLE2", "RunSeries", "check_files", "compare_file",
           "curve_blocks", "curve_run", "render_check", "render_comparison", "run_series",
           "time_optimal_bound_s"]
