"""What a reader hands the pipeline: a stream of pass-through lines and NURBS curve blocks.

Every reader (JSON, Fanuc G06.2, LinuxCNC G5.2/G6.2) yields these in file order, so the pipeline
can stream a program of any length: a `PassThrough` is written back unchanged, a `CurveBlock` is
planned, interpolated and replaced by G1 moves.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nurbsfeed.errors import Location
from nurbsfeed.geometry import NurbsCurve


@dataclass(frozen=True)
class PassThrough:
    """One source line, exactly as read (decoded with surrogateescape, line ending included)."""

    text: str


@dataclass(frozen=True, eq=False)
class CurveBlock:
    """One NURBS curve of the program and the modal state it is executed in.

    feed_u / feed_mm_s: the programmed feed as a step function of u (design §3a: an F word on a
    Fanuc control point j caps the spans from j on). feed_u[0] == curve.u_min; feed_mm_s is in
    program units per second, inf where no feed was programmed. Empty arrays mean "no cap".
    """

    curve: NurbsCurve
    location: Location
    units: str = "mm"  # "mm" (G21) or "in" (G20)
    eol: str = "\n"  # line ending for the lines written in place of the block
    incremental: bool = False  # G91 in effect: the moves are bracketed by G90 ... G91
    rapid_to_start: bool = False  # a G0 to the first control point comes first (JSON curves:
    # nothing in the input moves the tool there)
    feed_word_after: str | None = None  # F word to restore after the moves, e.g. "F1200."
    # (always with a decimal point: it is written by us)
    feed_u: np.ndarray = field(default_factory=lambda: np.empty(0))
    feed_mm_s: np.ndarray = field(default_factory=lambda: np.empty(0))


ProgramItem = PassThrough | CurveBlock
