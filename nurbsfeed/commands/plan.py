"""`nurbsfeed plan`: each curve's plan as a report (key points, speeds, segments or stretches,
a chain's joints, the cycle against the time-optimal bound) and, with --reference, the
jerk-limited reference schedule (analysis.bound, scipy).
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from nurbsfeed.commands.common import (
    dialect_option,
    epilog,
    machine_from,
    machine_options,
    reports_errors,
)
from nurbsfeed.commands.warm_up import hand_off, profile_options, warm_up
from nurbsfeed.errors import EXIT_BAD_INPUT

if TYPE_CHECKING:
    import numpy as np

    from nurbsfeed.machine import Machine
    from nurbsfeed.planning.chain import Joints
    from nurbsfeed.planning.plan import PathDiagnostics, Plan, SCurveDiagnostics
    from nurbsfeed.program import CurveBlock

REFERENCE_NEEDS_SCIPY = ("nurbsfeed plan --reference needs scipy: "
                         "pip install 'nurbsfeed[reference]'")


@click.command(epilog=epilog(
    "  nurbsfeed plan samples/butterfly.json -m paper-table1"))
@click.argument("input", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--reference", is_flag=True,
              help="Also find a jerk-limited schedule under the same limits, by its own code "
                   "(sequential linear programming), and compare (seconds to minutes a curve).")
@machine_options
@dialect_option
@reports_errors
def plan(input: Path, dialect: str, reference: bool, **kwargs: Any) -> None:
    """Key points, nominal and scanned speeds, segments and cycle time of every curve; a chain
    of curves that join (planned as one) lists its joints: turn, curvature jump and speed."""
    from nurbsfeed.analysis import time_optimal_bound_s
    from nurbsfeed.chains import ChainWindow, chain_items
    from nurbsfeed.pipeline import chain_block, joint_speeds, plan_block
    from nurbsfeed.planning.plan import KIND_NAMES, SCurveDiagnostics
    from nurbsfeed.readers import read_program

    if reference:
        try:
            importlib.import_module("nurbsfeed.analysis.bound.solve")  # scipy, an extra
        except ImportError:
            click.echo(REFERENCE_NEEDS_SCIPY, err=True)
            sys.exit(EXIT_BAD_INPUT)
    hand_off(warm_up("plan", profile_options(kwargs)))
    machine = machine_from(kwargs)
    index = 0
    for window in chain_items(read_program(input, dialect), machine):
        if not isinstance(window, ChainWindow):
            continue
        item, chain, found = chain_block(window, machine.limits)
        p = plan_block(item, machine)
        lim = p.limits
        unit = "mm"  # an inch program's too: every report is in the profile's unit
        n_curves = len(window.blocks)
        if n_curves == 1:
            click.echo(f"curve {index} {item.curve.name} ({item.location})")
        else:
            click.echo(f"curves {index}-{index + n_curves - 1}, a chain planned as one curve "
                       f"({item.location}; u below is the chain's, 0 to 1)")
        click.echo(f"  degree {item.curve.degree}, {item.curve.n_ctrl} control points, "
                   f"length {p.length_mm:.6f} {unit}")
        d = p.diagnostics
        if isinstance(d, SCurveDiagnostics):
            keys = f"{len(p.key_node)} key points after {d.fix_rounds} limit-fix rounds"
            nominal, scanned = d.key_nominal_mm_s.tolist(), d.key_v_mm_s.tolist()
        else:  # the path planner's keys are its rests: speed 0
            keys = f"{len(p.key_node)} rests (the {p.planner} planner's keys)"
            nominal = scanned = [0.0] * len(p.key_node)
        click.echo(f"  kappa0 {d.kappa0_1_mm:.6g} 1/{unit}; {d.n_peaks_above_threshold} "
                   f"curvature peaks >= kappa0; {keys}")
        click.echo(f"  {'#':>3} {'kind':<6} {'u':>12} {'s':>12} {'kappa':>12} "
                   f"{'nominal':>10} {'scanned':>10}")
        for k, node in enumerate(p.key_node):
            click.echo(f"  {k:>3} {KIND_NAMES[int(p.key_kind[k])]:<6} "
                       f"{item.curve.input_u(p.grid.u[node]):>12.8f} "
                       f"{p.grid.s_mm[node]:>12.6f} {p.grid.kappa_1_mm[node]:>12.6g} "
                       f"{nominal[k]:>10.4f} {scanned[k]:>10.4f}")
        if isinstance(d, SCurveDiagnostics):
            _echo_segments(p, d, unit)
        else:
            _echo_stretches(p, d, unit)
        if n_curves > 1:
            _echo_joints(index, found, joint_speeds(p, chain), unit)
        bound = time_optimal_bound_s(p, item)
        click.echo(f"  cycle time {p.cycle_time_s:.3f} s ({p.n_periods} periods of "
                   f"{lim.period_s * 1e3:g} ms; time scale {p.time_scale:.9f})")
        click.echo(f"  time-optimal bound {bound:.3f} s (acceleration-limited, no jerk limit): "
                   f"planned is {100 * (p.cycle_time_s / bound - 1):+.1f}%" if bound > 0 else
                   "  time-optimal bound 0 s (zero length)")
        if reference and bound > 0:
            click.echo(_reference_line(item, machine, p.cycle_time_s, bound))
        if window.ahead:
            click.echo("  a window of a longer chain, planned here to rest at its cut: the "
                       "conversion runs on into the next window from its last point before "
                       f"the joint after curve {index + n_curves - 1} (docs/design.md §3b)")
        index += n_curves
    if index == 0:
        click.echo("no NURBS curves in the input")


def _echo_joints(first: int, found: Joints, speed_mm_s: np.ndarray, unit: str) -> None:
    """A chain's joints (design §3b): where, how far the tangent turns, the jump of the
    curvature vector, the cap the period rule sets (a corner rests: 0) and the speed the
    stepped points cross at."""
    import numpy as np

    click.echo(f"  joints ({unit}, {unit}/s; speed from the stepped points across the joint):")
    click.echo(f"  {'#':>3} {'curves':>11} {'u':>12} {'turn_deg':>10} {'dkappa':>12} "
               f"{'cap':>10} {'speed':>10}")
    for j in range(found.u.size):
        curves = f"{first + j}|{first + j + 1}"
        cap = "-" if np.isinf(found.cap_mm_s[j]) else f"{found.cap_mm_s[j]:.4f}"
        click.echo(f"  {j:>3} {curves:>11} {found.u[j]:>12.8f} "
                   f"{np.degrees(found.turn_rad[j]):>10.6f} {found.kappa_jump_1_mm[j]:>12.6g} "
                   f"{cap:>10} {speed_mm_s[j]:>10.4f}")


def _echo_segments(p: Plan, d: SCurveDiagnostics, unit: str) -> None:
    """The S-curve plan's segments between key points."""
    from nurbsfeed.planning.scurve import transition_distance_mm

    a, j = d.acc_mm_s2, d.jerk_mm_s3
    click.echo(f"  segments ({unit}, {unit}/s):")
    click.echo(f"  {'#':>3} {'length':>12} {'v_start':>10} {'v_peak':>10} {'v_end':>10} "
               f"{'hold_in':>9} {'hold_out':>9} {'cruise':>10}")
    key_s = p.key_s_mm
    for i in range(len(p.key_node) - 1):
        length = key_s[i + 1] - key_s[i]
        vs, ve, vp = d.key_v_mm_s[i], d.key_v_mm_s[i + 1], d.seg_peak_mm_s[i]
        cruise = (length - d.seg_hold_start_mm[i] - d.seg_hold_end_mm[i]
                  - transition_distance_mm(vs, vp, a, j) - transition_distance_mm(vp, ve, a, j))
        click.echo(f"  {i:>3} {length:>12.6f} {vs:>10.4f} {vp:>10.4f} {ve:>10.4f} "
                   f"{d.seg_hold_start_mm[i]:>9.4f} {d.seg_hold_end_mm[i]:>9.4f} "
                   f"{max(cruise, 0.0):>10.4f}")


