"""The fuzzing tier: `python -m tests.fuzz --cases 100000 --jobs 2 [--seed S]`.

Runs N cases spread evenly over the four families (gcode, json, profile, samples; see
strategies.py), each through `nurbsfeed convert` in-process (oracle.py states the property).
Prints progress, the case count per family and every failure; saves every failing input (with
its profile, and the problem in a .txt beside it) under --failures; exits 1 on any failure.
Failures that match a recorded finding in code owned elsewhere (known.py) are labelled "known"
but still count.

Cases run in chunks of at most CHUNK cases, each chunk in a process of its own with its own seed.
A case stuck in compiled code (which no signal interrupts) is caught by a watchdog thread: it
saves the case as a hang and ends the process; the chunk then restarts after that case (the
same seed draws the same cases, and those already run are skipped).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import re
import shutil
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

FAMILIES = ("gcode", "json", "profile", "samples")
CHUNK = 1000
CHECK_EVERY = 10  # `nurbsfeed check` (~0.2 s) runs on every tenth case drawn valid
MAX_SAVED = 300  # failing inputs saved per chunk (a systematic bug fails thousands of cases)
HANG_S = 90.0  # a case this long is stuck beyond the reach of the oracle's time limits
EXIT_HANG = 3


def signature(problem: str) -> str:
    """A failure's kind: its first line (its last for a traceback), paths, quotes and numbers
    blanked."""
    lines = problem.strip().splitlines()
    line = lines[-1] if problem.startswith("Traceback") else lines[0]
    line = re.sub(r"/tmp/nurbsfeed-fuzz-[^/]*/", "", line)
    return re.sub(r"'[^']*'|\"[^\"]*\"|[0-9]+", "_", line)[:160]


def save_case(folder: Path, stem: str, case, problem: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / (stem + Path(case.name).suffix)).write_bytes(case.data)
    if case.profile is not None:
        (folder / (stem + ".yaml")).write_bytes(case.profile)
    (folder / (stem + ".txt")).write_text(problem + "\n")


def run_chunk(family: str, count: int, seed: int, skip: int, failures_dir: str, quiet: bool,
              report) -> None:
    """Run cases skip..count-1 of one chunk; send ("case", index, converted, stem or None,
    problem or None) per case, then ("done",)."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hypothesis_seed

    from tests.fuzz.oracle import check_case
    from tests.fuzz.strategies import FAMILIES as STRATEGIES

    folder = Path(tempfile.mkdtemp(prefix=f"nurbsfeed-fuzz-{family}-"))
    save_to = Path(failures_dir)
    index = -1
    valid = 0
    saved = 0
    current = {"case": None, "since": None}

    def watchdog() -> None:
        while True:
            time.sleep(1.0)
            since = current["since"]
            if since is not None and time.monotonic() - since > HANG_S:
                stem = f"{family}-{seed}-{index}"
                problem = f"hang: more than {HANG_S:g} s, not interrupted (compiled code)"
                save_case(save_to, stem, current["case"], problem)
                report.send(("case", index, False, stem, problem))
                shutil.rmtree(folder, ignore_errors=True)  # the stuck case's .part file too
                os._exit(EXIT_HANG)

    threading.Thread(target=watchdog, daemon=True).start()
    _warm_up(folder)

    @hypothesis_seed(seed)
    @settings(max_examples=count, database=None, deadline=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(STRATEGIES[family])
    def one_case(case) -> None:
        nonlocal index, valid, saved
        index += 1
        if index < skip or index >= count:
            return
        check_motion = case.valid and valid % CHECK_EVERY == 0
        valid += case.valid
        current["case"], current["since"] = case, time.monotonic()
        outcome = check_case(folder, case.name, case.data, case.profile, check_motion)
        current["since"] = None
        problem = outcome.problem
        if problem is None and case.valid and outcome.exit_code != 0:
            problem = f"a valid {family} input was refused: {outcome.stderr.strip()}"
        stem = None
        if problem is not None:
            stem = f"{family}-{seed}-{index}"
            if saved < MAX_SAVED:
                save_case(save_to, stem, case, problem)
                saved += 1
        report.send(("case", index, outcome.exit_code == 0 and problem is None, stem, problem))

    one_case()
    for leftover in folder.iterdir():
        leftover.unlink()
    folder.rmdir()
    report.send(("done",))


def _warm_up(folder: Path) -> None:
    """Convert and check a sample once, outside any case's time limit: on a cold numba cache
    (a fresh clone, two workers compiling at once) the first cases would otherwise spend their
    limit compiling kernels and be reported as time-outs."""
    from tests.fuzz.oracle import run_cli

    sample = Path(__file__).resolve().parents[2] / "samples" / "butterfly.json"
    out = folder / "warm-up.nc"
    for args in (["convert", str(sample), "-o", str(out), "-q"],
                 ["check", str(sample), str(out)]):
        code, stderr, crash = run_cli(args, time_limit_s=600.0)
        if code != 0 or crash:
            raise RuntimeError(f"the warm-up run {args[0]} failed: {stderr}{crash}")
    out.unlink()


class Chunk:
    def __init__(self, family: str, count: int, seed: int) -> None:
        self.family, self.count, self.seed = family, count, seed
        self.next_index = 0  # the first case not reported yet
        self.process = None
        self.conn = None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", type=int, default=4000, help="total cases (default 4000)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    parser.add_argument("--family", choices=FAMILIES, action="append",
                        help="only this family (repeatable; default all four)")
    parser.add_argument("--failures", default="fuzz-failures",
                        help="folder for failing inputs (default ./fuzz-failures)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    args = parser.parse_args(argv)
    from tests.fuzz.known import known_finding

    families = args.family or list(FAMILIES)
    waiting: list[Chunk] = []
    for f_index, family in enumerate(families):
        left = args.cases // len(families) + (f_index < args.cases % len(families))
        for number in range((left + CHUNK - 1) // CHUNK):
            waiting.append(Chunk(family, min(CHUNK, left - number * CHUNK),
                                 args.seed * 100003 + f_index * 1009 + number))
    waiting.reverse()
    context = multiprocessing.get_context("fork")
    start = time.monotonic()
    cases, converted = Counter(), Counter()
    failures: list[tuple[str, str, str]] = []
    running: list[Chunk] = []
    last_progress = start
    while waiting or running:
        while waiting and len(running) < args.jobs:
            chunk = waiting.pop()
            parent, child = context.Pipe(duplex=False)
            chunk.conn = parent
            chunk.process = context.Process(target=run_chunk, args=(
                chunk.family, chunk.count, chunk.seed, chunk.next_index, args.failures,
                args.quiet, child))
            chunk.process.start()
            child.close()
            running.append(chunk)
        ready = multiprocessing.connection.wait([c.conn for c in running])
        for chunk in [c for c in running if c.conn in ready]:
            try:
                message = chunk.conn.recv()
            except EOFError:  # the process ended without "done": a hang, or a crash
                chunk.process.join()
                running.remove(chunk)
                if chunk.next_index < chunk.count and chunk.process.exitcode != EXIT_HANG:
                    stem = f"{chunk.family}-{chunk.seed}-{chunk.next_index}"
                    failures.append((chunk.family, stem, "the fuzzing process died "
                                     f"(exit {chunk.process.exitcode})"))
                    cases[chunk.family] += 1
                    chunk.next_index += 1
                if chunk.next_index < chunk.count:
                    waiting.append(chunk)
                continue
            if message[0] == "done":
                chunk.process.join()
                running.remove(chunk)
                continue
            _, index, ok, stem, problem = message
            chunk.next_index = index + 1
            cases[chunk.family] += 1
            converted[chunk.family] += ok
            if problem is not None:
                failures.append((chunk.family, stem, problem))
        now = time.monotonic()
        if not args.quiet and now - last_progress > 10:
            last_progress = now
            print(f"  {sum(cases.values())}/{args.cases} cases, {len(failures)} failures, "
                  f"{now - start:.0f} s", file=sys.stderr, flush=True)
    wall_s = time.monotonic() - start
    kinds = Counter((known_finding(problem) or "NEW", signature(problem))
                    for _, _, problem in failures)
    for family, stem, problem in failures:
        if known_finding(problem) is None:
            print(f"FAIL {family} {stem}: {problem.strip().splitlines()[-1][:300]}")
    print(f"\n{'family':<8} {'cases':>8} {'converted':>10} {'failures':>9}")
    for family in families:
        n_failed = sum(f[0] == family for f in failures)
        print(f"{family:<8} {cases[family]:>8} {converted[family]:>10} {n_failed:>9}")
    print(f"{'total':<8} {sum(cases.values()):>8} {sum(converted.values()):>10} "
          f"{len(failures):>9}   wall {wall_s:.0f} s, seed {args.seed}, jobs {args.jobs}")
    if failures:
        print(f"\nfailure kinds ({len(kinds)}; inputs saved under {args.failures}/):")
        for (known, kind), n in kinds.most_common():
            print(f"{n:>7}  {known:<34} {kind}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
