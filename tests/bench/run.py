"""Benchmarks of nurbsfeed (issue 5), printed as a table. Run from the repository root:

    python -m tests.bench.run            # the full set
    python -m tests.bench.run --quick    # smaller programs, for a smoke run
    python -m tests.bench.run --sizes 100 --runs 3   # programs of these sizes, runs of each

1. Stepping kernels: microseconds per step for each method on the butterfly with paper-table1
   (the compiled kernel alone, median of repeated runs after a warm-up).
2. End to end: `nurbsfeed convert` on generated Fanuc G06.2 programs of hundreds of butterfly-sized
   curves (tests/bench/programs.py) under the default profile, the larger one again under
   its limits with the paper model (what the path model's planning costs), and a program of
   CHAINED_CURVES curves that join into one smooth path (planned as chains), pinned to one core,
   after a warm-up conversion that fills the numba cache; output points per second (start-up,
   reading, planning, interpolation and writing included) of the median of END_TO_END_RUNS runs
   with the range over all of them, its wall time, and the highest peak RSS of the children,
   for two program sizes (memory must not grow with the output).
3. Reading: `nurbsfeed convert` of a program of PASS_THROUGH_MB MB of lines it passes through
   and 3 curves (tests/bench/programs.py), once: its wall time and peak RSS, which must not grow
   with the input (the reader streams).
4. Cold start: `nurbsfeed convert` of a small sample with a warm numba cache (median of 5).
5. Phases: per curve of the samples and the butterfly under the default profile, in one
   process with a warm cache, the time to plan (`pipeline.plan_block`, the verification's look at
   its points included), to step (`interpolate.stepping.Stepping`) and to write (`MoveWriter`),
   side by side, median of PHASE_RUNS.
Speed is measured here, never asserted in the test suite.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from nurbsfeed.interpolate.kernels import METHODS, SLOW_SPEED_REL, step_spans
from nurbsfeed.machine import load_machine
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.readers.json_curves import read_json_curves
from tests.bench.programs import chained_program, fanuc_program, write_pass_through_program
from tests.conftest import default_paper_profile, law_increments

ROOT = Path(__file__).resolve().parents[2]
REPEATS = 30
END_TO_END_RUNS = 5  # the machine is shared: report the median and the range
PHASE_RUNS = 5
PHASE_SAMPLES = ("quarter-circle.json", "circle.json", "butterfly.json",
                 "fanuc-multi-curve.nc", "linuxcnc-nurbs-xy.ngc")
PASS_THROUGH_MB = 200
CHAINED_CURVES = 10_000


def kernel_us_per_step() -> dict[str, float]:
    _, [(curve, _)] = read_json_curves(ROOT / "samples" / "butterfly.json")
    plan = plan_curve(curve, load_machine("paper-table1").limits)
    law = plan.law
    t = np.arange(plan.n_periods + 1) * (law.duration_s / plan.n_periods)
    ds = law_increments(law, t)
    u = np.empty(ds.size + 1)
    pts = np.empty((ds.size + 1, 3))
    slow = SLOW_SPEED_REL * plan.length_mm / (curve.u_max - curve.u_min)
    result = {}
    for name, code in METHODS.items():
        args = (code, curve.knots, curve.span_polynomials, curve.degree, curve.n_ctrl,
                curve.u_min, ds, 1.0, slow, u, pts)
        step_spans(*args)  # compile / load from cache
        times = []
        for _ in range(REPEATS):
            start = time.perf_counter()
            step_spans(*args)
            times.append(time.perf_counter() - start)
        result[name] = statistics.median(times) / ds.size * 1e6
    return result


def _pin_to_one_core() -> None:
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def _child_env() -> dict[str, str]:
    """This environment, with Python's bytecode cache on: an installed package has its .pyc
    files (pip writes them), so a run should not compile nurbsfeed's sources each time even
    where PYTHONDONTWRITEBYTECODE is set (as in some CI images)."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def run_convert(args: list[str]) -> tuple[float, int]:
    """Wall seconds and peak RSS (KiB) of one `nurbsfeed convert` child process."""
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "nurbsfeed.cli", "convert", *args],
                            preexec_fn=_pin_to_one_core, stdout=subprocess.DEVNULL,
                            env=_child_env())
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"nurbsfeed convert {' '.join(args)} failed")
    return wall, usage.ru_maxrss


def phases() -> list[tuple[str, int, float, float, float]]:
    """Per curve of PHASE_SAMPLES under the default profile: name, points, and the median
    seconds to plan, to step and to write it."""
    from nurbsfeed.analysis.common import curve_blocks
    from nurbsfeed.gcode.writer import MoveWriter
    from nurbsfeed.interpolate.stepping import Stepping
    from nurbsfeed.pipeline import plan_block

    machine = load_machine("default")
    rows = []
    for name in PHASE_SAMPLES:
        for k, block in enumerate(curve_blocks(ROOT / "samples" / name)):
            times: list[tuple[float, float, float]] = []
            for _ in range(PHASE_RUNS + 1):  # the first fills the numba cache
                start = time.perf_counter()
                plan = plan_block(block, machine)
                planned = time.perf_counter()
                chunks = [chunk.points for chunk in Stepping(plan, "rk2c").chunks()]
                stepped = time.perf_counter()
                with open(os.devnull, "wb") as sink:
                    writer = MoveWriter(sink, machine.decimals, machine.feed_decimals,
                                        plan.limits.period_s, "\n", block.curve.points[0])
                    for points in chunks:
                        writer.add_points(points)
                    writer.end_curve()
                written = time.perf_counter()
                times.append((planned - start, stepped - planned, written - stepped))
            median = [statistics.median(t[i] for t in times[1:]) for i in range(3)]
            rows.append((f"{name} {k}" if k else name, plan.n_periods + 1, *median))
    return rows