def _echo_stretches(p: Plan, d: PathDiagnostics, unit: str) -> None:
    """The stretches between rests of the path planner's plan, whose keys are the rests alone,
    and the passes over their sets that found it."""
    click.echo(f"  {p.planner} schedule: {d.passes} passes over its sets, uniform slowdown "
               f"{p.uniform_slowdown:.4f}; stretches between rests ({unit}, {unit}/s):")
    click.echo(f"  {'#':>3} {'length':>12} {'v_peak':>10} {'periods':>10}")
    key_s = p.key_s_mm
    for i in range(len(p.key_node) - 1):
        click.echo(f"  {i:>3} {key_s[i + 1] - key_s[i]:>12.6f} {d.stretch_peak_mm_s[i]:>10.4f} "
                   f"{int(p.piece_periods[i]):>10}")


def _reference_line(block: CurveBlock, machine: Machine, cycle_s: float, bound_s: float
                    ) -> str:
    """`plan --reference`: the jerk-limited reference schedule's cycle and the plan's ratio."""
    from nurbsfeed.analysis.bound.solve import jerk_limited_schedule

    try:
        ref = jerk_limited_schedule(block.curve, machine.limits, block.feed_u, block.feed_mm_s)
    except (RuntimeError, ValueError) as exc:  # an LP HiGHS could not solve, NaN geometry
        return f"  jerk-limited reference: not found ({exc})"
    return (f"  jerk-limited reference {ref.cycle_s:.3f} s (keeps every limit; the optimum lies "
            f"between {bound_s:.3f} and {ref.cycle_s:.3f} s): planned is "
            f"{100 * (cycle_s / ref.cycle_s - 1):+.1f}%")


