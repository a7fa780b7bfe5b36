"""What `nurbsfeed plot` draws for one interpolated curve."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.analysis.geometry import chord_errors_mm, curvature_1_mm
from nurbsfeed.errors import InputError, Location
from nurbsfeed.interpolate.stepping import Interpolation, interpolate
from nurbsfeed.machine import Machine
from nurbsfeed.pipeline import plan_block
from nurbsfeed.planning.plan import Plan, feed_at
from nurbsfeed.program import CurveBlock


@dataclass(frozen=True, eq=False)
class RunSeries:
    """What the plots of one interpolated curve show. (N+1,) per point, (N,) per step."""

    t_s: np.ndarray  # (N+1,) time of each point
    t_mid_s: np.ndarray  # (N,) mid-time of each step
    planned_v_mm_s: np.ndarray  # (N+1,) feed of the time law
    feed_cap_mm_s: np.ndarray  # (N+1,) v_m: min(machine max feed, programmed feed) at the point
    chord_v_mm_s: np.ndarray  # (N,) |P_k+1 - P_k| / T
    tangential_acc_mm_s2: np.ndarray  # (N+1,)
    normal_acc_mm_s2: np.ndarray  # (N+1,) v^2 kappa
    tangential_jerk_mm_s3: np.ndarray  # (N+1,)
    normal_jerk_mm_s3: np.ndarray  # (N+1,) v^3 kappa^2
    chord_error_mm: np.ndarray  # (N,) on the true curve, unrounded points
    feed_fluctuation_pct: np.ndarray  # (N,) design §3; NaN where the target step is 0
    key_points: np.ndarray  # (K, 3) the plan's key points
    key_kind: np.ndarray  # (K,)


def run_series(block: CurveBlock, plan: Plan, result: Interpolation) -> RunSeries:
    """The series of the paper's figures 9-13 for one curve and one interpolator."""
    curve = plan.curve
    cap = np.minimum(plan.limits.feed_mm_s, feed_at(result.u, block.feed_u, block.feed_mm_s))
    kappa = curvature_1_mm(curve, result.u)
    v = result.v_mm_s
    chord = np.linalg.norm(np.diff(result.points, axis=0), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ff = np.where(result.ds_mm > 0.0, np.abs(chord - result.ds_mm) / result.ds_mm, np.nan)
    err = chord_errors_mm(curve, result.u[:-1], result.u[1:], result.points[:-1],
                          result.points[1:])
    return RunSeries(result.t_s, 0.5 * (result.t_s[:-1] + result.t_s[1:]), v, cap,
                     chord / result.period_s, result.a_mm_s2, v**2 * kappa,
                     np.asarray(result.j_mm_s3, dtype=float), v**3 * kappa**2, err, 100.0 * ff,
                     curve.point(plan.key_u), np.asarray(plan.key_kind))


def curve_run(path: Path, machine: Machine, method: str, dialect: str,
              index: int) -> tuple[CurveBlock, Plan, Interpolation]:
    """Plan and interpolate curve `index` (from 0, in file order) of `path`: what `plot` draws."""
    blocks = curve_blocks(path, dialect)
    if index >= len(blocks):
        raise InputError(f"there is no curve {index}: the input has {len(blocks)} NURBS curve(s), "
                         "numbered from 0", Location(str(path)))
    block = blocks[index]
    plan = plan_block(block, machine)
    if plan.n_periods == 0:
        raise InputError(f"curve {index} ({block.curve.name}) has zero length: nothing to plot",
                         block.location)
    return block, plan, interpolate(plan, method)
