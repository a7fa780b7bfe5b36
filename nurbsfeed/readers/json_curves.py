"""JSON curves (design §4) read as a complete program: header, units, a rapid to each curve start.

Streamed: the file is decoded piece by piece and the curves of `"curves": [...]` one at a time
(`json.JSONDecoder.raw_decode` on a window of the text that grows only while a value is
unfinished), so memory holds one curve, not the file. The file is read twice: the header names
the number of curves and the units, and "units" may come after "curves"; the first read also
finds every syntax error before anything is yielded. A single curve object at top level is read
whole (it is one curve).

Errors point at the value or key at fault: json reports positions of syntax errors only, so a
field is located by its key inside its own curve's text. A JSON file is UTF-8 (RFC 8259): any
other byte is refused where it is, as are numbers a double cannot hold (1e400, an integer of
thousands of digits: json would read inf, or fail without a position) and nesting deeper than
the decoder follows.
"""

from __future__ import annotations

import itertools
import json
import math
import re
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nurbsfeed.errors import CurveError, InputError, Location
from nurbsfeed.files import BOM, InputFile
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem

CURVE_KEYS = {"name", "degree", "knots", "control_points", "weights", "feed"}
FILE_KEYS = {"units", "curves"}  # a file of curves (a single curve object: CURVE_KEYS, units)
PIECE_BYTES = 1 << 16  # read at a time; the window grows past it only for a longer value
_WHITESPACE = " \t\n\r"
# the end of the window a value reaching it may continue past (a number, an escape, a literal)
_CUT_MARGIN = 16
_NUMBER = re.compile(r"-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?")
_LONG_INTEGER = re.compile(r"[0-9]{4300,}")  # int() refuses more digits (sys.int_info)
_NUMBER_TYPES = {int, float}  # json's numbers (not bool: a subclass of int, written true)
_LARGEST_DOUBLE = sys.float_info.max
_NESTING = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]')


class _NonStandardNumber(ValueError):
    def __init__(self, name: str) -> None:
        super().__init__(f"{name} is not a number JSON allows")
        self.name = name


def _reject_constants(name: str) -> Any:
    raise _NonStandardNumber(name)


_DECODER = json.JSONDecoder(parse_constant=_reject_constants)
_LIST = object()  # the value of a "curves" list, whose elements are read one at a time


