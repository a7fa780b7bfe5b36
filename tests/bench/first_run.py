"""The first conversion after an install: what it compiles and how long it takes (issue 30).

    python -m tests.bench.first_run            # the butterfly under the default profile
    python -m tests.bench.first_run samples/circle.json -m paper-table1

Runs `nurbsfeed convert` in a new process with an empty numba cache (NUMBA_CACHE_DIR in a
temporary directory, so the in-tree cache is left alone), then again with the cache it filled,
and prints the wall and CPU time of both and the load before them (on a shared machine the CPU
time is the steadier), every kernel the first run compiled with its compile time (its own,
callees excluded, from numba's event API) and any kernel compiled for more than one signature.
nurbsfeed.jit.FIRST_COMPILE_S, which the compile notice quotes, comes from this measurement.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# Runs inside the measured process: times every compilation (outermost ones include their
# callees; the time of each kernel alone is its own minus its callees'), then converts.
PROBE = """
import json, sys, time
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
from nurbsfeed.cli import main
try:
    main(sys.argv[1:])
except SystemExit as exc:
    assert not exc.code, exc.code
signatures = {f"{name}.{attr}": [str(sig) for sig in kernel.signatures]
              for name, module in list(sys.modules.items()) if name.startswith("nurbsfeed")
              for attr, kernel in vars(module).items()
              if isinstance(kernel, CPUDispatcher) and kernel.signatures}
print(json.dumps({"own_s": own, "signatures": signatures}))
"""


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def convert(args: list[str], cache: str) -> tuple[float, float, dict[str, object]]:
    """Wall and CPU time of a conversion in a new process, and what the probe saw. The CPU time
    is the steadier of the two on a shared machine (another process's load stretches the wall
    time, not this one's CPU time, on a machine with a core to spare)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    env.pop("NURBSFEED_NO_JIT", None)
    start, start_cpu = time.perf_counter(), _children_cpu_s()
    done = subprocess.run([sys.executable, "-c", PROBE, "convert", *args, "-q"], env=env,
                          capture_output=True, text=True, check=True)
    return (time.perf_counter() - start, _children_cpu_s() - start_cpu,
            json.loads(done.stdout.splitlines()[-1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("input", nargs="?", default="samples/butterfly.json")
    parser.add_argument("-m", "--machine", default="default")
    parser.add_argument("--top", type=int, default=25, help="kernels listed (slowest first)")
    options = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        args = [options.input, "-m", options.machine, "-o", str(Path(tmp) / "out.nc")]
        cache = str(Path(tmp) / "numba-cache")
        load = os.getloadavg()[0]
        cold_s, cold_cpu_s, cold = convert(args, cache)
        warm_s, warm_cpu_s, _ = convert(args, cache)
    own: dict[str, float] = cold["own_s"]  # type: ignore[assignment]
    ours = {name: t for name, t in own.items() if name.startswith("nurbsfeed.")}
    print(f"first run (empty cache): {cold_s:6.1f} s wall, {cold_cpu_s:5.1f} s CPU")
    print(f"second run (cache)     : {warm_s:6.1f} s wall, {warm_cpu_s:5.1f} s CPU")
    print(f"load before the runs   : {load:.2f} (1-minute average, {os.cpu_count()} cores)")
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
    signatures: dict[str, list[str]] = cold["signatures"]  # type: ignore[assignment]
    twice = {name: sigs for name, sigs in signatures.items() if len(sigs) > 1}
    print(f"kernels with more than one signature: {len(twice)}")
    for name, sigs in sorted(twice.items()):
        print(f"  {name}: {len(sigs)}")


if __name__ == "__main__":
    main()
