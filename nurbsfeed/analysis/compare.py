"""`nurbsfeed compare`: the paper's Table 2 on any input: per interpolator the feed fluctuation
(design §3) and the compiled kernel's time per step."""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.interpolate.kernels import METHODS, SLOW_SPEED_REL, step_spans
from nurbsfeed.interpolate.stepping import Interpolation, interpolate
from nurbsfeed.machine import Machine
from nurbsfeed.pipeline import plan_block
from nurbsfeed.planning.plan import Plan

# Wei et al. 2022, Table 2 (butterfly, Table 1 limits, MATLAB): max feed fluctuation in %, and
# computation time per interpolation step in microseconds.
PAPER_TABLE2 = {"taylor1": (6.84, 3.9), "rk4": (0.36, 16.1), "rk2c": (0.0281, 11.5)}


@dataclass(frozen=True)
class MethodRow:
    """One interpolator over every curve of the input."""

    method: str
    max_ff_pct: float  # max over curves of the per-curve maximum
    mean_ff_pct: float  # mean over every period of every curve (curves weighted by their steps)
    n_points: int
    n_steps: int
    us_per_step: float  # median kernel time of one run over all targets / steps
    paper_max_ff_pct: float
    paper_us_per_step: float


@dataclass(frozen=True)
class Comparison:
    """Table 2 for one input file."""

    source: str
    n_curves: int  # curves that move (zero-length curves have no period to measure)
    n_zero_length: int
    repeat: int
    rows: tuple[MethodRow, ...]

    def as_dict(self) -> dict[str, Any]:
        return {"source": self.source, "curves": self.n_curves,
                "zero_length_curves": self.n_zero_length, "repeat": self.repeat,
                "aggregate": AGGREGATE_NOTE if self.n_curves > 1 else None,
                "methods": [vars(row) for row in self.rows]}


AGGREGATE_NOTE = ("max: largest per-curve maximum; mean: over every period of every curve "
                  "(curves weighted by their number of steps)")


def kernel_seconds(plan: Plan, result: Interpolation, repeat: int) -> float:
    """Median wall time of `repeat` runs of the compiled kernel over all of a curve's targets.

    The kernel steps once through result.ds_mm from the curve start (one run, whatever the
    stretches between rests): the cost per step, without the end-landing search. The kernel was
    compiled by the `interpolate` call that produced `result`.
    """
    curve = plan.curve
    slow = SLOW_SPEED_REL * plan.length_mm / (curve.u_max - curve.u_min)  # as interpolate()
    u = np.empty(result.ds_mm.size + 1)
    pts = np.empty((u.size, 3))
    code = METHODS[result.method]
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        step_spans(code, curve.knots, curve.span_polynomials, curve.degree, curve.n_ctrl,
                   curve.u_min, result.ds_mm, 1.0, slow, u, pts)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def compare_file(path: Path, machine: Machine, dialect: str, repeat: int) -> Comparison:
    """Feed fluctuation and time per step of every interpolator on every curve of `path`."""
    plans = [plan_block(block, machine) for block in curve_blocks(path, dialect)]
    moving = [p for p in plans if p.n_periods > 0]
    rows = []
    for method in METHODS:
        ff, seconds, points, steps = [], 0.0, 0, 0
        for plan in moving:
            result = interpolate(plan, method)
            ff.append(result.feed_fluctuation())
            seconds += kernel_seconds(plan, result, repeat)
            points += result.n_points
            steps += result.ds_mm.size
        every = np.concatenate(ff) if ff else np.zeros(0)
        paper_ff, paper_us = PAPER_TABLE2[method]
        rows.append(MethodRow(method, 100.0 * float(every.max()) if every.size else 0.0,
                              100.0 * float(every.mean()) if every.size else 0.0, points, steps,
                              1e6 * seconds / steps if steps else 0.0, paper_ff, paper_us))
    return Comparison(str(path), len(moving), len(plans) - len(moving), repeat, tuple(rows))


def render_comparison(c: Comparison, machine_name: str) -> str:
    """The comparison as the paper's Table 2, with the paper's numbers alongside."""
    lines = [f"{c.source}: {c.n_curves} curve(s), machine {machine_name}"
             + (f", {c.n_zero_length} zero-length curve(s) skipped" if c.n_zero_length else ""),
             f"{'method':<8} {'max FF %':>11} {'mean FF %':>11} {'points':>9} "
             f"{'us/step':>8}   {'paper max FF %':>14} {'paper us/step':>13}"]
    for r in c.rows:
        lines.append(f"{r.method:<8} {r.max_ff_pct:>11.4g} {r.mean_ff_pct:>11.4g} "
                     f"{r.n_points:>9,} {r.us_per_step:>8.3f}   {r.paper_max_ff_pct:>14g} "
                     f"{r.paper_us_per_step:>13g}")
    lines.append("FF = | |C(u_k+1) - C(u_k)| - ds_k | / ds_k over every period "
                 f"(docs/design.md §3); us/step: median of {c.repeat} compiled kernel runs")
    lines.append("paper: butterfly, Table 1 limits, MATLAB (Wei et al. 2022, Table 2)")
    if c.n_curves > 1:
        lines.append(f"aggregated over {c.n_curves} curves: {AGGREGATE_NOTE}")
    return "\n".join(lines)