class _JsonText:
    """A JSON file decoded piece by piece: a window of its text from the value being read on,
    and where each of its characters is in the file."""

    def __init__(self, source: InputFile) -> None:
        self.path = str(source.path)
        self.pieces = source.chunks(PIECE_BYTES)
        self.window = ""
        self.pos = 0  # the next character to read, in the window
        self.line = 1  # the line of window[0] ...
        self.col0 = 0  # ... and its 0-based column
        self.counted = (0, 0)  # (a window index, the newlines before it): locations go forward
        self.undecoded = b""  # the start of a character a piece ended in
        self.ended = False
        self.started = False

    # ---- the window -------------------------------------------------------------------------
    def _more(self) -> bool:
        """Append the next piece to the window; False at the end of the file."""
        piece = next(self.pieces, None)
        if piece is None:
            self.ended = True
            if self.undecoded:
                self._decode(self.undecoded)
            self.undecoded = b""
            return False
        data = self.undecoded + piece
        cut = _complete_utf8(data)
        self.undecoded = data[cut:]
        self._decode(data[:cut])
        return True

    def _decode(self, data: bytes) -> None:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            self.window += data[:exc.start].decode("utf-8")
            raise InputError(f"not UTF-8: byte 0x{data[exc.start]:02X} (a JSON file is UTF-8)",
                             self.location(len(self.window))) from None
        if not self.started:
            self.started = True
            text = text.removeprefix(BOM)  # json refuses it; positions count from after it
        self.window += text

    def release(self) -> None:
        """Forget the text before the read position (what has been read is not looked at)."""
        if self.pos < PIECE_BYTES:
            return
        done = self.window[:self.pos]
        newlines = done.count("\n")
        if newlines:
            self.line += newlines
            self.col0 = self.pos - (done.rfind("\n") + 1)
        else:
            self.col0 += self.pos
        self.window = self.window[self.pos:]
        self.pos = 0
        self.counted = (0, 0)

    def location(self, at: int) -> Location:
        """FILE:LINE:COL of window[at]."""
        newline = self.window.rfind("\n", 0, at)
        col = at - newline if newline >= 0 else self.col0 + at + 1
        since, newlines = self.counted if self.counted[0] <= at else (0, 0)
        newlines += self.window.count("\n", since, at)
        self.counted = (at, newlines)
        return Location(self.path, self.line + newlines, col)

    # ---- reading ----------------------------------------------------------------------------
    def next_char(self) -> str:
        """The next character that is not whitespace ("" at the end), left to be read."""
        while True:
            while self.pos < len(self.window) and self.window[self.pos] in _WHITESPACE:
                self.pos += 1
            if self.pos < len(self.window) or not self._more():
                return self.window[self.pos:self.pos + 1]

    def expect(self, chars: str, what: str) -> str:
        """Read the next character, one of `chars`, else refuse the file with json's `what`."""
        char = self.next_char()
        if not char or char not in chars:
            raise InputError(f"not valid JSON: {what}", self.location(self.pos))
        self.pos += 1
        return char

    def value(self) -> tuple[Any, int, int]:
        """Decode the next value: (value, its start and end in the window)."""
        self.next_char()
        start = self.pos
        while True:
            try:
                value, end = _DECODER.raw_decode(self.window, start)
            except json.JSONDecodeError as exc:
                if self._continues(exc):
                    continue
                raise InputError(f"not valid JSON: {exc.msg}", self.location(exc.pos)) from None
            except _NonStandardNumber as exc:
                found = self.window.find(exc.name, start)
                raise InputError(f"not valid JSON: {exc}",
                                 self.location(found if found >= 0 else start)) from None
            except RecursionError:
                raise InputError("nested deeper than nurbsfeed reads JSON (a curve needs 2 "
                                 "levels of lists)", self.location(self._too_deep(start))) from None
            except ValueError:  # an integer too long for int(): json gives no position
                digits = _LONG_INTEGER.search(self.window, start)
                raise InputError("an integer of more than 4300 digits is out of range",
                                 self.location(digits.start() if digits else start)) from None
            if end < len(self.window) - _CUT_MARGIN or self.ended or not self._grow():
                self.pos = end
                return value, start, end

    def _continues(self, exc: json.JSONDecodeError) -> bool:
        """Whether the value may only be cut by the window's end: then the window grew."""
        near_end = exc.pos >= len(self.window) - _CUT_MARGIN
        return (near_end or exc.msg.startswith("Unterminated string")) and self._grow()

    def _grow(self) -> bool:
        """Double the unread part of the window (a value longer than a piece is read in
        O(its length)); False at the end of the file."""
        wanted = len(self.window) - self.pos
        grew = False
        while len(self.window) - self.pos < 2 * wanted and self._more():
            grew = True
        return grew

    def _too_deep(self, start: int) -> int:
        """Where the nesting of the value at `start` passes the depth json follows."""
        depth = 0
        limit = 900  # below the interpreter's recursion limit, where the decoder stopped
        for match in _NESTING.finditer(self.window, start):
            depth += {"[": 1, "{": 1, "]": -1, "}": -1}.get(match.group(), 0)
            if depth > limit:
                return match.start()
        return start

    def key_location(self, key: str, start: int, end: int) -> Location:
        """Where `"key"` is written in window[start:end] (the value there), else its start."""
        found = self.window.find(f'"{key}"', start, end)
        return self.location(found if found >= 0 else start)


