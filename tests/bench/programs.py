"""Synthetic shop programs for the benchmarks: many butterfly-sized cubic NURBS curves, chained.

Each curve is a finishing-pass toolpath the way CAM fits it: 50 control points (the butterfly
has 51) 4-9 mm apart along a path whose heading turns gently (0.2 rad per control point, normal)
with a tight bend at one control point in three or four (another 1.2 rad, normal), a little
Z, rational weights, and knots averaged from the chord lengths (de Boor), so that |C'| is even
along the curve. Under the default machine at F6000 a curve is ~300 mm long, runs ~3,300
periods and has ~15 curvature peaks above kappa_0 (the tightest bends of radius ~0.4 mm) where the
feed drops and the limit-fixing rounds work. Each curve starts where the previous one ended
(seeded, reproducible).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

N_CTRL = 50
STEP_MM = (4.0, 9.0)  # control point spacing, uniform
TURN_RAD = 0.2  # heading change per control point, normal
BEND_SHARE = 0.3  # share of control points with a tight bend ...
BEND_RAD = 1.2  # ... of this much more heading change, normal
Z_STEP_MM = 0.1


def random_curves(n_curves: int, seed: int = 1, n_ctrl: int = N_CTRL) -> list[dict]:
    rng = np.random.default_rng(seed)
    curves = []
    start = np.zeros(3)
    heading = 0.0
    for i in range(n_curves):
        bends = rng.normal(0.0, TURN_RAD, n_ctrl - 1)
        bends += (rng.random(n_ctrl - 1) < BEND_SHARE) * rng.normal(0.0, BEND_RAD, n_ctrl - 1)
        headings = heading + np.cumsum(bends)
        steps = rng.uniform(*STEP_MM, n_ctrl - 1)
        moves = np.column_stack([steps * np.cos(headings), steps * np.sin(headings),
                                 rng.normal(0.0, Z_STEP_MM, n_ctrl - 1)])
        pts = np.vstack([start, start + np.cumsum(moves, axis=0)])
        chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(moves, axis=1))])
        t = chord / chord[-1]
        inner = [t[j:j + 3].mean() for j in range(1, n_ctrl - 3)]  # de Boor averaging
        knots = np.concatenate([np.zeros(4), inner, np.ones(4)])
        weights = rng.uniform(0.9, 1.1, n_ctrl)
        weights[0] = weights[-1] = 1.0
        curves.append({"name": f"c{i}", "degree": 3, "knots": knots.round(6).tolist(),
                       "control_points": pts.round(4).tolist(),
                       "weights": weights.round(4).tolist()})
        start = pts[-1].round(4)
        heading = float(headings[-1])
    return curves


def json_program(n_curves: int, seed: int = 1) -> str:
    return json.dumps({"units": "mm", "curves": random_curves(n_curves, seed)})


def fanuc_program(n_curves: int, seed: int = 1) -> str:
    """The same curves as a Fanuc G06.2 program (one curve after another, F6000)."""
    lines = ["%", "O1234 (BENCHMARK)", "G17 G21 G90 G94", "S12000 M3"]
    curves = random_curves(n_curves, seed)
    x0, y0, z0 = curves[0]["control_points"][0]
    lines.append(f"G0 X{x0:.4f} Y{y0:.4f} Z{z0:.4f}")
    for c in curves:
        pts, w, k = c["control_points"], c["weights"], c["knots"]
        for j, (p, wj) in enumerate(zip(pts, w)):
            head = "G06.2 P4 " if j == 0 else ""
            feed = " F6000." if j == 0 else ""
            lines.append(f"{head}K{k[j]:.6f} X{p[0]:.4f} Y{p[1]:.4f} Z{p[2]:.4f} R{wj:.4f}{feed}")
        lines += [f"K{kk:.6f}" for kk in k[len(pts):]]
        lines.append("G01")
    lines += ["M5", "M30", "%"]
    return "\n".join(lines) + "\n"


CHAIN_STEP_MM = 3.0  # control point spacing of the chained program's path
CHAIN_TURN_RAD = 0.05  # its heading change per control point, normal: gentle, no corner


def chained_program(n_curves: int, seed: int = 1) -> str:
    """One smooth path as n_curves G06.2 curves that join end to start, tangent and
    curvature-continuous (design §3b): the Bézier spans of a uniform cubic B-spline whose
    control points are CHAIN_STEP_MM apart along a gently turning heading, each span written as
    a curve of its own (4 control points, knots 0 and 1), with an N-numbered comment line
    between them. A chain the planner plans in windows, never stopping inside one."""
    rng = np.random.default_rng(seed)
    headings = np.cumsum(rng.normal(0.0, CHAIN_TURN_RAD, n_curves + 2))
    steps = CHAIN_STEP_MM * np.column_stack([np.cos(headings), np.sin(headings)])
    q = np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])  # (n_curves + 3, 2)
    q0, q1, q2, q3 = q[:-3], q[1:-2], q[2:-1], q[3:]
    # each span of a uniform cubic B-spline as a Bézier curve (its control points in closed
    # form); rounded once, the end of one span and the start of the next are the same text
    bez = np.stack([(q0 + 4 * q1 + q2) / 6, (2 * q1 + q2) / 3, (q1 + 2 * q2) / 3,
                    (q1 + 4 * q2 + q3) / 6], axis=1).round(6)
    bez[1:, 0] = bez[:-1, 3]
    lines = ["%", "O1235 (CHAINED BENCHMARK)", "G17 G21 G90 G94", "S12000 M3",
             f"G0 X{bez[0, 0, 0]:.6f} Y{bez[0, 0, 1]:.6f} Z0."]
    for i, span in enumerate(bez):
        if i:
            lines.append(f"N{i} (span {i})")
        for j, (x, y) in enumerate(span):
            head = "G06.2 P4 " if j == 0 else ""
            feed = " Z0. R1. F6000." if j == 0 else ""
            lines.append(f"{head}K0. X{x:.6f} Y{y:.6f}{feed}")
        lines += ["K1."] * 4
    lines += ["M5", "M30", "%"]
    return "\n".join(lines) + "\n"


def write_pass_through_program(path: Path, size_mb: int, n_curves: int = 3,
                               seed: int = 1) -> None:
    """A program of `size_mb` MB that is nearly all lines nurbsfeed passes through (G1 moves
    a straight-line post wrote), with `n_curves` of the G06.2 curves above spread through it:
    the reading path alone, at a size where holding the file would show in the peak RSS.
    Written in pieces, so that the generator holds none of it."""
    curve_program = fanuc_program(n_curves, seed).splitlines(keepends=True)
    head, tail = curve_program[:5], curve_program[-3:]
    starts = [c["control_points"][0] for c in random_curves(n_curves, seed)]
    curves = [f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f}\n{curve}G01\n" for (x, y, z), curve
              in zip(starts, "".join(curve_program[5:-3]).split("G01\n"))]
    rng = np.random.default_rng(seed)
    moves = "".join(f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f} F1200.\n"
                    for x, y, z in rng.uniform(-100.0, 100.0, (20_000, 3)))
    block_bytes = len(moves.encode("ascii"))
    n_blocks = max(1, size_mb * 1_000_000 // block_bytes)
    with path.open("w", encoding="ascii", newline="") as handle:
        handle.writelines(head)
        for i in range(n_blocks):
            handle.write(moves)
            if curves and (i + 1) * len(curves) // n_blocks > i * len(curves) // n_blocks:
                handle.write(curves.pop(0))
        handle.writelines(curves)
        handle.writelines(tail)
