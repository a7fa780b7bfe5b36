"""G1 output (design §5): coordinates as written, F from the written coordinates, no zero moves.

For each interpolation point the coordinates are rounded to `decimals`. A point whose rounded
coordinates equal the previously written point is not written; its period goes to the next
written move, so every move lasts n * T with n >= 1 (n > 1 only near standstill). The F word is
60 |dP^| / (n T) from the *rounded* coordinates, so the controller spends exactly the planned time
on every move. Only axes that change and F words that change are written (modal words).

How nurbsfeed writes a number with d decimals, every number it writes (coordinates, F words,
an F word it restores): value * 10^d, in double precision, rounded half away from zero to an
integer (`_round_tick`); its digits with the point before the last d, at least one digit before
it; trailing zeros after the point dropped, the point always kept; no minus sign on zero
(`50.`, `12.34`, `0.`, `-0.5`). Coordinates are written with `decimals` (one more in inch
programs, `written_decimals`), F with `feed_decimals`, or more when F is small, so that it keeps
5 significant digits.

All of it runs in one loop in numba's subset, `_emit_moves`, point by point: convert mm to the
program's unit, round to integers of output units ("ticks"), drop a point equal to the last
written one, compute F, and write the text. `format_number` writes one number by the same rule
in plain Python, for the few written elsewhere (tests hold the two to the same bytes).

A curve comes in chunks (`MoveWriter.add_points`, then `end_curve`): the writer's state between
them is the last written point, the periods since it, the last F and the held run of points that
round onto the last point given, so the text does not depend on where the chunks are cut.
"""

from __future__ import annotations

import math
from typing import BinaryIO

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.program import MM_PER_UNIT

FEED_SIGNIFICANT_DIGITS = 5
FEED_MAX_DECIMALS = 6
ZERO_LENGTH_COMMENT = "(nurbsfeed: zero-length curve, no move written)"
CHUNK_POINTS = 65536  # points formatted per call: bounds the text buffer
_BYTES_PER_LINE = 4 + 3 * 23 + 24 + 2

_AXES = np.array([ord("X"), ord("Y"), ord("Z")], dtype=np.uint8)
_FEED_POW10 = 10.0 ** np.arange(FEED_MAX_DECIMALS + 1)
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
    """value * scale rounded to an integer, half away from zero: THE rounding rule of every
    number nurbsfeed writes (scale = 10^decimals)."""
    scaled = value * scale
    whole = int(math.floor(abs(scaled) + 0.5))
    return -whole if scaled < 0.0 else whole


# _emit_moves' state between calls (an int64 array): the last written point in ticks, the
# periods since it, the last F (ticks * 10^(FEED_MAX_DECIMALS - decimals); -1: none yet), whether
# the next line is the curve's first, and the moves written
_X, _Y, _Z, _PENDING, _FEED, _FIRST, _MOVES = range(7)


