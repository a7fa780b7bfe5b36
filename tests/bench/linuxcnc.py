"""How a LinuxCNC machine runs nurbsfeed's output (issue 14), printed as a table:

    python -m tests.bench.linuxcnc                         # every sample, 1000 and 5000 mm/s²
    python -m tests.bench.linuxcnc butterfly.json --acc 1000 --output default,decimals=6
    python -m tests.bench.linuxcnc butterfly.json --output default,planner=optimal
    python -m tests.bench.linuxcnc quarter-circle.json --traj ARC_BLEND_RAMP_FREQ=1000

Each sample is converted with an output variant: a built-in profile (the linuxcnc profile when
the variant names none) and overrides of its keys. It is run end
to end on the headless simulated mill of tests/linuxcnc/sim/ (1 ms servo period, 200 mm/s
per axis, the acceleration per axis under test) and its commanded positions recorded every
servo period (tests/linuxcnc/run_sim.py). Per curve: measured / planned cycle (the machine's
time between the ends of the first and the second-to-last move over the planned time; 1 = the
planned feed) and the largest distance of a recorded position from the exact curve
(tests/linuxcnc/measure.py), and the servo periods in which the machine stood still mid-curve
(its queue ran empty: LinuxCNC's task fills it in real time, and on a busy computer falls
behind), and the rest-to-rest ratio (the whole curve, first and last move included, to a
servo period). `--traj` adds INI [TRAJ] settings to the machine. Needs LinuxCNC
(linuxcnc-uspace); as root, the user 'lcnc'.
Measured here, never asserted in the test suite (a loaded machine can starve LinuxCNC's queue).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from nurbsfeed.machine import INT_KEYS
from tests.linuxcnc.measure import MeasurementError, measure
from tests.linuxcnc.programs import LINUXCNC_PROFILE, convert_for_linuxcnc, samples
from tests.linuxcnc.run_sim import (
    ACCELERATIONS_MM_S2,
    SimulationError,
    simulate,
    unavailable_reason,
)

DEFAULT_OUTPUTS = (LINUXCNC_PROFILE, "default")


def output_variant(spec: str) -> tuple[str, dict[str, float | int | str]]:
    """'default,decimals=6,planner=optimal' -> ('default', {'decimals': 6, 'planner':
    'optimal'}): an item without '=' names the profile (linuxcnc when none does), the others
    override it (jerk_model and planner by name, the rest numbers)."""
    profile = LINUXCNC_PROFILE
    overrides: dict[str, float | int | str] = {}
    for item in filter(None, spec.split(",")):
        key, equals, value = item.partition("=")
        if not equals:
            profile = key
        elif key in ("jerk_model", "planner"):
            overrides[key] = value
        else:
            overrides[key] = int(value) if key in INT_KEYS else float(value)
    return profile, overrides


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("samples", nargs="*", help="sample file names (default: all)")
    parser.add_argument("--acc", type=float, action="append",
                        help="machine acceleration per axis, mm/s² (default: 1000 and 5000)")
    parser.add_argument("--output", action="append",
                        help="an output variant: a built-in profile and overrides of its "
                             "keys, e.g. default,decimals=6 (default: linuxcnc, and default)")
    parser.add_argument("--traj", action="append", default=[],
                        help="an INI [TRAJ] setting of the machine, KEY=VALUE, e.g. "
                             "ARC_BLEND_RAMP_FREQ=1000 (default: sim.ini's)")
    args = parser.parse_args()
    traj = dict(item.partition("=")[::2] for item in args.traj)
    if reason := unavailable_reason():
        sys.exit(f"cannot run LinuxCNC: {reason}")
    chosen = [s for s in samples() if not args.samples or s.name in args.samples]
    print("| sample | curve | output | acc mm/s² | planned s | measured / planned | path µm "
          "| standstill periods | rest to rest |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as scratch:
        for output in args.output or DEFAULT_OUTPUTS:
            folder = Path(scratch) / output.replace(",", "_")
            folder.mkdir()
            for source in chosen:
                profile, overrides = output_variant(output)
                program = convert_for_linuxcnc(source, folder, overrides, profile)
                for acc_mm_s2 in args.acc or ACCELERATIONS_MM_S2:
                    try:
                        runs = measure(source, program, simulate(program, acc_mm_s2, traj))
                    except (SimulationError, MeasurementError) as failure:
                        print(f"| {source.name} | | {output} | {acc_mm_s2:g} | | FAILED: "
                              f"{failure} | | | |", flush=True)
                        continue
                    for index, run in enumerate(runs):
                        print(f"| {source.name} | {index} | {output} | {acc_mm_s2:g} | "
                              f"{run.planned_s:.3f} | {run.cycle_ratio:.4f} | "
                              f"{run.path_error_mm * 1000:.3f} | {run.standstill_periods} | "
                              f"{run.rest_to_rest_ratio:.4f} |",
                              flush=True)


if __name__ == "__main__":
    main()
