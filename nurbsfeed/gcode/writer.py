"""G1 output (SPEC §5): coordinates as written, F from the written coordinates, no zero moves.

For each interpolation point the coordinates are rounded to `decimals`. A point whose rounded
coordinates equal the previously written point is not written; its period goes to the next
written move, so every move lasts n * T with n >= 1 (n > 1 only near standstill). The F word is
60 |dP^| / (n T) from the *rounded* coordinates, so the controller spends exactly the planned time
on every move. Only axes that change and F words that change are written (modal words).

Numbers are integers of output units ("ticks") turned into text by `_emit_lines`, a loop in
numba's subset: always a decimal point, trailing zeros dropped (`50.`, `12.34`), never `-0.`.
F is written with `feed_decimals`, or more when F is small, so that it keeps 5 significant digits.
"""

from __future__ import annotations

from typing import BinaryIO

import numpy as np

from nurbsfeed.jit import jit

FEED_SIGNIFICANT_DIGITS = 5
FEED_MAX_DECIMALS = 6
CHUNK_POINTS = 65536  # points formatted per call: bounds the text buffer
_BYTES_PER_LINE = 4 + 3 * 23 + 24 + 2

_G = ord("G")
_ONE = ord("1")
_SPACE = ord(" ")
_AXES = np.array([ord("X"), ord("Y"), ord("Z")], dtype=np.uint8)
_F = ord("F")


@jit
def _emit_number(buf, pos, value, decimals):
    """Write integer `value` * 10^-decimals as text at buf[pos:]; return the new position."""
    if value < 0:
        buf[pos] = 45  # '-'
        pos += 1
        value = -value
    scale = 1
    for _ in range(decimals):
        scale *= 10
    whole = value // scale
    frac = value - whole * scale
    # integer part, most significant digit first
    digits = 1
    probe = whole
    while probe >= 10:
        probe //= 10
        digits += 1
    for i in range(digits - 1, -1, -1):
        buf[pos + i] = 48 + whole % 10
        whole //= 10
    pos += digits
    buf[pos] = 46  # '.'
    pos += 1
    if frac > 0:
        width = decimals
        while frac % 10 == 0:
            frac //= 10
            width -= 1
        for i in range(width - 1, -1, -1):
            buf[pos + i] = 48 + frac % 10
            frac //= 10
        pos += width
    return pos


@jit
def _emit_lines(ticks, changed, feed_ticks, feed_dec, write_feed, first_g1, decimals,
                axes, eol, buf):
    """One line per row: [G1 ]X.. Y.. Z.. [F..]. ticks (M, 3) int64, changed (M, 3) bool,
    feed_ticks / feed_dec (M,) int64, write_feed (M,) bool. Returns the bytes used in buf."""
    pos = 0
    for k in range(ticks.shape[0]):
        first = True
        if k == 0 and first_g1:
            buf[pos] = 71  # 'G'
            buf[pos + 1] = 49  # '1'
            pos += 2
            first = False
        for axis in range(3):
            if changed[k, axis]:
                if not first:
                    buf[pos] = 32
                    pos += 1
                first = False
                buf[pos] = axes[axis]
                pos = _emit_number(buf, pos + 1, ticks[k, axis], decimals)
        if write_feed[k]:
            buf[pos] = 32
            buf[pos + 1] = 70  # 'F'
            pos = _emit_number(buf, pos + 2, feed_ticks[k], feed_dec[k])
        for b in range(eol.size):
            buf[pos] = eol[b]
            pos += 1
    return pos


def round_ticks(points: np.ndarray, decimals: int) -> np.ndarray:
    """(N, 3) coordinates -> (N, 3) int64 in units of 10^-decimals (round half away from 0)."""
    scaled = points * 10.0**decimals
    return (np.sign(scaled) * np.floor(np.abs(scaled) + 0.5)).astype(np.int64)


