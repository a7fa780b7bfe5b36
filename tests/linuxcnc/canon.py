"""LinuxCNC's standalone interpreter `rs274` as a test client: run it, read its canonical calls.

rs274 reads a program with the interpreter a LinuxCNC machine runs and prints one canonical
machining call per line (`STRAIGHT_FEED(x, y, z, a, b, c)`, `SET_FEED_RATE(f)`,
`COMMENT("...")`) without a machine. Positions and feeds are printed in the program's units
(G20: inches, inch/min) with 4 decimals, whatever the program wrote.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tests.linuxcnc.programs import WrittenCurve

PRINTED_DECIMALS = 4
CANON_LINE = re.compile(r"^\s*\d+\s+(N\S*)\s+([A-Z0-9_]+)\((.*)\)\s*$")
CURVE_COMMENT = re.compile(r"nurbsfeed: curves? .*?, (\d+) points, period ([\d.]+) ms, "
                           r".*planned cycle ([\d.]+) s")


def rs274_path() -> str | None:
    return shutil.which("rs274")


@dataclass(frozen=True)
class CanonCurve:
    """The feed moves LinuxCNC made of one converted curve, in program units."""

    points: int
    period_s: float
    comment_cycle_s: float  # as the comment prints it, to 1 ms
    start: np.ndarray  # (3,) position before the first move
    ends: np.ndarray  # (M, 3) end of each STRAIGHT_FEED
    feeds_per_min: np.ndarray  # (M,) feed in force for each move

    @property
    def planned_cycle_s(self) -> float:
        """Every written point lies one whole period after the one before it."""
        return (self.points - 1) * self.period_s


def moves_cycle_s(start: np.ndarray, ends: np.ndarray, feeds_per_min: np.ndarray) -> float:
    """Σ distance / F: how long the moves last at their programmed feeds."""
    starts = np.vstack([start, ends[:-1]])
    lengths = np.linalg.norm(ends - starts, axis=1)
    return float(np.sum(lengths / feeds_per_min) * 60.0)


def printed_tolerance(written_decimals: int) -> float:
    """How far a printed number may lie from the written one: half a printed unit when the
    program wrote more decimals than rs274 prints (inch programs), else nothing but float noise."""
    if written_decimals <= PRINTED_DECIMALS:
        return 1e-9
    return 0.5 * 10.0 ** -PRINTED_DECIMALS + 1e-9


def interpreted_cycle_s(canon: CanonCurve, written: WrittenCurve) -> float:
    """Σ distance / F over LinuxCNC's moves, each number at the precision the program wrote.

    The caller has checked that every printed position and feed is the written one to rs274's
    4 printed decimals; where the program wrote more (inch programs: 5 decimals, small F to 5
    significant digits) the written digits replace the printed ones, which would otherwise
    round a 1.7e-3 in move by up to 3 %.
    """
    ends = np.where(np.isnan(written.ends), canon.ends, written.ends)
    return moves_cycle_s(canon.start, ends, written.feeds_per_min)


@dataclass(frozen=True)
class Canon:
    returncode: int
    output: str
    calls: list[tuple[str, str, str]]  # (N word or "N.....", call name, its arguments)

    def errors(self) -> list[str]:
        """What the interpreter printed besides its canonical calls: its error and the line."""
        return [line for line in self.output.splitlines()
                if line.strip() and not CANON_LINE.match(line) and line.strip() != "executing"]

    def curves(self) -> list[CanonCurve]:
        """Each nurbsfeed curve: the feed calls of the unnumbered lines after its comment.

        The moves nurbsfeed writes carry no N word, so the first numbered line or any other
        call (a rapid, a spindle command) ends the curve.
        """
        found = []
        position = np.zeros(3)
        i = 0
        while i < len(self.calls):
            _, name, args = self.calls[i]
            i += 1
            if name in ("STRAIGHT_FEED", "STRAIGHT_TRAVERSE"):
                position = _xyz(args)
            if name != "COMMENT" or not (match := CURVE_COMMENT.search(args)):
                continue
            start, ends, feeds = position.copy(), [], []
            feed = np.nan
            while (i < len(self.calls) and self.calls[i][0] == "N....."
                   and self.calls[i][1] in ("SET_FEED_RATE", "STRAIGHT_FEED")):
                _, name, args = self.calls[i]
                i += 1
                if name == "SET_FEED_RATE":
                    feed = float(args)
                else:
                    position = _xyz(args)
                    ends.append(position)
                    feeds.append(feed)
            found.append(CanonCurve(int(match.group(1)), float(match.group(2)) / 1000.0,
                                    float(match.group(3)), start,
                                    np.array(ends).reshape(-1, 3), np.array(feeds)))
        return found


def _xyz(args: str) -> np.ndarray:
    return np.array([float(value) for value in args.split(",")[:3]])


def run_rs274(program: Path, workdir: Path) -> Canon:
    """Interpret `program` with rs274 in batch mode (`-g`: on through M0/M1 without waiting).

    With no `-t`/`-v`/`-i` rs274 uses its built-in tool table and parameters, which is all a
    program of straight moves needs.
    """
    done = subprocess.run([rs274_path() or "rs274", "-g", str(program)], cwd=workdir,
                          capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=300)
    calls = [(m.group(1), m.group(2), m.group(3))
             for m in map(CANON_LINE.match, done.stdout.splitlines()) if m]
    return Canon(done.returncode, done.stdout + done.stderr, calls)
