"""G1 output (design §5): coordinates as written, F from the written coordinates, no zero moves.

For each interpolation point the coordinates are rounded to `decimals`. A point whose rounded
coordinates equal the previously written point is not written; its period goes to the next
written move, so every move lasts n * T with n >= 1 (n > 1 only near standstill). The F word is
60 |dP^| / (n T) from the *rounded* coordinates, so the controller spends exactly the planned time
on every move. Only axes that change and F words that change are written (modal words).

All of it runs in one loop in numba's subset, `_emit_moves`, point by point: round to integers
of output units ("ticks"), drop a point equal to the last written one, compute F, and write the
text: always a decimal point, trailing zeros dropped (`50.`, `12.34`), never `-0.`. F is written
with `feed_decimals`, or more when F is small, so that it keeps 5 significant digits.
`format_number` gives the same text for one value (it is `_emit_moves`' own X word).

A curve comes in chunks (`MoveWriter.add_points`, then `end_curve`): the writer's state between
them is the last written point, the periods since it, the last F and the held run of points that
round onto the last point given, so the text does not depend on where the chunks are cut.
"""

from __future__ import annotations

import math
from typing import BinaryIO

import numpy as np

from nurbsfeed.jit import jit

FEED_SIGNIFICANT_DIGITS = 5
FEED_MAX_DECIMALS = 6
CHUNK_POINTS = 65536  # points formatted per call: bounds the text buffer
_BYTES_PER_LINE = 4 + 3 * 23 + 24 + 2