class MoveWriter:
    """Writes the G1 moves of one curve to a binary stream, chunk by chunk."""

    def __init__(self, out: BinaryIO, decimals: int, feed_decimals: int, period_s: float,
                 eol: str, start: np.ndarray) -> None:
        self.out = out
        self.decimals = decimals
        self.feed_decimals = feed_decimals
        self.period_s = period_s
        self.eol = np.frombuffer(eol.encode("ascii"), dtype=np.uint8)
        self.last_ticks = round_ticks(np.asarray(start, dtype=float)[None, :], decimals)[0]
        self.periods_pending = 0  # periods since the last written point
        self.last_feed = (-1, -1)
        self.first = True
        self.moves = 0

    def write(self, points: np.ndarray) -> None:
        """Points (N, 3) that follow the previous ones, one period apart."""
        for lo in range(0, len(points), CHUNK_POINTS):
            self._write_chunk(points[lo:lo + CHUNK_POINTS])

    def _write_chunk(self, points: np.ndarray) -> None:
        ticks = round_ticks(points, self.decimals)
        prev = np.vstack([self.last_ticks[None, :], ticks[:-1]])
        # a point equal (as written) to the one before is dropped; consecutive duplicates
        # collapse, so comparing with the previous row is comparing with the last written one
        moved = np.any(ticks != prev, axis=1)
        index = np.flatnonzero(moved)
        periods = np.diff(np.concatenate([[-1 - self.periods_pending], index]))
        self.periods_pending = len(points) - 1 - (index[-1] if index.size else
                                                  -1 - self.periods_pending)
        if index.size == 0:
            return
        kept = ticks[index]
        before = np.vstack([self.last_ticks[None, :], kept[:-1]])
        changed = kept != before
        dist = np.linalg.norm((kept - before).astype(float), axis=1) * 10.0**-self.decimals
        feed = 60.0 * dist / (periods * self.period_s)
        magnitude = np.floor(np.log10(feed))
        feed_dec = np.clip(FEED_SIGNIFICANT_DIGITS - 1 - magnitude, self.feed_decimals,
                           FEED_MAX_DECIMALS).astype(np.int64)
        feed_ticks = np.floor(feed * 10.0**feed_dec + 0.5).astype(np.int64)
        # F ticks at their decimals: equal text <=> equal (ticks / 10^dec), compare normalised
        norm = feed_ticks * 10 ** (FEED_MAX_DECIMALS - feed_dec)
        prev_norm = np.concatenate([[self._last_norm()], norm[:-1]])
        write_feed = norm != prev_norm
        buf = np.empty(len(kept) * _BYTES_PER_LINE, dtype=np.uint8)
        used = _emit_lines(kept, changed, feed_ticks, feed_dec, write_feed, self.first,
                           self.decimals, _AXES, self.eol, buf)
        self.out.write(buf[:used].tobytes())
        self.first = False
        self.last_ticks = kept[-1]
        self.last_feed = (int(feed_ticks[-1]), int(feed_dec[-1]))
        self.moves += len(kept)

    def _last_norm(self) -> int:
        ticks, dec = self.last_feed
        return -1 if dec < 0 else ticks * 10 ** (FEED_MAX_DECIMALS - dec)


def format_number(value: float, decimals: int) -> str:
    """The writer's number format for one value (used for comments and restoring lines)."""
    ticks = int(round_ticks(np.array([[value, 0.0, 0.0]]), decimals)[0, 0])
    buf = np.empty(32, dtype=np.uint8)
    used = _emit_number(buf, 0, ticks, decimals)
    return buf[:used].tobytes().decode("ascii")


def cycle_comment(curve_index: int, name: str, n_points: int, period_s: float, method: str,
                  cycle_s: float, length_mm: float, units: str) -> str:
    """The comment line written before each replaced block (no parentheses inside)."""
    clean = "".join(ch for ch in name if ch not in "()\r\n")
    unit = "mm" if units == "mm" else "in"
    return (f"(nurbsfeed: curve {curve_index} {clean}, {n_points} points, period "
            f"{period_s * 1e3:g} ms, {method}, length {length_mm:.3f} {unit}, "
            f"planned cycle {cycle_s:.3f} s)")
