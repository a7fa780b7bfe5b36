"""A minimal reader of our own G1 output, for tests: modal axes, F words, comments skipped."""

from __future__ import annotations

import re

import numpy as np

WORD = re.compile(r"([A-Z])(-?\d*\.?\d*)")


def moves(text: str, start) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Points (M, 3) and F (M,) of every G1 line after `start`, with the raw lines."""
    pos = np.array(start, dtype=float)
    feed = np.nan
    points, feeds, raw = [], [], []
    for line in text.splitlines():
        if not line or line.startswith("(") or not re.match(r"^(G1 )?[XYZF]", line):
            continue
        words = dict(WORD.findall(line.replace("G1 ", "")))
        for axis, i in (("X", 0), ("Y", 1), ("Z", 2)):
            if axis in words:
                pos[i] = float(words[axis])
        if "F" in words:
            feed = float(words["F"])
        points.append(pos.copy())
        feeds.append(feed)
        raw.append(line)
    return np.array(points), np.array(feeds), raw