@jit
def _emit_moves(points, per_mm, decimals, scale, unit, period_s, feed_decimals, pow10, eol, axes,
                state, buf):
    """Write the G1 lines of points (M, 3) in mm, which follow the state's last point one period
    apart, into buf; return the bytes used. per_mm: output units per mm (1 or 1/25.4);
    scale = 10^decimals, unit = 10^-decimals (output units); pow10[k] = 10^k for the F decimals
    k; decimals <= MAX_DECIMALS.

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
        tx = _round_tick(points[k, 0] * per_mm, scale)
        ty = _round_tick(points[k, 1] * per_mm, scale)
        tz = _round_tick(points[k, 2] * per_mm, scale)
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


def round_ticks(points: np.ndarray, decimals: int, per_mm: float = 1.0) -> np.ndarray:
    """(N, 3) coordinates in mm -> (N, 3) int64 in units of 10^-decimals of the output unit
    (per_mm of them to a mm), rounded as `_emit_moves` rounds them (`_round_tick`'s arithmetic
    in numpy: a few calls per curve, no kernel to compile)."""
    scaled = np.asarray(points, dtype=float) * per_mm * 10.0**decimals
    with np.errstate(invalid="ignore"):  # (a NaN is refused before it is written)
        whole = np.floor(np.abs(scaled) + 0.5).astype(np.int64)
    return np.where(scaled < 0.0, -whole, whole)


def run_start(points: np.ndarray, ticks: np.ndarray, decimals: int, per_mm: float = 1.0) -> int:
    """Index of the first of the trailing points of points (M, 3) that round onto ticks (3,):
    M if the last one does not, 0 if all of them do. Only the last few are looked at."""
    look = min(16, len(points))
    while look:
        tail = round_ticks(points[-look:], decimals, per_mm)
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


def written_decimals(decimals: int, units: str) -> int:
    """The coordinate decimals written in a program of `units` for a profile's `decimals`: one
    more in inches, so that a last digit of 0.00001 in (0.254 um) is near the 0.1 um of
    0.0001 mm rather than 25 times coarser."""
    return decimals + 1 if units == "in" else decimals


class MoveWriter:
    """Writes the G1 moves of one curve to a binary stream, chunk by chunk: points in mm, text
    in the program's `units`, coordinates with `written_decimals(decimals, units)` decimals."""

    def __init__(self, out: BinaryIO, decimals: int, feed_decimals: int, period_s: float,
                 eol: str, start: np.ndarray, units: str = "mm") -> None:
        decimals = written_decimals(decimals, units)
        _check_decimals(decimals)
        self.out = out
        self.per_mm = 1.0 / MM_PER_UNIT[units]
        self.decimals = decimals
        self.scale = 10.0**decimals
        self.unit = 10.0**-decimals
        self.feed_decimals = feed_decimals
        self.period_s = period_s
        self.eol = np.frombuffer(eol.encode("ascii"), dtype=np.uint8)
        self.state = np.zeros(7, dtype=np.int64)
        self.state[:3] = round_ticks(np.asarray(start, dtype=float)[None, :], decimals,
                                     self.per_mm)[0]
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
        last = round_ticks(points[-1:], self.decimals, self.per_mm)[0]
        first_held = run_start(points, last, self.decimals, self.per_mm)
        if first_held == 0 and self.held_count and np.array_equal(self.held_ticks, last):
            self.held_count += len(points)
            return
        self._release()
        self.write(points[:first_held])
        self.held_point = np.array(points[first_held], dtype=float)
        self.held_ticks = last
        self.held_count = len(points) - first_held

    def end_curve(self) -> None:
        """Write the held run onto the end as one move spanning all its periods (at a joint of
        a chain, before the lines written there: the points after continue from it)."""
        if self.held_count:
            self.state[_PENDING] += self.held_count - 1  # held where the point before is
            self.write(self.held_point[None, :])
        self.held_count = 0

    def after_lines(self) -> None:
        """Lines that execute words (a G0, an F) were written between the moves (a chain's
        joint, design §3b): the next move writes its G1 and F again."""
        self.state[_FIRST] = 1
        self.state[_FEED] = -1

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
            used = _emit_moves(points[lo:lo + CHUNK_POINTS], self.per_mm, self.decimals,
                               self.scale, self.unit, self.period_s, self.feed_decimals,
                               _FEED_POW10, self.eol, _AXES, self.state, self.buf)
            self.out.write(self.buf[:used].data)  # the bytes in place, no copy


def format_number(value: float, decimals: int) -> str:
    """`value` written as nurbsfeed writes every number (the module docstring's rule): the text
    `_emit_moves` builds byte by byte, for the few numbers written outside it. Its integer
    arithmetic is Python's, unbounded, so any finite value is written."""
    scaled = value * 10.0**decimals
    ticks = math.floor(abs(scaled) + 0.5)  # `_round_tick`
    return _format_ticks(-ticks if scaled < 0.0 else ticks, decimals)


def _format_ticks(ticks: int, decimals: int) -> str:
    """An integer count of 10^-decimals as written: a decimal point always, no trailing zeros,
    never `-0.`."""
    whole, fraction = divmod(abs(ticks), 10**decimals)
    digits = f"{fraction:0{decimals}d}".rstrip("0") if decimals else ""
    return f"{'-' if ticks < 0 else ''}{whole}.{digits}"


def rapid_line(point_mm: np.ndarray, decimals: int, units: str = "mm") -> str:
    """A G0 to `point_mm` (3,) in the program's `units`, rounded as `MoveWriter` rounds the
    start it is given (so the first move starts exactly where the G0 ends)."""
    places = written_decimals(decimals, units)
    ticks = round_ticks(np.asarray(point_mm, dtype=float)[None, :], places,
                        1.0 / MM_PER_UNIT[units])[0]
    return "G0 " + " ".join(f"{axis}{_format_ticks(int(tick), places)}"
                            for axis, tick in zip("XYZ", ticks))


def cycle_comment(curve_index: int, name: str, n_points: int, period_s: float, method: str,
                  cycle_s: float, length_mm: float, units: str) -> str:
    """The comment line written before each replaced block (no parentheses inside); the length
    in the program's `units`, as the moves under it."""
    clean = "".join(ch for ch in name if ch not in "()\r\n")
    return (f"(nurbsfeed: curve {curve_index} {clean}, {n_points} points, period "
            f"{period_s * 1e3:g} ms, {method}, length {length_mm / MM_PER_UNIT[units]:.3f} "
            f"{units}, "
            f"planned cycle {cycle_s:.3f} s)")


def chain_comment(first_index: int, last_index: int, name: str, n_points: int, period_s: float,
                  method: str, cycle_s: float, length_mm: float, units: str) -> str:
    """The comment line written before a chain of curves (design §3b): `cycle_comment` naming
    the chain's curves."""
    return cycle_comment(first_index, name, n_points, period_s, method, cycle_s, length_mm,
                         units).replace(f"curve {first_index} ",
                                        f"curves {first_index}-{last_index} chained, ", 1)


def comment_line(text: str, semicolon: bool) -> str:
    """A comment "(text)" as written: unchanged, or "; text" for a program whose controller
    reads only ';' comments (Sinumerik)."""
    return f"; {text[1:-1]}" if semicolon else text
