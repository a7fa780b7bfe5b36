"""The lines read between a chain's curves, written in place where the motion crosses their
joint (design §3b)."""

from __future__ import annotations

from typing import BinaryIO

import numpy as np

from nurbsfeed.files import ENCODING, ERRORS
from nurbsfeed.gcode.writer import MoveWriter
from nurbsfeed.program import PassThrough


def write_lines(writer: MoveWriter | None, out: BinaryIO,
                lines: tuple[PassThrough, ...]) -> None:
    """Lines read between two curves, written where the motion is (the writer's held moves
    first); if they carry words (a zero-length G1, an F) the next move writes its G1 and F
    again, since the controller executed theirs."""
    if not lines:
        return
    if writer is not None:
        writer.end_curve()
    out.write(b"".join(line.text.encode(ENCODING, ERRORS) for line in lines))
    if writer is not None and any(line.words for line in lines):
        writer.after_lines()


class JointLines:
    """Hands points to the writer and, where the motion crosses a joint, writes the lines read
    there, in place (design §3b): after the last point at or before the joint. `crossings`
    (J,): the count of points handed on (the chain's first point not counted) after which
    each joint's lines come; a joint whose count is not known yet is None."""

    def __init__(self, writer: MoveWriter | None, out: BinaryIO,
                 between: tuple[tuple[PassThrough, ...], ...]) -> None:
        self.writer = writer
        self.out = out
        self.between = between
        self.crossings: list[int] = []
        self.given = 0
        self.written = 0  # joints whose lines are written

    def add(self, points: np.ndarray) -> None:
        while (self.written < len(self.crossings)
               and self.crossings[self.written] <= self.given + len(points)):
            cut = self.crossings[self.written] - self.given
            self._give(points[:cut])
            points = points[cut:]
            self._lines(self.written)
            self.written += 1
        self._give(points)

    def finish(self) -> None:
        while self.written < len(self.between):  # joints at the very end (none: a safeguard)
            self._lines(self.written)
            self.written += 1

    def _give(self, points: np.ndarray) -> None:
        if len(points) and self.writer is not None:
            self.writer.add_points(points)
        self.given += len(points)

    def _lines(self, joint: int) -> None:
        write_lines(self.writer, self.out, self.between[joint])
