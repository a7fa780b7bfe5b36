"""Chains against the whole curve (issue 29), printed as a table. Run from the repository root:

    python -m tests.bench.chains                 # butterfly and circle, 4 to 20 blocks
    python -m tests.bench.chains --draws 11      # and the planner's own noise, 11 draws
    python -m tests.bench.chains --windows 1600  # what a long chain's window rests cost

Each benchmark curve is cut at its knots by knot insertion (tests/cut_curves.py: the very same
path) into N consecutive G06.2 blocks (Fanuc) and G6.2 blocks with a zero-length G1 between each
two (LinuxCNC), converted under each profile, and the cycle compared with the whole curve's,
converted the same way. --draws adds the spread of the whole curve's cycle when its control
points are multiplied by 1 +- 1e-15 (seeded): what the planner itself does with a change far
below any that a chain makes (docs/design.md §3b). Measured here, asserted in tests/test_chains.py.

--windows N converts the benchmark's chained program of N curves (tests/bench/programs.py) as
the conversion does, in windows that each end at rest (chains.MAX_WINDOW_CURVES and
MAX_WINDOW_NODES), and as one window of all of it (no rest inside, memory growing with the
chain): the cycle the window rests cost, and each one's peak RSS (a child process each).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import Machine, load_machine
from nurbsfeed.pipeline import convert_file, verified_plan
from tests.bench.programs import chained_program
from tests.cut_curves import cut, cuts_for, gcode_chain

ROOT = Path(__file__).resolve().parents[2]
CURVES = ("butterfly.json", "circle.json")
BLOCKS = (4, 8, 12, 16, 20)
PROFILES = (("default", {}), ("default", {"planner": "scurve"}), ("paper-table1", {}))
FEED_PER_MIN = 12000.0


def _cycle(folder: Path, text: str, machine: Machine) -> float:
    source = folder / "chain.nc"
    source.write_text(text)
    return convert_file(source, folder / "chain.out", machine).cycle_time_s


def _noise(curve: dict, machine: Machine, draws: int) -> tuple[float, float]:
    """The lowest and highest cycle of the whole curve, planned, over `draws` perturbations."""
    whole = NurbsCurve.build(curve["degree"], curve["knots"], curve["control_points"],
                             curve.get("weights"))
    rng = np.random.default_rng(1)
    empty = np.empty(0)
    cycles = []
    for _ in range(draws):
        points = whole.points * (1.0 + rng.uniform(-1e-15, 1e-15, whole.points.shape))
        moved = NurbsCurve(whole.degree, whole.knots, points, whole.weights)
        cycles.append(verified_plan(moved, machine.limits, empty, empty).cycle_time_s)
    return min(cycles), max(cycles)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=0,
                        help="perturbations of the whole curve (default: none)")
    parser.add_argument("--windows", type=int, default=0,
                        help="curves of a chained program: its window rests' cost (only that)")
    args = parser.parse_args()
    if args.windows:
        _window_rests(args.windows)
        return
    header = " | ".join(f"{n} blocks" for n in BLOCKS)
    print(f"| curve | profile | whole s | {header} | whole, perturbed |")
    print("|" + " --- |" * (len(BLOCKS) + 4))
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        for name in CURVES:
            data = json.loads((ROOT / "samples" / name).read_text())["curves"][0]
            weights = data.get("weights", [1.0] * len(data["control_points"]))
            degree, knots, points = data["degree"], data["knots"], data["control_points"]
            whole = cut(degree, knots, points, weights, [])
            for profile, overrides in PROFILES:
                machine = load_machine(profile, overrides)
                label = profile + "".join(f", {k} {v}" for k, v in overrides.items())
                base = _cycle(folder, gcode_chain(whole, FEED_PER_MIN), machine)
                cells = []
                for n in BLOCKS:
                    pieces = cut(degree, knots, points, weights, cuts_for(knots, degree, n))
                    zero = [[f"G1 X{p.points[0][0]:.9f} Y{p.points[0][1]:.9f}"]
                            for p in pieces[1:]]
                    fanuc = _cycle(folder, gcode_chain(pieces, FEED_PER_MIN), machine)
                    lcnc = _cycle(folder, gcode_chain(pieces, FEED_PER_MIN, "linuxcnc", zero),
                                  machine)
                    cells.append(f"{fanuc / base:.4f} / {lcnc / base:.4f}")
                spread = ""
                if args.draws:
                    low, high = _noise(data, machine, args.draws)
                    spread = f"{low / base:.4f} ... {high / base:.4f}"
                print(f"| {name} | {label} | {base:.3f} | {' | '.join(cells)} | {spread} |",
                      flush=True)
    print()
    print("Each cell: chain cycle / whole cycle, Fanuc G06.2 blocks / LinuxCNC G6.2 blocks with "
          "a zero-length G1 between.")


# a child converts the program and prints its cycle, windows and peak RSS (MB)
_CHILD = """
import resource, sys
from pathlib import Path
import nurbsfeed.chains as chains
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file
if sys.argv[3] == "one":
    chains.MAX_WINDOW_CURVES = chains.MAX_WINDOW_NODES = 10**12
report = convert_file(Path(sys.argv[1]), Path(sys.argv[2]), load_machine("default"))
windows = Path(sys.argv[2]).read_text().count("chained, line")
print(report.cycle_time_s, windows, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
"""


def _window_rests(n_curves: int) -> None:
    with tempfile.TemporaryDirectory() as scratch:
        source = Path(scratch) / "chain.nc"
        source.write_text(chained_program(n_curves))
        rows = {}
        for mode in ("windows", "one"):
            out = subprocess.run([sys.executable, "-c", _CHILD, str(source),
                                  str(Path(scratch) / f"{mode}.nc"), mode],
                                 capture_output=True, text=True, check=True, cwd=ROOT)
            cycle, windows, rss = out.stdout.split()
            rows[mode] = (float(cycle), int(windows), float(rss))
    base = rows["one"][0]
    print(f"| {n_curves} chained curves | cycle s | windows (rests inside) | over one window "
          "| peak RSS MB |")
    print("| --- | --- | --- | --- | --- |")
    for mode, label in (("windows", "in windows (the conversion)"), ("one", "one window")):
        cycle, windows, rss = rows[mode]
        print(f"| {label} | {cycle:.3f} | {windows} ({windows - 1}) | {cycle / base:.4f} "
              f"| {rss:.0f} |")


if __name__ == "__main__":
    main()
