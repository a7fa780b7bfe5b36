"""Per curve: the planning grid and the path model's features, printed as a table. Run from the
repository root:

    python -m tests.bench.geometry               # the 650 curves of fanuc_program(650)
    python -m tests.bench.geometry --curves 100 --runs 5

Each curve of the benchmark program (tests/bench/programs.py, read as a conversion reads it, in
mm) goes through what the planner runs on it before its linear programs, called as the planner
calls them: `grid.build_grid`, then under the default profile (path model) `least_cycle_s`,
`limits.speed_limit`, `path_limit` and `axis_capped`, and the two the layout of cells calls
for each cell, `arc_parameters` (at each grid interval's middle) and `cells.point_geometry` (at
the nodes and those middles); under paper-table1, `build_grid` and `speed_limit`. Each row is the
process's CPU time per curve, the least of --runs passes over all curves (the machine is shared:
the least is the steadiest), after a pass that loads the compiled kernels. The curves run one
after another, each function on all of them in turn: the caches are warmer than between the
planner's programs, so a conversion spends more on each (about twice as much on build_grid).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.machine import load_machine
from nurbsfeed.planning.cells import point_geometry
from nurbsfeed.planning.grid import build_grid
from nurbsfeed.planning.limits import curvature_threshold, speed_limit
from nurbsfeed.planning.path_check import (
    arc_parameters,
    axis_capped,
    least_cycle_s,
    path_limit,
)
from nurbsfeed.planning.plan import feed_at, grid_spacing
from tests.bench.programs import fanuc_program


def cpu_ms_per_curve(run: Callable[[int], object], n: int, runs: int) -> float:
    """The least, over runs passes (after one more), of the CPU time of run(i) for every curve
    i < n, per curve, in ms."""
    best = np.inf
    for _ in range(runs + 1):
        start = time.process_time()
        for i in range(n):
            run(i)
        best = min(best, time.process_time() - start)
    return 1e3 * best / n


def table(profile: str, blocks: list, runs: int) -> tuple[float, list[tuple[str, float]]]:
    """The mean grid's nodes, and per function its ms per curve."""
    lim = load_machine(profile).limits
    kappa0 = curvature_threshold(lim)
    n = len(blocks)

    def grid_of(i: int):
        b = blocks[i]
        feed_breaks = b.feed_u[1:] if b.feed_u.size else b.feed_u
        return build_grid(b.curve, grid_spacing(b.curve, lim), feed_breaks, kappa0)

    grids = [grid_of(i) for i in range(n)]
    fcap = [feed_at(g.u, b.feed_u, b.feed_mm_s) for g, b in zip(grids, blocks)]
    caps = [speed_limit(g.kappa_1_mm, lim, f) for g, f in zip(grids, fcap)]
    rows = [("build_grid", cpu_ms_per_curve(grid_of, n, runs)),
            ("speed_limit", cpu_ms_per_curve(
                lambda i: speed_limit(grids[i].kappa_1_mm, lim, fcap[i]), n, runs))]
    nodes = float(np.mean([g.u.size for g in grids]))
    if lim.jerk_model != "path":
        return nodes, rows
    curve = [b.curve for b in blocks]
    middles = [0.5 * (g.s_mm[1:] + g.s_mm[:-1]) for g in grids]
    points = [np.concatenate((g.u, arc_parameters(c, g, m)))
              for c, g, m in zip(curve, grids, middles)]
    rows += [
        ("least_cycle_s", cpu_ms_per_curve(
            lambda i: least_cycle_s(curve[i], grids[i], lim, fcap[i]), n, runs)),
        ("path_limit", cpu_ms_per_curve(
            lambda i: path_limit(curve[i], grids[i], lim, caps[i]), n, runs)),
        ("axis_capped", cpu_ms_per_curve(
            lambda i: axis_capped(curve[i], grids[i], lim, caps[i]), n, runs)),
        ("arc_parameters", cpu_ms_per_curve(
            lambda i: arc_parameters(curve[i], grids[i], middles[i]), n, runs)),
        ("point_geometry", cpu_ms_per_curve(
            lambda i: point_geometry(curve[i], lim, points[i], feed_at(
                points[i], blocks[i].feed_u, blocks[i].feed_mm_s),
                np.full(points[i].size, -1)), n, runs)),
    ]
    return nodes, rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--curves", type=int, default=650)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        program = Path(folder) / "bench.nc"
        program.write_text(fanuc_program(args.curves))
        blocks = curve_blocks(program)
    print(f"{len(blocks)} curves, CPU ms per curve, least of {args.runs} runs")
    for profile in ("default", "paper-table1"):
        nodes, rows = table(profile, blocks, args.runs)
        print(f"\n{profile} ({nodes:.0f} grid nodes a curve)")
        print(f"{'':16s} {'ms/curve':>9s}")
        for name, ms in rows:
            print(f"{name:16s} {ms:9.4f}")
        print(f"{'total':16s} {sum(ms for _, ms in rows):9.4f}")


if __name__ == "__main__":
    main()
