"""Runs of plain control-point lines "K_ X_ Y_ Z_ [R_]", scanned and converted in compiled code.

A CAM-posted G06.2 curve is nearly all such lines. `fanuc.NurbsCurveReader.take_run` reads a whole
run of them with one call of `scan_point_lines`, which checks each line against the grammar of
`fanuc._POINT_LINE` (K, X, Y, Z, optional R, letters either case, one space between words,
numbers `[+-]?(\\d+(\\.\\d*)?|\\.\\d+)`, ending in "\\n", "\\r\\n", or the end of the text
after an optional "\\r") and converts its numbers, on the program's ASCII codes.

Numbers are converted by Clinger's fast path (W. D. Clinger, "How to read floating point numbers
accurately", PLDI 1990, §"the fast path"): a number of at most 2**53 written with at most 16
significant digits and e <= 22 digits after the point is m / 10**e with m and 10**e both exact
doubles, so the one IEEE division rounds it correctly, bit for bit what Python's float() gives.
A number outside these bounds (more significant digits, more fraction digits) ends the run
before its line, which the per-line path then reads with float().
"""

from __future__ import annotations

import numpy as np

from nurbsfeed.jit import JIT_ENABLED, jit

# As plain Python (numba missing or NURBSFEED_NO_JIT=1) the scan is slower than the per-line
# regex path it replaces, so runs are only read when it is compiled.
RUNS_ENABLED = JIT_ENABLED
RUN_LINES = 256  # capacity of one scan; a longer run takes several
_MAX_FRACTION = 22  # 10**22 is the largest power of ten a double holds exactly (5**22 < 2**53)
_POWERS_OF_TEN = np.array([float(10**e) for e in range(_MAX_FRACTION + 1)])
_MAX_SIGNIFICANT = 16  # enough for every m < 2**53, few enough that m never overflows int64
_MANTISSA_LIMIT = 2**53
_LF, _CR, _SPACE, _PLUS, _MINUS, _POINT, _ZERO, _NINE = 10, 13, 32, 43, 45, 46, 48, 57
_LETTERS = np.array([ord(letter) for letter in "kxyzr"])  # `code | 32` folds upper case on them


class ProgramCodes:
    """A program's text as ASCII codes for `scan_point_lines`, and the buffer scans fill."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.codes = np.frombuffer(text.encode("ascii"), dtype=np.uint8)
        self.values = np.empty((RUN_LINES, 5))

    @staticmethod
    def of(text: str) -> ProgramCodes | None:
        """The codes of `text`, or None where runs are not read (not ASCII: string and byte
        positions would differ; or the scan not compiled)."""
        return ProgramCodes(text) if RUNS_ENABLED and text.isascii() else None


@jit
def _number(codes, i):
    """(value, index after it) of the number written at codes[i], or (0.0, -1) where there is
    none or Clinger's fast path cannot convert it exactly."""
    size = codes.size
    negative = False
    if i < size and (codes[i] == _PLUS or codes[i] == _MINUS):
        negative = codes[i] == _MINUS
        i += 1
    mantissa = 0
    significant = 0
    digits = 0
    fraction = -1  # digits after the point; -1 before the point
    while i < size:
        code = int(codes[i])
        if _ZERO <= code <= _NINE:
            digits += 1
            if fraction >= 0:
                fraction += 1
            if mantissa > 0 or code > _ZERO:  # leading zeros are not significant
                significant += 1
                if significant > _MAX_SIGNIFICANT:
                    return 0.0, -1
                mantissa = mantissa * 10 + (code - _ZERO)
        elif code == _POINT and fraction < 0:
            fraction = 0
        else:
            break
        i += 1
    if digits == 0 or mantissa > _MANTISSA_LIMIT or fraction > _MAX_FRACTION:
        return 0.0, -1
    value = float(mantissa) / _POWERS_OF_TEN[max(fraction, 0)]
    return (-value if negative else value), i


@jit
def _point_line(codes, i, row):
    """Read the point line at codes[i] into row: (5,) K, X, Y, Z, R (1.0 where R is omitted).
    Returns the index after its line ending, or -1 where it is no point line `_number` reads."""
    size = codes.size
    row[4] = 1.0
    for word in range(5):
        if word > 0:
            if i < size and codes[i] == _SPACE:
                i += 1
            elif word == 4:
                break  # no R
            else:
                return -1
        if i >= size or (codes[i] | 32) != _LETTERS[word]:
            return -1
        value, i = _number(codes, i + 1)
        if i < 0:
            return -1
        row[word] = value
    if i < size and codes[i] == _CR:
        i += 1
    if i < size:
        if codes[i] != _LF:
            return -1
        i += 1
    return i


@jit
def scan_point_lines(codes, start, knot_before, values):
    """Read point lines from codes[start] on, while each is "K_ X_ Y_ Z_ [R_]" with numbers
    `_number` converts, its knot above the one before (`knot_before` for the first) and its
    weight positive; at most len(values) lines.

    codes: (N,) uint8; values: (L, 5) float64, filled with K, X, Y, Z, R (1.0 where R is
    omitted) of the lines read, in order. Returns (lines read, index of the last one's first
    code, index after the last one's line ending).
    """
    n = 0
    last_start = start
    end = start
    while n < values.shape[0] and end < codes.size:
        after = _point_line(codes, end, values[n])
        if after < 0 or not (values[n, 0] > knot_before and values[n, 4] > 0.0):
            break
        knot_before = values[n, 0]
        n += 1
        last_start = end
        end = after
    return n, last_start, end
