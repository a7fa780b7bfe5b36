"""A minimal reader of our own G1 output, for tests: modal axes, F words, comments skipped."""

from __future__ import annotations

import re

import numpy as np

WORD = re.compile(r"([A-Z])(-?\d*\.?\d*)")
MOVE = re.compile(r"(G1 )?[XYZF]")
# A move line as we write it ("G1 X1.5 Y-2. F300.", "X1.5", "F300."): read by one match, to the
# same values as the words one by one (any other line takes the word by word path)
_NUMBER = r"(-?(?:\d+\.?\d*|\.\d+))"
PLAIN_MOVE = re.compile(rf"(?:G1 )?(?=[XYZF])(?:X{_NUMBER})?(?: ?Y{_NUMBER})?(?: ?Z{_NUMBER})?"
                        rf"(?: ?F{_NUMBER})?")
AXES = (("X", 0), ("Y", 1), ("Z", 2))


def moves(text: str, start) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Points (M, 3) and F (M,) of every G1 line after `start`, with the raw lines. The
    position is kept in plain floats, not an array copied per line: tests read programs of
    10^5 lines, some hundreds of times."""
    pos = [float(x) for x in np.asarray(start, dtype=float)]
    feed = np.nan
    points, feeds, raw = [], [], []
    for line in text.splitlines():
        plain = PLAIN_MOVE.fullmatch(line)
        if plain:
            x, y, z, f = plain.groups()
            if x is not None:
                pos[0] = float(x)
            if y is not None:
                pos[1] = float(y)
            if z is not None:
                pos[2] = float(z)
            if f is not None:
                feed = float(f)
        elif not line or line.startswith("(") or not MOVE.match(line):
            continue
        else:
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
