"""The commonest line of a program outside its curves, read without words and blocks: a straight
move "[N_ ][G0 |G1 ]X_ Y_ Z_ F_" (any of X, Y, Z and F, in this order, one space apart, upper
case, at least one of them).

A straight-line post writes little else, and a program of such lines with a few curves in it
is read about twice as fast this way (readers.gcode `_Reader._plain_move`, which hands every
other line, and every such line it cannot execute exactly as `modal.ModalState.apply` would, to
the tokenizer and the general path).
"""

from __future__ import annotations

import math
import re

from nurbsfeed.gcode.tokenizer import PLAIN_NUMBER, Word, decimals_written

_END = r"(?=\r?\n?\Z)"
_PLAIN_MOVE = re.compile(
    rf"(N[0-9]+ )?(?:G(0?[01]) )?(?=[XYZF])"
    rf"(?:X({PLAIN_NUMBER})(?: (?=[YZF])|{_END}))?"
    rf"(?:Y({PLAIN_NUMBER})(?: (?=[ZF])|{_END}))?"
    rf"(?:Z({PLAIN_NUMBER})(?: (?=F)|{_END}))?"
    rf"(?:F({PLAIN_NUMBER}))?\r?\n?")

# an axis word's letter, value and fractional digits written (tokenizer.decimals_written)
AxisValue = tuple[str, float, int | None]


def plain_move(line_text: str, line: int
               ) -> tuple[int | None, list[AxisValue], Word | None] | None:
    """The motion code (G0: 0, G1: 10, None where the line has no G word), the X, Y, Z values
    and the F word of a plain move line (module docstring); None for any other line, or where a
    number is too large to be one (the tokenizer words that)."""
    match = _PLAIN_MOVE.fullmatch(line_text)
    if match is None:
        return None
    number, g_text, x_text, y_text, z_text, f_text = match.groups()
    axes = []
    for axis, text in (("X", x_text), ("Y", y_text), ("Z", z_text)):
        if text is not None:
            value = float(text)
            if not math.isfinite(value):
                return None
            axes.append((axis, value, decimals_written(text)))
    feed = None
    if f_text is not None:
        value = float(f_text)
        if not math.isfinite(value):
            return None
        # tuple.__new__ as in tokenizer._simple_words; the column is the letter's, 1-based
        feed = tuple.__new__(Word, ("F", value, f_text, decimals_written(f_text), line,
                                    match.start(6)))
    return (None if g_text is None else 10 * int(g_text)), axes, feed
