from __future__ import annotations

import json
from pathlib import Path

import pytest

from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine
from nurbsfeed.planning.limits import Limits

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--update-golden", action="store_true",
                     help="Rewrite the golden output files instead of comparing with them.")


def load_curve(name: str, folder: Path = SAMPLES) -> NurbsCurve:
    """The first curve of folder/name.json."""
    raw = json.loads((folder / f"{name}.json").read_text())["curves"][0]
    return NurbsCurve.build(raw["degree"], raw["knots"], raw["control_points"],
                            raw.get("weights"), raw.get("name", name))


@pytest.fixture(scope="session")
def butterfly() -> NurbsCurve:
    return load_curve("butterfly")


@pytest.fixture(scope="session")
def paper_limits() -> Limits:
    return load_machine("paper-table1").limits


PROFILES = ("default", "paper-table1")


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

