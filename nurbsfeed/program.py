"""What a reader hands the pipeline: a stream of pass-through lines and NURBS curve blocks.

Every reader (JSON, Fanuc G06.2, LinuxCNC G5.2/G6.2) yields these in file order, so the pipeline
can stream a program of any length: a `PassThrough` is written back unchanged, a `CurveBlock` is
planned, interpolated and replaced by G1 moves.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from nurbsfeed.errors import Location
from nurbsfeed.geometry import NurbsCurve

MM_PER_INCH = 25.4
MM_PER_UNIT = {"mm": 1.0, "in": MM_PER_INCH}  # G21, G20


@dataclass(frozen=True)
class PassThrough:
    """One source line, exactly as read (decoded with surrogateescape, line ending included).

    joins: the line changes no motion state, so a chain of curves runs on across it (design
    §3b): a comment, blank or N-only line, or words that leave the position, units, plane,
    distance mode, feed mode and cutter compensation as they were (a zero-length G0 / G1, a
    repeated G90, a new F). words: it carries words the controller executes (a written G0 / G1
    or F): the moves written after it repeat their G1 and F.
    """

    text: str
    joins: bool = field(default=False, compare=False)  # (the line is its text: equal texts are
    words: bool = field(default=False, compare=False)  # equal items)


@dataclass(frozen=True, eq=False)
class CurveBlock:
    """One NURBS curve of the program and the modal state it is executed in.

    feed_u / feed_mm_s: the programmed feed as a step function of u (design §3a: an F word on a
    Fanuc control point j caps the spans from j on). feed_u[0] == curve.u_min; feed_mm_s is per
    second, inf where no feed was programmed. Empty arrays mean "no cap".

    A reader yields the block in the program's unit `units`; `in_mm` converts its lengths (the
    curve's control points, the programmed feed) to mm, the one unit nurbsfeed plans, steps and
    checks in. `units` stays the program's: the writer converts back to it.
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
    lengths_in_mm: bool = False  # True once `in_mm` has converted curve and feed_mm_s
    semicolon_comments: bool = False  # comments written "; ..." (Sinumerik reads no "( )")

    def in_mm(self) -> CurveBlock:
        """This block with its lengths in mm: the form every stage after reading takes. The
        knots, weights and feed_u are not lengths and stay as read."""
        if self.lengths_in_mm:
            return self
        scale = MM_PER_UNIT[self.units]
        curve = self.curve
        if scale != 1.0:
            points = curve.points * scale
            points.setflags(write=False)
            curve = NurbsCurve(curve.degree, curve.knots, points, curve.weights, curve.name,
                               curve.u_origin, curve.u_scale)
        return dataclasses.replace(self, curve=curve, feed_mm_s=self.feed_mm_s * scale,
                                   lengths_in_mm=True)


ProgramItem = PassThrough | CurveBlock
