"""Siemens Sinumerik programs: their line syntax, and BSPLINE, the modal B spline.

    G1 X_ Y_ Z_ F_                         the current position: the first control point
    BSPLINE [SD=2|3] [X_ Y_ Z_] [PW=_] [PL=_]  B spline on; a point here is a control point
    X_ Y_ Z_ [PW=_] [PL=_]                 one block per further control point
    G1 X_ ...                              another motion command ends the spline

References: SINUMERIK 840D sl / 828D Programming Manual, Job planning (6FC5398-2BP40-0BA0,
07/2010, §4.2; 6FC5398-2EP40-0BA0, 12/2019, §3.7) "Spline interpolation (ASPLINE, BSPLINE,
CSPLINE, BAUTO, BNAT, BTAN, EAUTO, ENAT, ETAN, PW, SD, PL)":

- BSPLINE is modal, a motion command of group 1; the programmed positions are control points
  ("check points"), not points of the curve. The curve starts at the current position and ends
  at the last control point, tangent to the control polygon at both ("The B spline is always
  tangential to the check polygon at its start and end points"): a clamped B-spline. It ends at
  the next motion command (G0 G1 G2 G3 ...), at the program end (M2 M17 M30) or the file's end;
  a BSPLINE programmed again inside it is refused (continue or restart: the manual does not say).
- SD: the degree, 3 unless SD=2 is programmed (on the BSPLINE block; any other value is refused).
- PW: the point weight of the control point in the same block, 0 <= PW <= 3 (the manual's
  range), 1 if omitted; PW=0 is refused here (the curve would not be a NURBS). The start point
  weighs 1.
- PL: "parameter interval length", the knot intervals. The manual says the intervals are
  "suitably calculated internally" when PL is omitted and publishes no rule: a spline without PL
  on every control point is refused, since the path the controller would cut is not known.
  nurbsfeed reads the PL values in program order as the spans of the clamped knot vector: with
  control points P0 (the start) .. Pn and degree p, the knots are p + 1 zeros, the running sums
  of the PL of P1 .. P(n-p), and p + 1 copies of the sum of the PL of P1 .. P(n-p+1); the PL of
  the last p - 1 points have no span left and are not used. (Equal PL give the uniform vector
  whatever the reading.)
- Units: G71 / G710 mm, G700 inch (F in inch/min too). Under G70 lengths are in inch but F stays
  in the machine's basic unit (machine data), which the program does not say: a BSPLINE under
  G70 is refused.
- Not supported, refused at the word: ASPLINE, CSPLINE, BAUTO, BNAT, BTAN, EAUTO, ENAT, ETAN,
  POLY; AC()/IC() and other expressions; R parameters.

The line syntax (`tokenize_siemens_line`): `;` comments, N and `:` block numbers, skip blocks
(`/`, read as executed, as everywhere in nurbsfeed), words as a letter
and a number with an optional `=` (`X10.5`, `X=10.5`), `SD=`, `PL=`, `PW=`, and the keywords and
calls that change no position, unit, distance mode or feed (SOFT, FFWON, G642 ..., `MSG(...)`,
`CYCLE832(...)`, `T="name"`). Anything else is refused at its column: a word the reader does not
understand may move the machine. G700/G710 read as G20/G21, G70/G71 too (the words keep their
text); the F and S of a G4 block are the dwell, not a feed.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

import numpy as np

from nurbsfeed.errors import CurveError, InputError, Location
from nurbsfeed.gcode.modal import AXES, AxisPos, FeedWord, ModalState
from nurbsfeed.gcode.nurbs_block import (
    FinishedCurve,
    build_curve,
    check_coordinates,
    count,
    curve_name,
    feed_steps,
    motion_words,
)
from nurbsfeed.gcode.tokenizer import Block, Word, decimals_written, printable, valid_code

SUFFIXES = (".mpf", ".spf")  # Sinumerik main programs and subprograms
BSPLINE = "BSPLINE"
DEFAULT_DEGREE = 3
MAX_WEIGHT = 3.0  # the manual's PW range
PROGRAM_ENDS = {20, 300, 170}  # M2 M30 M17 (M codes in tenths)
REFUSED = {
    "ASPLINE": "ASPLINE (Akima spline)", "CSPLINE": "CSPLINE (cubic spline)",
    "BAUTO": "BAUTO (A/C spline start)", "BNAT": "BNAT (A/C spline start)",
    "BTAN": "BTAN (A/C spline start)", "EAUTO": "EAUTO (A/C spline end)",
    "ENAT": "ENAT (A/C spline end)", "ETAN": "ETAN (A/C spline end)",
    "POLY": "POLY (polynomial interpolation)",
}
# keywords that change no position, unit, distance mode or programmed feed
INERT = frozenset({"SOFT", "BRISK", "DRIVE", "FFWON", "FFWOF", "FNORM", "CFC", "CFTCP", "CFIN",
                   "UPATH", "SPATH", "COMPOF", "COMPON", "COMPCURV", "COMPCAD", "SUPA"})
INERT_CALLS = frozenset({"MSG", "CYCLE832"})
SPLINE_WORDS = ("SD", "PL", "PW")
UNIT_CODES = {70: 20.0, 700: 20.0, 71: 21.0, 710: 21.0}  # as written -> G20 / G21

_SPACE = "[ \t\r]"
_NUMBER = re.compile(rf"{_SPACE}*(=)?{_SPACE}*([+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+))")
_IDENT = re.compile(r"[A-Za-z_][A-Za-z_]*[0-9]*")
_CALL = re.compile(rf"{_SPACE}*\(")
_STRING_T = re.compile(rf"T{_SPACE}*={_SPACE}*\"[^\"]*\"", re.IGNORECASE)


def tokenize_siemens_line(line_text: str, line: int, path: str) -> Block:
    """One Sinumerik line -> a Block of the words the reader executes (module docstring)."""
    if line_text.endswith("\n"):
        eol = "\r\n" if line_text.endswith("\r\n") else "\n"
        body = line_text[:-len(eol)]
    else:
        eol, body = "", line_text
    words: list[Word] = []
    pos = len(body) - len(body.lstrip(" \t\r"))
    block_delete = body[pos:pos + 1] == "/"  # a skip block "/" or "/1".."/9": read as executed
    if block_delete:
        pos += 2 if body[pos + 1:pos + 2].isdigit() else 1

    def error(message: str, at: int) -> InputError:
        return InputError(message, Location(path, line, at + 1))

    while pos < len(body):
        char = body[pos]
        if char in " \t\r":
            pos += 1
            continue
        if char == ";":
            break
        if char == "%" and not words and not body[:pos].strip():
            return Block(line, (), delimiter=True, eol=eol)
        if char == ":" and not words:  # main block number ":10"
            number = _NUMBER.match(body, pos + 1)
            if number is None:
                raise error("':' (main block number) has no number after it", pos)
            pos = number.end()
            continue
        text_t = _STRING_T.match(body, pos)
        if text_t:  # T="tool name": a tool selection, no move
            pos = text_t.end()
            continue
        ident = _IDENT.match(body, pos)
        if ident is None:
            raise error(f"unexpected character '{printable(char)}' (a Sinumerik word is an "
                        "address and a number, e.g. X10.5)", pos)
        name = ident.group().upper()
        if len(name) > 1 and not name[1:].isdigit() and name not in SPLINE_WORDS:
            pos = _keyword(body, pos, ident, name, line, words, error)
            continue
        letter = name[0] if name not in SPLINE_WORDS else name
        number = _NUMBER.match(body, pos + len(letter))
        if number is None:
            raise error(f"{letter} has no number after it (found "
                        f"'{printable(body[pos + len(letter):pos + len(letter) + 8])}'); "
                        f"expressions, AC(), IC() and R parameters are not supported: write "
                        f"e.g. {letter}=10.5", pos)
        if body[number.end():].lstrip(" \t\r").startswith("="):
            raise error(f"'{body[pos:number.end()].strip()}=' assigns an R parameter or a "
                        "variable; nurbsfeed reads literal Sinumerik programs only (no R "
                        "parameters, variables or expressions)", pos)
        text = number.group(2)
        value = float(text)
        if not math.isfinite(value):
            raise error(f"{letter}{text} is too large to be a number", pos)
        if letter in "GM" and not valid_code(value):
            raise error(f"{letter}{text} is not a valid {letter} code: a whole number or one "
                        "decimal from 0 to 10000", pos)
        if letter == "G" and round(value) in UNIT_CODES and value == round(value):
            value = UNIT_CODES[round(value)]
        words.append(Word(letter, value, text, decimals_written(text), line, pos + 1))
        pos = number.end()
    if any(word.letter == "G" and word.code == 40 for word in words):  # G4: F and S are the dwell
        words = [word for word in words if word.letter not in "FS"]
    return Block(line, tuple(words), block_delete=block_delete, eol=eol)


def _keyword(body: str, pos: int, ident: re.Match[str], name: str, line: int,
             words: list[Word], error: Callable[[str, int], InputError]) -> int:
    """Read a keyword or call at `pos`; BSPLINE becomes a word, the inert ones nothing."""
    end = ident.end()
    call = _CALL.match(body, end)
    if call:
        close = body.find(")", call.end())
        if name not in INERT_CALLS or close < 0:
            raise error(f"'{ident.group()}(...)' is not read by nurbsfeed (it reads "
                        f"{', '.join(sorted(INERT_CALLS))} calls, which change no position)", pos)
        return close + 1
    if name in REFUSED:
        raise error(f"{REFUSED[name]} is not supported: nurbsfeed reads BSPLINE, whose control "
                    "points and knots make a NURBS", pos)
    if name == BSPLINE:
        words.append(Word(BSPLINE, 0.0, "", None, line, pos + 1))
        return end
    if name in INERT:
        return end
    raise error(f"'{ident.group()}' is not a Sinumerik command nurbsfeed reads: it reads words "
                f"(X10.5, G1, F300), BSPLINE with SD, PL, PW, and {', '.join(sorted(INERT))}",
                pos)


class BsplineReader:
    """One BSPLINE read block by block: `ends_at` says when a block ends it (that block is then
    read as any other), `take` reads a control point."""

    def __init__(self, first: Block, state: ModalState, start: Word, g70: Word | None) -> None:
        self.state = state
        self.start = start
        self.location = state.where(start)
        self.name = curve_name(first, start)
        moves = motion_words(first)
        if moves:
            raise InputError(f"{moves[0].name} and BSPLINE are both motion commands; one per "
                             "block", state.where(moves[0]))
        if g70 is not None:
            raise InputError(f"BSPLINE under {g70.name} (line {g70.line}): F stays in the "
                             "machine's basic unit, which the program does not say; write G700 "
                             "(inch, F in inch/min) or G710", self.location)
        state.check_nurbs_allowed(start)
        self.origin = {axis: state.pos[axis] for axis in AXES}
        self.last = {axis: 0.0 if (value := state.pos[axis].value) is None else value
                     for axis in AXES}
        self.moved: dict[str, Word] = {}  # the first word that moves each axis
        self.points: list[tuple[float, float, float]] = [
            (self.last["X"], self.last["Y"], self.last["Z"])]
        self.point_lines = [start.line]
        self.weights = [1.0]
        self.intervals: list[Word | None] = []  # the PL of each control point after the start
        self.decimals = {axis: state.pos[axis].decimals for axis in AXES}
        degree = first.first("SD")
        self.degree = DEFAULT_DEGREE
        if degree is not None:
            if degree.value not in (2.0, 3.0):
                raise InputError(f"SD={degree.text}: the degree of a BSPLINE is 2 or 3 (SD=2, "
                                 "SD=3)", state.where(degree))
            self.degree = int(degree.value)
        feed = first.first("F")
        self.feed: FeedWord | None = state.feed if feed is None else state.feed_from(feed)
        self._point(first, "a BSPLINE block (N X Y Z SD PL PW F)", opening=True)

    def ends_at(self, block: Block) -> bool:
        """True when `block` ends the spline: another motion command, or the program's end."""
        return bool(motion_words(block)) or bool(block.codes("M").keys() & PROGRAM_ENDS)

    def take(self, block: Block) -> bool:
        """Read one control-point block (never the last: `ends_at` decides that)."""
        self._point(block, "a BSPLINE control point (N X Y Z PL PW)", opening=False)
        return False

    def _point(self, block: Block, what: str, opening: bool) -> None:
        """Check one block's words, then add its control point (if it has axis words)."""
        state = self.state
        allowed = POINT_WORDS | (OPENING_WORDS if opening else set())
        seen: set[str] = set()
        for word in block.words:
            if word.letter == BSPLINE and not opening:
                # whether a BSPLINE programmed again continues the spline or starts a new one
                # at this point is not in the manual: refused rather than guessed
                raise InputError(f"BSPLINE inside the BSPLINE started on line {self.start.line}: "
                                 "end that one with G1 (or another motion command) first",
                                 state.where(word))
            if word.letter in ("SD", "F") and not opening:
                where = "the BSPLINE block" if word.letter == "SD" else \
                    "the BSPLINE block or before it (nurbsfeed plans one feed per spline)"
                raise InputError(f"{_shown(word)} inside a BSPLINE: write it on {where}",
                                 state.where(word))
            if word.letter not in allowed:
                raise InputError(f"{_shown(word)} does not belong in {what}", state.where(word))
            if word.letter in seen:
                raise InputError(f"{word.letter} appears twice in one block", state.where(word))
            seen.add(word.letter)
        axes = {word.letter: word for word in block.words if word.letter in AXES}
        weight = block.first("PW")
        interval = block.first("PL")
        if not axes:
            extra = weight or interval
            if extra is not None and not opening:
                raise InputError(f"{_shown(extra)} without a control point (X Y Z)",
                                 state.where(extra))
            if extra is not None:
                raise InputError(f"{_shown(extra)} on a BSPLINE block without a control point: "
                                 "PW and PL belong to the point of their block",
                                 state.where(extra))
            return
        if weight is not None and not 0.0 < weight.value <= MAX_WEIGHT:
            raise CurveError(f"PW={weight.text}: a point weight is above 0 and at most "
                             f"{MAX_WEIGHT:g}", state.where(weight))
        if interval is not None and interval.value < 0.0:
            raise CurveError(f"PL={interval.text}: a parameter interval is not negative",
                             state.where(interval))
        for axis, word in axes.items():
            self.moved.setdefault(axis, word)
            self.decimals[axis] = word.decimals
            self.last[axis] = self.last[axis] + word.value if state.incremental else word.value
        self.points.append((self.last["X"], self.last["Y"], self.last["Z"]))
        self.point_lines.append(block.line)
        self.weights.append(1.0 if weight is None else weight.value)
        self.intervals.append(interval)

    def finish(self) -> FinishedCurve:
        state = self.state
        for axis, word in self.moved.items():
            state.known(axis, word, "BSPLINE starts at the current position; move there with G0 "
                                    "or G1 first")
        n = len(self.points) - 1
        if n < self.degree:
            raise CurveError(f"{count(len(self.points), 'control point')} too few for SD="
                             f"{self.degree}, counting the start point: a B spline of degree "
                             f"{self.degree} needs at least {self.degree + 1}", self.location)
        knots = self._knots(n)
        check_coordinates(self.points, self.point_lines, self.location)
        curve = build_curve(self.degree, knots, self.points, self.weights, self.name,
                            self.location)
        feed_u, feed_mm_s = feed_steps(curve, self.feed, [], state, self.location)
        end = {axis: AxisPos(self.points[-1][i], self.decimals[axis]) if axis in self.moved
               else self.origin[axis] for i, axis in enumerate(AXES)}
        return FinishedCurve(curve, self.location, feed_u, feed_mm_s, end, self.feed, 10)

    def _knots(self, n: int) -> list[float]:
        """The clamped knot vector from the PL values (module docstring)."""
        missing = [i for i, word in enumerate(self.intervals) if word is None]
        if missing:
            where = Location(self.state.path, self.point_lines[missing[0] + 1], 1)
            if len(missing) == n:
                raise InputError("BSPLINE without PL: the Sinumerik manual says the knot "
                                 "intervals are \"suitably calculated internally\" and does not "
                                 "publish the rule, so the path the controller cuts is not known; "
                                 "write PL= on every control point (as NX's Sinumerik post does)",
                                 self.location)
            raise InputError("control point without PL in a BSPLINE whose other points have "
                             "one: write PL= on every control point", where)
        p = self.degree
        spans = [word.value for word in self.intervals[:n - p + 1] if word is not None]
        zero = next((i for i, value in enumerate(spans) if value <= 0.0), None)
        if zero is not None:
            word = self.intervals[zero]
            assert word is not None, "every interval is given (checked above)"
            raise CurveError(f"PL={word.text}: the parameter interval of a span must be above 0",
                             self.state.where(word))
        sums = np.cumsum(spans).tolist()
        return [0.0] * (p + 1) + sums[:-1] + [sums[-1]] * (p + 1)


POINT_WORDS = frozenset({"N", "X", "Y", "Z", "PL", "PW"})
OPENING_WORDS = frozenset({BSPLINE, "SD", "F"})


def _shown(word: Word) -> str:
    """A word as written in a Sinumerik program: "PL=0.5", "X10.", "BSPLINE"."""
    if word.letter == BSPLINE:
        return BSPLINE
    return f"{word.letter}={word.text}" if word.letter in SPLINE_WORDS else word.name
