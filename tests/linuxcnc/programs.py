"""The samples converted for LinuxCNC, and the written moves of each converted curve.

nurbsfeed passes every line it does not convert through byte for byte, so a Fanuc program's
output still carries its Fanuc-only words. Two samples switch Fanuc's AI contour control on and
off around their curves (`G05 P10000`/`G05 P0`, `G05.1 Q1`/`G05.1 Q0`); LinuxCNC reads G5 and
G5.1 as its cubic and quadratic splines and stops there ("All axes missing with motion code").
Those lines change nothing in the path, so the LinuxCNC copy of such a program leaves them out;
everything else, including our moves, is read as written.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file
from tests.conftest import SAMPLES

FANUC_ONLY_LINE = re.compile(r"^N\d+\s+G0?5(\.1)?\s+[PQ]\d+\s*$")
CURVE_COMMENT = re.compile(r"^\(nurbsfeed: curves? ")  # a curve, or a chain (design §3b)
MOVE_LINE = re.compile(r"^(G1 )?(?=[XYZF])")
COMMENT_LINE = re.compile(r"\([^)]*\)")
WORD = re.compile(r"([XYZF])(-?\d*\.?\d*)")


def samples() -> list[Path]:
    return sorted(p for p in SAMPLES.iterdir() if p.suffix in (".json", ".nc", ".ngc"))


def fanuc_only_lines(program_text: str) -> list[str]:
    """The lines LinuxCNC cannot read that a LinuxCNC copy of the program leaves out."""
    return [line for line in program_text.splitlines() if FANUC_ONLY_LINE.match(line)]


LINUXCNC_PROFILE = "linuxcnc"  # the built-in profile of a machine like the simulated one


def convert_for_linuxcnc(source: Path, folder: Path, overrides: dict | None = None,
                         profile: str = LINUXCNC_PROFILE) -> Path:
    """`source` converted with `profile` (and overrides), Fanuc-only lines left out."""
    converted = folder / f"{source.stem}.converted.nc"
    convert_file(source, converted, load_machine(profile, overrides or {}))
    text = converted.read_text()
    dropped = set(fanuc_only_lines(text))
    target = folder / f"{source.stem}.ngc"
    target.write_text("".join(line for line in text.splitlines(keepends=True)
                              if line.rstrip("\r\n") not in dropped))
    return target


@dataclass(frozen=True)
class WrittenCurve:
    """One converted curve as written: the end of each move, its F, and each number's text."""

    ends: np.ndarray  # (M, 3), NaN on an axis not yet written since the curve comment
    feeds_per_min: np.ndarray  # (M,)
    decimals: int  # the most decimals any coordinate was written with


def written_curves(text: str) -> list[WrittenCurve]:
    """Each curve's moves: the G1/axis/F lines after its `(nurbsfeed: curve ...)` comment."""
    curves = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        if not CURVE_COMMENT.match(lines[i]):
            i += 1
            continue
        i += 1
        position = np.full(3, np.nan)
        feed = np.nan
        ends, feeds, decimals = [], [], 0
        while i < len(lines) and (MOVE_LINE.match(lines[i]) or (
                COMMENT_LINE.fullmatch(lines[i]) and not CURVE_COMMENT.match(lines[i])
                and i + 1 < len(lines) and MOVE_LINE.match(lines[i + 1]))):
            if not MOVE_LINE.match(lines[i]):  # a comment between a chain's curves
                i += 1
                continue
            words = WORD.findall(lines[i])
            for axis, value in words:
                if axis == "F":
                    feed = float(value)
                else:
                    position["XYZ".index(axis)] = float(value)
                    decimals = max(decimals, len(value.partition(".")[2]))
            if any(axis != "F" for axis, _ in words):
                ends.append(position.copy())
                feeds.append(feed)
            i += 1
        curves.append(WrittenCurve(np.array(ends).reshape(-1, 3), np.array(feeds), decimals))
    return curves
