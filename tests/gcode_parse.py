"""A minimal reader of our own G1 output, for tests: modal axes, F words, comments skipped."""

from __future__ import annotations

import re

import numpy as np

WORD = re.compile(r"([A-Z])(-?\d*\.?\d*)")
MOVE = re.compile(r"(G1 )?[XYZF]")
AXES = (("X", 0), ("Y", 1), ("Z", 2))


def moves(text: str, start) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Points (M, 3) and F (M,) of every G1 line after `start`, with the raw lines. The
    position is kept in plain floats, not an array copied per line: tests read programs of
    10^5 lines, some hundreds of times."""
    pos = [float(x) for x in np.asarray(start, dtype=float)]
    feed = np.nan
    points, feeds, raw = [], [], []
    for line in text.splitlines():
        if not line or line.startswith("(") or not MOVE.match(line):
            continue
        words = dict(WORD.findall(line.replace("G1 ", "")))
        for axis, i in AXES:
            if axis in words:
                pos[i] = float(words[axis])
        if "F" in words:
            feed = float(words["F"])
        points.append(tuple(pos))
        feeds.append(feed)
        raw.append(line)
    return np.array(points), np.array(feeds), raw
