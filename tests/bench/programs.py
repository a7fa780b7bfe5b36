"""Synthetic shop programs for the benchmarks: many smooth cubic NURBS curves, chained.

Each curve is a clamped cubic through a random walk of control points (seeded), starting where
the previous one ended, so the programs look like a CAM finishing pass: hundreds of curves of
tens of mm, rational weights, a few G0 moves between groups.
"""

from __future__ import annotations

import json

import numpy as np


def random_curves(n_curves: int, seed: int = 1, n_ctrl: int = 24) -> list[dict]:
    rng = np.random.default_rng(seed)
    curves = []
    start = np.zeros(3)
    for i in range(n_curves):
        steps = rng.normal(0.0, 6.0, (n_ctrl - 1, 3)) * [1.0, 1.0, 0.1]
        pts = np.vstack([start, start + np.cumsum(steps, axis=0)])
        inner = np.sort(rng.uniform(0.0, 1.0, n_ctrl - 4))
        knots = np.concatenate([np.zeros(4), inner, np.ones(4)])
        weights = rng.uniform(0.8, 1.25, n_ctrl)
        weights[0] = weights[-1] = 1.0
        curves.append({"name": f"c{i}", "degree": 3, "knots": knots.round(6).tolist(),
                       "control_points": pts.round(4).tolist(),
                       "weights": weights.round(4).tolist()})
        start = pts[-1].round(4)
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