def end_to_end(n_curves: int, folder: Path, profile: Path | None = None,
               runs: int = END_TO_END_RUNS, chained: bool = False) -> dict[str, float]:
    """END_TO_END_RUNS conversions of an n-curve program (numba cache warm) under the default
    profile or the one given: the median run, and the points per second of the slowest and the
    fastest. chained: the program is one smooth path cut into n curves that join
    (programs.chained_program), planned as chains."""
    src = folder / f"program-{n_curves}{'-chained' if chained else ''}.nc"
    src.write_text(chained_program(n_curves) if chained else fanuc_program(n_curves))
    out = folder / f"out-{n_curves}.nc"
    machine = ["-m", str(profile)] if profile else []
    done = sorted((run_convert([str(src), "-o", str(out), "-q", *machine])
                   for _ in range(runs)), key=lambda run: run[0])
    wall, rss_kib = done[len(done) // 2]
    points = 0
    with out.open() as handle:
        for line in handle:
            if line.startswith("(nurbsfeed: curve"):
                points += int(re.search(r", (\d+) points,", line).group(1))
    out_mb = out.stat().st_size / 1e6
    out.unlink()
    return {"curves": n_curves, "points": points, "wall_s": wall, "points_per_s": points / wall,
            "model": (" under the paper model" if profile else "")
            + (" chained, one smooth path" if chained else ""),
            "slowest": points / done[-1][0], "fastest": points / done[0][0],
            "rss_mb": max(run[1] for run in done) / 1024, "output_mb": out_mb, "runs": runs}


def warm_up(folder: Path) -> None:
    """Fill the numba cache for every kernel a conversion uses, so that no timed run compiles."""
    src = folder / "warm-up.nc"
    src.write_text(fanuc_program(3, seed=2))
    run_convert([str(src), "-o", str(folder / "warm-up-out.nc"), "-q"])


def pass_through(size_mb: int, folder: Path) -> dict[str, float]:
    """One conversion of a size_mb program that is nearly all pass-through lines."""
    src = folder / f"pass-through-{size_mb}.nc"
    write_pass_through_program(src, size_mb)
    out = folder / "pass-through-out.nc"
    wall, rss_kib = run_convert([str(src), "-o", str(out), "-q"])
    result = {"input_mb": src.stat().st_size / 1e6, "wall_s": wall, "rss_mb": rss_kib / 1024}
    src.unlink()
    out.unlink()
    return result


def cold_start(folder: Path) -> float:
    out = folder / "cold.nc"
    sample = str(ROOT / "samples" / "fanuc-quadratic.nc")
    run_convert([sample, "-o", str(out), "-q"])  # fills the numba cache
    return statistics.median(run_convert([sample, "-o", str(out), "-q"])[0] for _ in range(5))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small programs only")
    parser.add_argument("--sizes", type=int, nargs="+", help="curves of each program")
    parser.add_argument("--runs", type=int, default=END_TO_END_RUNS,
                        help="conversions of each program (the median is reported)")
    args = parser.parse_args()
    quick = args.quick
    sizes = tuple(args.sizes) if args.sizes else (50, 100) if quick else (325, 650)
    kernel = kernel_us_per_step()
    phase_rows = phases()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        warm_up(folder)
        runs = [end_to_end(n, folder, runs=args.runs) for n in sizes]
        # the default's limits under the paper model (the default profile before it moved to
        # the path model): what planning the path model costs
        paper = folder / "default-paper.yaml"
        paper.write_text(yaml.safe_dump(default_paper_profile()))
        runs.append(end_to_end(sizes[-1], folder, paper, args.runs))
        # a long chain: windows of look-ahead, memory bounded by the window, not the chain
        runs.append(end_to_end(CHAINED_CURVES // 10 if quick else CHAINED_CURVES, folder,
                               runs=args.runs, chained=True))
        reading = pass_through(PASS_THROUGH_MB // 10 if quick else PASS_THROUGH_MB, folder)
        cold = cold_start(folder)
    print("| benchmark | result |")
    print("| --- | --- |")
    for name, us in kernel.items():
        print(f"| kernel {name}, butterfly, paper-table1 | {us:.3f} us/step |")
    for r in runs:
        print(f"| convert {r['curves']} curves{r['model']}, {r['points']:,} points "
              f"({r['output_mb']:.0f} MB out) | {r['points_per_s'] / 1e6:.2f} M points/s "
              f"({r['slowest'] / 1e6:.2f}-{r['fastest'] / 1e6:.2f} over {r['runs']} runs), "
              f"{r['wall_s']:.2f} s, peak RSS {r['rss_mb']:.0f} MB |")
    print(f"| convert {reading['input_mb']:.0f} MB of pass-through lines and 3 curves | "
          f"{reading['wall_s']:.1f} s, peak RSS {reading['rss_mb']:.0f} MB |")
    print(f"| cold start, convert fanuc-quadratic.nc (warm cache) | {cold:.2f} s |")
    print()
    print("| curve, default profile | points | plan ms | step ms | write ms | plan us/point |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for name, points, plan_s, step_s, write_s in phase_rows:
        print(f"| {name} | {points:,} | {plan_s * 1e3:.1f} | {step_s * 1e3:.1f} | "
              f"{write_s * 1e3:.1f} | {plan_s / points * 1e6:.2f} |")


if __name__ == "__main__":
    main()