_AXES = np.array([ord("X"), ord("Y"), ord("Z")], dtype=np.uint8)
_FEED_POW10 = 10.0 ** np.arange(FEED_MAX_DECIMALS + 1)
_LF = np.frombuffer(b"\n", dtype=np.uint8)
_POW10 = np.array([10**k for k in range(20)], dtype=np.uint64)
_ONES = np.array([48 + k % 10 for k in range(100)], dtype=np.uint8)  # "00".."99", digit by digit
_TENS = np.array([48 + k // 10 for k in range(100)], dtype=np.uint8)
MAX_DECIMALS = 18  # decimals written: ticks are int64, at most 19 digits
# `_emit_moves` builds the number text with unsigned integers, digits and positions alike; these
# are its constants, unsigned too (numba makes uint64 op int64 an int64, or even a float)
_U1 = np.uint64(1)
_U2 = np.uint64(2)
_U4 = np.uint64(4)
_U10 = np.uint64(10)
_U100 = np.uint64(100)
_U10K = np.uint64(10000)


@jit
def _put_pair(buf, end, pair):
    """Write the two digits of pair (0..99) at buf[end - 2:end]; end unsigned."""
    buf[end - _U1] = _ONES[pair]
    buf[end - _U2] = _TENS[pair]


@jit
def _put_quad(buf, end, quad):
    """Write the four digits of quad (0..9999) at buf[end - 4:end]; end unsigned. One division
    by 100 gives both pairs, so digits come four per step of the division chain."""
    high = quad // _U100
    _put_pair(buf, end, quad - high * _U100)
    _put_pair(buf, end - _U2, high)


@jit
def _round_tick(value, scale):
    """value * scale rounded to an integer, half away from zero."""
    scaled = value * scale
    whole = int(math.floor(abs(scaled) + 0.5))
    return -whole if scaled < 0.0 else whole


@jit
def _round_many(values, scale, out):
    """`_round_tick` of every value: values, out (M,)."""
    for q in range(values.size):
        out[q] = _round_tick(values[q], scale)


# _emit_moves' state between calls (an int64 array): the last written point in ticks, the
# periods since it, the last F (ticks * 10^(FEED_MAX_DECIMALS - decimals); -1: none yet), whether
# the next line is the curve's first, and the moves written
_X, _Y, _Z, _PENDING, _FEED, _FIRST, _MOVES = range(7)


@jit
def _emit_moves(points, decimals, scale, unit, period_s, feed_decimals, pow10, eol, axes, state,
                buf):
    """Write the G1 lines of points (M, 3), which follow the state's last point one period
    apart, into buf; return the bytes used. scale = 10^decimals, unit = 10^-decimals; pow10[k]
    = 10^k for the F decimals k; decimals <= MAX_DECIMALS.

    A point whose ticks equal the last written ones only adds its period to the next move.
    F = 60 |dP^| / (n T) from the ticks, written with the decimals that keep
    FEED_SIGNIFICANT_DIGITS (at least feed_decimals, at most FEED_MAX_DECIMALS). Only changed
    axes and a changed F are written; the curve's first line starts with G1.
    """
    # at or above this F, feed_decimals already keep the significant digits (with a margin that
    # log10's rounding cannot cross)
    plain_feed = 10.0 ** (FEED_SIGNIFICANT_DIGITS - 1 - feed_decimals) * (1.0 + 1e-9)
    lx = state[_X]
    ly = state[_Y]
    lz = state[_Z]
    pending = state[_PENDING]
    last_feed = state[_FEED]
    first_line = state[_FIRST]
    moves = 0
    pos = 0
    for k in range(points.shape[0]):
        tx = _round_tick(points[k, 0], scale)
        ty = _round_tick(points[k, 1], scale)
        tz = _round_tick(points[k, 2], scale)
        pending += 1
        if tx == lx and ty == ly and tz == lz:
            continue
        dx = float(tx - lx)
        dy = float(ty - ly)
        dz = float(tz - lz)
        feed = 60.0 * (math.sqrt(dx * dx + dy * dy + dz * dz) * unit) / (pending * period_s)
        feed_dec = feed_decimals
        if feed < plain_feed:  # only then can more decimals be needed
            magnitude = math.floor(math.log10(feed))
            feed_dec = int(min(max(FEED_SIGNIFICANT_DIGITS - 1 - magnitude, feed_decimals),
                               FEED_MAX_DECIMALS))
        feed_ticks = int(math.floor(feed * pow10[feed_dec] + 0.5))
        # equal text <=> equal ticks / 10^decimals: compare at FEED_MAX_DECIMALS
        feed_norm = feed_ticks * int(pow10[FEED_MAX_DECIMALS - feed_dec])
        if first_line:
            buf[pos] = 71  # 'G'
            buf[pos + 1] = 49  # '1'
            buf[pos + 2] = 32
            pos += 3
            first_line = 0
        # the words, each followed by a space: X, Y, Z when changed, then F when changed
        for word in range(4):
            if word < 3:
                value = tx if word == 0 else (ty if word == 1 else tz)
                last = lx if word == 0 else (ly if word == 1 else lz)
                if value == last:
                    continue
                letter = axes[word]
                dec = decimals
            else:
                if feed_norm == last_feed:
                    continue
                value = feed_ticks
                letter = 70  # 'F'
                dec = feed_dec
                last_feed = feed_norm
            buf[pos] = letter
            pos += 1
            # the number value * 10^-dec. Its digits are taken right to left from the magnitude
            # as an unsigned integer (division by a constant is then a multiplication), four or
            # two at a time from a table of "00".."99", and written right to left from the
            # number's end: dec fraction digits, the point, the integer digits (at least one,
            # "0." and "0.5"); then the fraction's trailing zeros are dropped. The positions are
            # unsigned too, so that numba indexes buf without its negative-index wraparound.
            # (Written out here rather than as a function: numba does not inline one this
            # large, and the calls made the whole loop a third slower.)
            if value < 0:
                buf[pos] = 45  # '-'
                pos += 1
                value = -value
            digits = np.uint64(value)
            n = np.uint64(dec + 1)  # the digits to write: dec and at least one more
            while digits >= _POW10[n]:
                n += _U1
            end = np.uint64(pos) + n + _U1
            p = end
            left = dec  # fraction digits still to write
            for _ in range(4):  # bounded (dec <= MAX_DECIMALS): unrolled, unlike a while loop
                if left < 4:
                    break
                _put_quad(buf, p, digits % _U10K)
                digits //= _U10K
                p -= _U4
                left -= 4
            if left >= 2:
                _put_pair(buf, p, digits % _U100)
                digits //= _U100
                p -= _U2
                left -= 2
            if left == 1:
                buf[p - _U1] = 48 + digits % _U10
                digits //= _U10
                p -= _U1
            p -= _U1
            buf[p] = 46  # '.'
            while digits >= _U10K:
                _put_quad(buf, p, digits % _U10K)
                digits //= _U10K
                p -= _U4
            if digits >= _U100:
                _put_pair(buf, p, digits % _U100)
                digits //= _U100
                p -= _U2
            if digits >= _U10:
                _put_pair(buf, p, digits)
            else:
                buf[p - _U1] = 48 + digits
            while buf[end - _U1] == 48:  # trailing zeros; the point stops it
                end -= _U1
            buf[end] = 32
            pos = np.int64(end) + 1
        pos -= 1  # the last word's space
        for b in range(eol.size):
            buf[pos] = eol[b]
            pos += 1
        lx = tx
        ly = ty
        lz = tz
        pending = 0
        moves += 1
    state[_X] = lx
    state[_Y] = ly
    state[_Z] = lz
    state[_PENDING] = pending
    state[_FEED] = last_feed
    state[_FIRST] = first_line
    state[_MOVES] += moves
    return pos


def round_ticks(points: np.ndarray, decimals: int) -> np.ndarray:
    """(N, 3) coordinates -> (N, 3) int64 in units of 10^-decimals (round half away from 0)."""
    values = np.ascontiguousarray(points, dtype=float)
    out = np.empty(values.shape, dtype=np.int64)
    _round_many(values.reshape(-1), 10.0**decimals, out.reshape(-1))
    return out


def run_start(points: np.ndarray, ticks: np.ndarray, decimals: int) -> int:
    """Index of the first of the trailing points of points (M, 3) that round onto ticks (3,):
    M if the last one does not, 0 if all of them do. Only the last few are looked at."""
    look = min(16, len(points))
    while look:
        tail = round_ticks(points[-look:], decimals)
        differ = np.flatnonzero(np.any(tail != ticks, axis=1))
        if differ.size:
            return len(points) - look + int(differ[-1]) + 1
        if look == len(points):
            break
        look = min(4 * look, len(points))
    return 0


def _check_decimals(decimals: int) -> None:
    if not 0 <= decimals <= MAX_DECIMALS:
        raise ValueError(f"decimals must be from 0 to {MAX_DECIMALS}, not {decimals}")


class MoveWriter:
    """Writes the G1 moves of one curve to a binary stream, chunk by chunk."""

    def __init__(self, out: BinaryIO, decimals: int, feed_decimals: int, period_s: float,
                 eol: str, start: np.ndarray) -> None:
        _check_decimals(decimals)
        self.out = out
        self.decimals = decimals
        self.scale = 10.0**decimals
        self.unit = 10.0**-decimals
        self.feed_decimals = feed_decimals
        self.period_s = period_s
        self.eol = np.frombuffer(eol.encode("ascii"), dtype=np.uint8)
        self.state = np.zeros(7, dtype=np.int64)
        self.state[:3] = round_ticks(np.asarray(start, dtype=float)[None, :], decimals)[0]
        self.state[_FEED] = -1
        self.state[_FIRST] = 1
        self.buf = np.empty(0, dtype=np.uint8)
        # the run of trailing points that round onto the last one given (see `add_points`)
        self.held_count = 0
        self.held_point = np.zeros(3)
        self.held_ticks = np.zeros(3, dtype=np.int64)

    @property
    def moves(self) -> int:
        return int(self.state[_MOVES])

    def write_curve(self, points: np.ndarray) -> None:
        """The curve's points (N, 3) after its first one (`start`), ending at the curve end."""
        self.add_points(points[1:])
        self.end_curve()

    def add_points(self, points: np.ndarray) -> None:
        """The curve's next points (M, 3), one period apart, in chunks of any size.

        The trailing points that round onto the curve end are not written (they equal the end
        as written), and a dropped point's period goes to the next move; at the end there is
        none, so the machine would arrive early. Held at the point before them instead, they
        make the one move onto the end span all their periods: it arrives when the plan does.
        The end is not known before the last chunk, so the run of points that round onto the
        last point given so far is held: as a count and one of them, which is all writing them
        needs (equal ticks: the first may move, the others only add their periods). A later
        point that rounds elsewhere releases the run, written as it would have been.
        """
        if len(points) == 0:
            return
        last = round_ticks(points[-1:], self.decimals)[0]
        first_held = run_start(points, last, self.decimals)
        if first_held == 0 and self.held_count and np.array_equal(self.held_ticks, last):
            self.held_count += len(points)
            return
        self._release()
        self.write(points[:first_held])
        self.held_point = np.array(points[first_held], dtype=float)
        self.held_ticks = last
        self.held_count = len(points) - first_held

    def end_curve(self) -> None:
        """Write the held run onto the end as one move spanning all its periods."""
        if self.held_count:
            self.state[_PENDING] += self.held_count - 1  # held where the point before is
            self.write(self.held_point[None, :])
        self.held_count = 0

    def _release(self) -> None:
        """Write the held run as the points it stands for (see `add_points`)."""
        if self.held_count:
            self.write(self.held_point[None, :])
            self.state[_PENDING] += self.held_count - 1
        self.held_count = 0

    def write(self, points: np.ndarray) -> None:
        """Points (N, 3) that follow the previous ones, one period apart."""
        points = np.ascontiguousarray(points, dtype=float)
        size = min(len(points), CHUNK_POINTS) * _BYTES_PER_LINE
        if self.buf.size < size:
            self.buf = np.empty(size, dtype=np.uint8)
        for lo in range(0, len(points), CHUNK_POINTS):
            used = _emit_moves(points[lo:lo + CHUNK_POINTS], self.decimals, self.scale,
                               self.unit, self.period_s, self.feed_decimals, _FEED_POW10,
                               self.eol, _AXES, self.state, self.buf)
            self.out.write(self.buf[:used])


def format_number(value: float, decimals: int) -> str:
    """The writer's number format for one value (used for comments and restoring lines): the X
    word that `_emit_moves` writes for a move to X = value."""
    _check_decimals(decimals)
    point = np.array([[value, 0.0, 0.0]])
    state = np.zeros(7, dtype=np.int64)
    # the last point differs from this one in X only, so the move is "X<value> F<feed>\n"
    state[_X] = round_ticks(point, decimals)[0, 0] + 1
    state[_FEED] = -1
    buf = np.empty(_BYTES_PER_LINE, dtype=np.uint8)
    used = _emit_moves(point, decimals, 10.0**decimals, 10.0**-decimals, 1.0, 0, _FEED_POW10,
                       _LF, _AXES, state, buf)
    return buf[1:used].tobytes().decode("ascii").split(" ")[0]


def rapid_line(point: np.ndarray, decimals: int) -> str:
    """A G0 to `point` (3,), its numbers as the moves write theirs."""
    return "G0 " + " ".join(f"{axis}{format_number(value, decimals)}"
                            for axis, value in zip("XYZ", point))


def cycle_comment(curve_index: int, name: str, n_points: int, period_s: float, method: str,
                  cycle_s: float, length_mm: float, units: str) -> str:
    """The comment line written before each replaced block (no parentheses inside)."""
    clean = "".join(ch for ch in name if ch not in "()\r\n")
    unit = "mm" if units == "mm" else "in"
    return (f"(nurbsfeed: curve {curve_index} {clean}, {n_points} points, period "
            f"{period_s * 1e3:g} ms, {method}, length {length_mm:.3f} {unit}, "
            f"planned cycle {cycle_s:.3f} s)")