def _complete_utf8(data: bytes) -> int:
    """The length of `data` without the start of a UTF-8 character it may end in."""
    for back in range(1, min(4, len(data)) + 1):
        byte = data[-back]
        if byte < 0x80:
            return len(data)
        if byte >= 0xC0:  # a lead byte: does its character fit?
            size = 2 if byte < 0xE0 else 3 if byte < 0xF0 else 4
            return len(data) if size <= back else len(data) - back
    return len(data)


@dataclass(frozen=True)
class _Curve:
    """One curve object as read: its index and value, and where its keys are written: in
    text.window[start:end] (a curve of "curves", read whole), or in `keys` (a single curve object
    at top level, whose members come one by one; "" is where it starts)."""

    index: int
    raw: Any
    text: _JsonText
    start: int = 0
    end: int = 0
    keys: dict[str, Location] | None = None

    def at(self, key: str) -> Location:
        """Where `"key"` is written, else ("" too) where the object starts."""
        if self.keys is not None:
            return self.keys.get(key or "{", self.keys["{"])
        if not key:
            return self.text.location(self.start)
        return self.text.key_location(key, self.start, self.end)

    def out_of_range(self, key: str) -> Location:
        """Where the first number of the object that a double cannot hold is written (at its
        key in a single curve object)."""
        if self.keys is None:
            for match in _NUMBER.finditer(self.text.window, self.start, self.end):
                if math.isinf(float(match.group())):
                    return self.text.location(match.start())
        return self.at(key)


def _events(text: _JsonText) -> Iterator[tuple[str, Any, int] | _Curve]:
    """The top-level object, member by member: ("{", None, where it starts), then (key, value,
    key position) for every key (the value of a "curves" list is _LIST, and its elements come
    next, one by one, as _Curve), then ("", None, where it ends)."""
    if text.next_char() != "{":
        if not text.next_char():
            text.expect("{", "Expecting value")
        text.value()  # a syntax error first, as json.loads reports it
        raise InputError("expected a JSON object with 'curves' (or a single curve object)",
                         text.location(0))
    yield "{", None, text.pos
    text.pos += 1
    seen: set[str] = set()
    if text.next_char() == "}":
        text.pos += 1
    else:
        while True:
            if text.next_char() != '"':
                text.expect('"', "Expecting property name enclosed in double quotes")
            key, at, _ = text.value()
            if key in seen:  # json.loads would keep the last silently
                raise InputError(f"{_shown(key, repr)} appears twice", text.location(at))
            seen.add(key)
            text.expect(":", "Expecting ':' delimiter")
            if key == "curves" and text.next_char() == "[":
                yield key, _LIST, at
                yield from _curve_elements(text)
            else:
                value, _, _ = text.value()
                yield key, value, at
            text.release()
            if text.expect(",}", "Expecting ',' delimiter") == "}":
                break
    end = text.pos - 1
    if text.next_char():
        raise InputError("not valid JSON: Extra data", text.location(text.pos))
    yield "", None, end


def _curve_elements(text: _JsonText) -> Iterator[_Curve]:
    text.pos += 1  # "["
    if text.next_char() == "]":
        text.pos += 1
        return
    index = 0
    while True:
        text.release()
        raw, start, end = text.value()
        yield _Curve(index, raw, text, start, end)
        index += 1
        if text.expect(",]", "Expecting ',' delimiter") == "]":
            return


@dataclass(frozen=True)
class _Survey:
    """What the first read finds: the units and the number of curves."""

    units: str
    n_curves: int


def _survey(source: InputFile) -> _Survey:
    """Read the whole file once for its syntax, units and number of curves."""
    text = _JsonText(source)
    units: Any = "mm"
    curves: Any = None
    top_at: dict[str, Location] = {}  # where each key is
    n_curves = 0
    for event in _events(text):
        if isinstance(event, _Curve):
            n_curves += 1
            continue
        key, value, at = event
        if key not in ("{", ""):
            top_at[key] = text.location(at)
        if key == "units":
            units = value
        elif key == "curves":
            curves = value
    if units not in ("mm", "in"):
        raise InputError(f"'units' must be \"mm\" or \"in\", not {_shown(units, repr)}",
                         top_at["units"])
    if "curves" in top_at:  # (a single curve object's keys are checked as curves[0]'s)
        unknown = sorted(set(top_at) - FILE_KEYS)
        if unknown:
            raise InputError(f"unknown key {_shown(unknown[0], repr)} (known: curves, units)",
                             top_at[unknown[0]])
        if curves is not _LIST or not n_curves:
            raise InputError("'curves' must be a non-empty list of curve objects",
                             top_at["curves"])
    return _Survey(units, max(n_curves, 1))


