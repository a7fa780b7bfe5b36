"""JSON curves (design §4) read as a complete program: header, units, a rapid to each curve start.

Streamed: the file is decoded piece by piece and the curves of `"curves": [...]` one at a time
(`json.JSONDecoder.raw_decode` on a window of the text that grows only while a value is
unfinished), so memory holds one curve, not the file. The file is read twice: the header names
the number of curves and the units, and "units" may come after "curves"; the first read also
finds every syntax error before anything is yielded. A single curve object at top level is read
whole (it is one curve).

Errors point at the value or key at fault: json reports positions of syntax errors only, so a
field is located by its key inside its own curve's text (readers.json_text, which also refuses
what is not UTF-8 and nesting deeper than the decoder follows). Numbers a double cannot hold
(1e400, an integer of thousands of digits: json would read inf, or fail without a position) are
refused here, at the first of them.
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
from nurbsfeed.files import InputFile
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem
from nurbsfeed.readers.json_text import JsonText

CURVE_KEYS = {"name", "degree", "knots", "control_points", "weights", "feed"}
FILE_KEYS = {"units", "curves"}  # a file of curves (a single curve object: CURVE_KEYS, units)
_NUMBER = re.compile(r"-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?")
_NUMBER_TYPES = {int, float}  # json's numbers (not bool: a subclass of int, written true)
_LARGEST_DOUBLE = sys.float_info.max
_LIST = object()  # the value of a "curves" list, whose elements are read one at a time


@dataclass(frozen=True)
class _Curve:
    """One curve object as read: its index and value, and where its keys are written: in
    text.window[start:end] (a curve of "curves", read whole), or in `keys` (a single curve object
    at top level, whose members come one by one; "" is where it starts)."""

    index: int
    raw: Any
    text: JsonText
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


def _events(text: JsonText) -> Iterator[tuple[str, Any, int] | _Curve]:
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


def _curve_elements(text: JsonText) -> Iterator[_Curve]:
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
    text = JsonText(source)
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
    text = JsonText(source)
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
