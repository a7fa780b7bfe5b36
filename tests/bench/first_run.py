"""The first conversion after an install: what it compiles, how long it takes (issue 30) and
how much memory it takes (issue 28).

    python -m tests.bench.first_run            # the butterfly under the default profile
    python -m tests.bench.first_run samples/circle.json -m paper-table1
    python -m tests.bench.first_run --in-process   # every kernel compiled in the process

Runs `nurbsfeed convert` in a new process with an empty numba cache (NUMBA_CACHE_DIR in a
temporary directory, so the in-tree cache is left alone), as the console script runs it (its
kernels compiled in child processes, nurbsfeed.jit.compile_in_children), then again with the
cache it filled, and prints the wall time, CPU time and peak RSS of both (CPU time and peak
over the process and its children, from os.wait4: a run's children run one at a time, so the
largest of them is the run's peak, as /usr/bin/time -v reports it) and the load before them (on
a shared machine the CPU time is the steadier); then every kernel the converting process itself
compiled, with its compile time (its own, callees excluded, from numba's event API), and any
kernel compiled for more than one signature. --in-process compiles every kernel in the
converting process, as before issue 28, for the time of each (and its peak RSS).
nurbsfeed.jit.FIRST_COMPILE_S, which the compile notice quotes, comes from this measurement.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# Runs inside the measured process: times every compilation (outermost ones include their
# callees; the time of each kernel alone is its own minus its callees'), then converts as the
# console script does (`run`), or with `main` (no compile children) after --in-process.
PROBE = """
import json, resource, sys, time
from numba.core import event
from numba.core.registry import CPUDispatcher

stack, own = [], {}

class Timer(event.Listener):
    def on_start(self, ev):
        stack.append([time.perf_counter(), 0.0])

    def on_end(self, ev):
        start, callees = stack.pop()
        spent = time.perf_counter() - start
        func = ev.data["dispatcher"].py_func
        name = f"{func.__module__}.{func.__qualname__}"
        own[name] = own.get(name, 0.0) + spent - callees
        if stack:
            stack[-1][1] += spent

event.register("numba:compile", Timer())
from nurbsfeed.cli import main, run
in_process = sys.argv.pop(1) == "in-process"
sys.argv[0] = "nurbsfeed"
try:
    main(sys.argv[1:]) if in_process else run()
except SystemExit as exc:
    assert not exc.code, exc.code
signatures = {f"{name}.{attr}": [str(sig) for sig in kernel.signatures]
              for name, module in list(sys.modules.items()) if name.startswith("nurbsfeed")
              for attr, kernel in vars(module).items()
              if isinstance(kernel, CPUDispatcher) and kernel.signatures}
children = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"own_s": own, "signatures": signatures,
                  "own_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "children_mb": children.ru_maxrss / 1024,
                  "children_cpu_s": children.ru_utime + children.ru_stime}))
"""


@dataclass(frozen=True)
class Run:
    """One measured conversion: wall and CPU time, peak RSS (of the process and its children,
    the largest of them), and what the probe saw (its compile times, its own peak and its
    children's)."""

    wall_s: float
    cpu_s: float
    peak_mb: float
    probe: dict[str, Any]

    def line(self) -> str:
        return (f"{self.wall_s:6.1f} s wall, {self.cpu_s:5.1f} s CPU, peak RSS "
                f"{self.peak_mb:4.0f} MB")


def convert(args: list[str], cache: str, in_process: bool = False) -> Run:
    """A conversion in a new process. The CPU time is the steadier of the two on a shared
    machine (another process's load stretches the wall time, not this one's CPU time, on a
    machine with a core to spare)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    env.pop("NURBSFEED_NO_JIT", None)
    start = time.perf_counter()
    mode = "in-process" if in_process else "console"
    with subprocess.Popen([sys.executable, "-c", PROBE, mode, "convert", *args, "-q"],
                          env=env, stdout=subprocess.PIPE, text=True) as child:
        assert child.stdout is not None
        out = child.stdout.read()
        # wait4: this run's own usage, its children's included (RUSAGE_CHILDREN would give
        # the largest peak of every process waited for so far, the first run's in the second)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode:
        raise SystemExit(f"the conversion failed (exit {child.returncode})")
    return Run(time.perf_counter() - start, usage.ru_utime + usage.ru_stime,
               usage.ru_maxrss / 1024, json.loads(out.splitlines()[-1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("input", nargs="?", default="samples/butterfly.json")
    parser.add_argument("-m", "--machine", default="default")
    parser.add_argument("--top", type=int, default=25, help="kernels listed (slowest first)")
    parser.add_argument("--in-process", action="store_true",
                        help="compile every kernel in the converting process, not in children")
    options = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        args = [options.input, "-m", options.machine, "-o", str(Path(tmp) / "out.nc")]
        cache = str(Path(tmp) / "numba-cache")
        load = os.getloadavg()[0]
        cold = convert(args, cache, options.in_process)
        warm = convert(args, cache)
    print(f"first run (empty cache): {cold.line()}")
    print(f"second run (cache)     : {warm.line()}")
    print(f"load before the runs   : {load:.2f} (1-minute average, {os.cpu_count()} cores)")
    own: dict[str, float] = cold.probe["own_s"]
    ours = {name: t for name, t in own.items() if name.startswith("nurbsfeed.")}
    if not options.in_process:
        print(f"first run: the converting process peaked at {cold.probe['own_mb']:.0f} MB and "
              f"compiled {len(ours)} kernel(s) itself ({', '.join(sorted(ours))}); its compile "
              f"children, one at a time, at {cold.probe['children_mb']:.0f} MB at most, "
              f"{cold.probe['children_cpu_s']:.1f} s CPU in all (--in-process: every kernel's "
              "compile time, in a process that compiles them all)")
        return
    print(f"compiling: {sum(own.values()):.1f} s, {len(ours)} nurbsfeed kernels "
          f"{sum(ours.values()):.1f} s, numba's own implementations (numpy functions...) "
          f"{sum(own.values()) - sum(ours.values()):.1f} s")
    by_folder: dict[str, float] = {}
    for name, spent in ours.items():
        folder = ".".join(name.split(".")[:2])
        by_folder[folder] = by_folder.get(folder, 0.0) + spent
    for folder, spent in sorted(by_folder.items(), key=lambda item: -item[1]):
        print(f"  {spent:6.2f} s  {folder}")
    print(f"slowest kernels to compile (own time, callees excluded), top {options.top}:")
    for name, spent in sorted(ours.items(), key=lambda item: -item[1])[:options.top]:
        print(f"  {spent:6.2f} s  {name}")
    signatures: dict[str, list[str]] = cold.probe["signatures"]
    twice = {name: sigs for name, sigs in signatures.items() if len(sigs) > 1}
    print(f"kernels with more than one signature: {len(twice)}")
    for name, sigs in sorted(twice.items()):
        print(f"  {name}: {len(sigs)}")


if __name__ == "__main__":
    main()