def json_program(source: InputFile) -> Iterator[ProgramItem]:
    """The JSON file as a program stream: header lines, then per curve a CurveBlock that asks
    for a rapid to its start (the writer writes the G0), then M2."""
    path = source.path
    survey = _survey(source)
    count = f"{survey.n_curves} curve" + ("" if survey.n_curves == 1 else "s")  # no "(s)"
    yield PassThrough(f"(nurbsfeed: {count} from {comment_safe(path.name)})\n")  # nests none
    yield PassThrough(("G21" if survey.units == "mm" else "G20") + " G90\n")
    for curve, feed_mm_s, location in _curves(source):
        yield CurveBlock(curve=curve, location=location, units=survey.units,
                         rapid_to_start=True,
                         feed_u=np.array([curve.u_min]), feed_mm_s=np.array([feed_mm_s]))
    yield PassThrough("M2\n")


def read_json_curves(path: Path) -> tuple[str, list[tuple[NurbsCurve, float]]]:
    """The whole file, checked: (units, [(curve, feed_mm_s or inf)])."""
    source = InputFile(path)
    return _survey(source).units, [(curve, feed) for curve, feed, _ in _curves(source)]


def _curves(source: InputFile) -> Iterator[tuple[NurbsCurve, float, Location]]:
    """Every curve, checked: (curve, feed_mm_s or inf, where its "degree" is)."""
    text = _JsonText(source)
    single: dict[str, Any] = {}  # the members of a single curve object at top level
    keys: dict[str, Location] = {}
    for event in _events(text):
        if isinstance(event, _Curve):
            yield _checked(event)
            continue
        key, value, at = event
        keys[key] = text.location(at)
        if key == "" and "curves" not in keys:
            yield _checked(_Curve(0, single, text, keys=keys))
        elif key not in ("{", "", "units"):
            single[key] = value


def _checked(item: _Curve) -> tuple[NurbsCurve, float, Location]:
    """The curve object `item` checked field by field: (curve, feed_mm_s or inf, its place)."""
    i, raw = item.index, item.raw
    if not isinstance(raw, dict):
        raise InputError(f"curves[{i}] must be an object", item.at(""))
    unknown = sorted(set(raw) - CURVE_KEYS)
    if unknown:
        raise InputError(f"curves[{i}]: unknown key {_shown(unknown[0], repr)} (known: "
                         f"{', '.join(sorted(CURVE_KEYS))})", item.at(unknown[0]))
    for key in ("degree", "knots", "control_points"):
        if key not in raw:
            raise InputError(f"curves[{i}]: missing '{key}'",
                             item.at("degree" if key != "degree" else "knots"))
    for key, value in raw.items():
        if _out_of_range(value):
            raise InputError(f"curves[{i}]: '{key}' holds a number out of range (a double "
                             f"holds magnitudes up to {_LARGEST_DOUBLE:.4g})",
                             item.out_of_range(key))
    for key in ("knots", "control_points", "weights"):
        wrong = _not_number(raw[key], key) if raw.get(key) is not None else None
        if wrong is not None:
            raise InputError(f"curves[{i}]: {wrong}", item.at(key))
    name = raw.get("name", f"curve{i}")
    if isinstance(name, (list, dict)):
        raise InputError(f"curves[{i}]: 'name' must be a string, not {_kind(name)}",
                         item.at("name"))
    try:
        curve = NurbsCurve.build(raw["degree"], raw["knots"], raw["control_points"],
                                 raw.get("weights"), comment_safe(str(name)))
    except CurveError as exc:
        raise CurveError(f"curves[{i}]: {exc.message}", item.at(_field_of(exc.message))) from None
    feed = raw.get("feed")
    if feed is None:
        feed_mm_s = math.inf
    elif not _is_number(feed) or feed <= 0:
        raise InputError(f"curves[{i}]: 'feed' must be a positive number (length/min), "
                         f"not {_shown(feed, repr)}", item.at("feed"))
    else:
        feed_mm_s = feed / 60.0
    return curve, feed_mm_s, item.at("degree")


