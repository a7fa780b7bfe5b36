from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import AXIS_KEYS, Machine, load_machine, machine_from_mapping
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.timelaw import TimeLaw, chain_segments, speed_at_arc

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--update-golden", action="store_true",
                     help="Rewrite the golden output files instead of comparing with them.")


# The suite's default run must stay under a minute; NURBSFEED_LONG_TESTS=1 runs the larger
# fuzzing properties at their full example counts.
LONG_TESTS = os.environ.get("NURBSFEED_LONG_TESTS", "") == "1"


def examples(full: int) -> int:
    """Hypothesis examples of a fuzzing property: `full` in a long run, a quarter by default."""
    return full if LONG_TESTS else max(full // 4, 100)


def load_curve(name: str, folder: Path = SAMPLES) -> NurbsCurve:
    """The first curve of folder/name.json."""
    raw = json.loads((folder / f"{name}.json").read_text())["curves"][0]
    return NurbsCurve.build(raw["degree"], raw["knots"], raw["control_points"],
                            raw.get("weights"), raw.get("name", name))


def default_paper_profile() -> dict[str, object]:
    """configs/default.yaml without its jerk_model, planner and per-axis keys: its path limits
    (200 mm/s, 2000 mm/s^2, 50,000 mm/s^3, 1 ms) under the paper's jerk model and planner, the
    default profile as it was before it moved to the path model (the paper model's tests are
    written for it)."""
    values = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())
    return {k: v for k, v in values.items()
            if k not in ("jerk_model", "planner") and k not in AXIS_KEYS}


def default_paper_machine(**overrides: object) -> Machine:
    """`default_paper_profile` with `overrides` of its keys, as a machine."""
    return machine_from_mapping({**default_paper_profile(), **overrides}, "default-paper")


def default_paper_limits() -> Limits:
    return default_paper_machine().limits


@pytest.fixture(scope="session")
def butterfly() -> NurbsCurve:
    return load_curve("butterfly")


@pytest.fixture(scope="session")
def paper_limits() -> Limits:
    return load_machine("paper-table1").limits


PROFILES = ("default", "paper-table1", "linuxcnc")


def convert_each(sources: list[Path], folder: Path) -> dict[tuple[str, str], Path]:
    """Every source converted under each built-in profile into folder: {(name, profile): out}."""
    from nurbsfeed.pipeline import convert_file

    out = {}
    for source in sources:
        for profile in PROFILES:
            target = folder / f"{source.stem}.{profile}.nc"
            convert_file(source, target, load_machine(profile))
            out[(source.name, profile)] = target
    return out


# ---- the time law as the tests read it (the product reads it only through TimeLaw.sample and
# the compiled kernels, which these call) ---------------------------------------------------------
def law_from_segments(s_key_mm, v_key_mm_s, v_peak_mm_s, hold_start_mm, hold_end_mm,
                      acc_mm_s2, jerk_mm_s3) -> TimeLaw:
    """The law the planner builds from these segments (chain_segments, then from_pieces)."""
    f = np.ascontiguousarray
    return TimeLaw.from_pieces(*chain_segments(
        f(s_key_mm, dtype=float), f(v_key_mm_s, dtype=float), f(v_peak_mm_s, dtype=float),
        f(hold_start_mm, dtype=float), f(hold_end_mm, dtype=float), float(acc_mm_s2),
        float(jerk_mm_s3)))


def law_at(law: TimeLaw, t_s: np.ndarray) -> tuple[np.ndarray, ...]:
    """s, v, a, j at absolute times (N,) -> four (N,) arrays."""
    piece, local, v, a, j = law.sample(np.array(t_s, dtype=float))  # (writable, as planned)
    return law.s0_mm[piece] + local, v, a, j


def law_increments(law: TimeLaw, t_s: np.ndarray) -> np.ndarray:
    """s(t[k+1]) - s(t[k]) for sorted times (N+1,) -> (N,), piece-locally (as the stepping's
    targets are), so that a tiny step far along the curve keeps its relative precision."""
    piece, local, _, _, _ = law.sample(t_s)
    return (law.s0_mm[piece[1:]] - law.s0_mm[piece[:-1]]) + (local[1:] - local[:-1])


def law_speed_at_arc(law: TimeLaw, s_mm: np.ndarray,
                     floor_mm_s: np.ndarray | None = None) -> np.ndarray:
    """v where the law passes arc length s (M,) -> (M,): the planner's kernel, which leaves 0
    where the law's piece cannot exceed the floor (M,) (default: every piece solved). The law's
    arrays are passed writable, as the planner passes them: read-only ones would compile the
    kernel once more."""
    s_mm = np.array(s_mm, dtype=float)
    floor = np.full(s_mm.size, -np.inf) if floor_mm_s is None else np.array(floor_mm_s)
    out = np.zeros_like(s_mm)
    speed_at_arc(*(np.array(x) for x in (law.t0_s, law.s0_mm, law.v0_mm_s, law.a0_mm_s2,
                                         law.jerk_mm_s3)), law.duration_s, s_mm, floor, out)
    return out