def _is_number(value: Any) -> bool:
    """A JSON number: int or float, never a bool (json reads true as True, an int subclass)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _nested(value: Any) -> Iterator[tuple[Any, str]]:
    """`value` and everything inside its lists and objects, depth first, each with its path
    ("[2][0]"), iteratively: JSON may nest deeper than a recursion goes."""
    stack = [(value, "")]
    while stack:
        item, at = stack.pop()
        yield item, at
        if isinstance(item, list):
            stack.extend((item[j], f"{at}[{j}]") for j in range(len(item) - 1, -1, -1))
        elif isinstance(item, dict):
            stack.extend((sub, f"{at}.{key}") for key, sub in reversed(item.items()))


def _plain_numbers(value: Any) -> list[int | float] | None:
    """The numbers of `value` where it is a list of numbers or a list of lists of numbers (a
    curve's fields), else None. Checked by type in C: a curve holds thousands of numbers."""
    if not isinstance(value, list):
        return None
    types = set(map(type, value))
    if types <= _NUMBER_TYPES:
        return value
    if types == {list}:
        flat = list(itertools.chain.from_iterable(value))
        if set(map(type, flat)) <= _NUMBER_TYPES:
            return flat
    return None


def _out_of_range(value: Any) -> bool:
    """Whether `value` holds a number beyond what a double holds: json reads a float with too
    large an exponent as inf (JSON has no infinity) and keeps an integer as long as written."""
    numbers = _plain_numbers(value)
    if numbers is None:
        numbers = [item for item, _ in _nested(value) if _is_number(item)]
    return bool(numbers) and max(map(abs, numbers)) > _LARGEST_DOUBLE


def _not_number(value: Any, at: str) -> str | None:
    """Where `value` (a number, or nested lists of them) holds something else, and what."""
    if _plain_numbers(value) is not None:
        return None
    for item, path in _nested(value):
        if isinstance(item, list) or _is_number(item):
            continue
        if item is None:
            return f"{at}{path} must be a number, not null"
        return f"{at}{path} must be a number, not {_shown(item)} ({_kind(item)})"
    return None


def _kind(value: Any) -> str:
    return {str: "a string", bool: "a boolean", list: "a list"}.get(type(value), "an object")


def _shown(value: Any, dump: Callable[[Any], str] = json.dumps, limit: int = 60) -> str:
    """`value` for a message, as `dump` writes it: escaped (no raw control character or lone
    surrogate reaches the terminal), cut at `limit` characters, never failing on deep nesting."""
    try:
        shown = dump(value)
    except (RecursionError, ValueError):
        shown = "[...]" if isinstance(value, list) else "{...}"
    return shown if len(shown) <= limit else shown[:limit - 3] + "..."


def _field_of(message: str) -> str:
    for word, key in (("weight", "weights"), ("knot", "knots"), ("degree", "degree"),
                      ("control point", "control_points")):
        if word in message:
            return key
    return "control_points"


def comment_safe(text: str) -> str:
    """`text` fit to sit inside a G-code comment "( ... )": parentheses become brackets (one ")"
    would end the comment early, and nurbsfeed itself refuses an unclosed "("), and line breaks,
    other control characters and anything unprintable (undecodable bytes) become "?"."""
    return "".join("[" if ch == "(" else "]" if ch == ")" else ch if ch.isprintable() else "?"
                   for ch in text)
