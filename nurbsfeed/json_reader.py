"""JSON curves (design §4) read as a complete program: header, units, a rapid to each curve start.

Semantic errors point at the key of the offending field in the file (the i-th occurrence of
`"weights"` for curve i), since json does not report positions of values.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from nurbsfeed.errors import CurveError, InputError, Location
from nurbsfeed.gcode.writer import format_number
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem

CURVE_KEYS = {"name", "degree", "knots", "control_points", "weights", "feed"}
FILE_KEYS = {"units", "curves"}  # a file of curves (a single curve object: CURVE_KEYS, units)


def _is_number(value: Any) -> bool:
    """A JSON number: int or float, never a bool (json reads true as True, an int subclass)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _not_number(value: Any, at: str) -> str | None:
    """Where `value` (a number, or nested lists of them) holds something else, and what."""
    if isinstance(value, list):
        for j, item in enumerate(value):
            found = _not_number(item, f"{at}[{j}]")
            if found is not None:
                return found
        return None
    if _is_number(value):
        return None
    if value is None:
        return f"{at} must be a number, not null"
    kind = {str: "a string", bool: "a boolean"}.get(type(value), "an object")
    return f"{at} must be a number, not {json.dumps(value)} ({kind})"


def _key_location(text: str, path: str, key: str, occurrence: int) -> Location:
    """Line and column of the `occurrence`-th `"key"` in text (first one if there are fewer)."""
    hits = [m.start() for m in re.finditer(re.escape(f'"{key}"'), text)]
    if not hits:
        return Location(path, 1, 1)
    return _text_location(text, path, hits[min(occurrence, len(hits) - 1)])


class _NonStandardNumber(ValueError):
    def __init__(self, name: str) -> None:
        super().__init__(f"{name} is not a number JSON allows")
        self.name = name


def _reject_constants(name: str) -> Any:
    raise _NonStandardNumber(name)


def _text_location(text: str, path: str, pos: int) -> Location:
    line = text.count("\n", 0, pos) + 1
    return Location(path, line, pos - (text.rfind("\n", 0, pos) + 1) + 1)


def read_json_curves(path: Path, text: str) -> tuple[str, list[tuple[NurbsCurve, float]]]:
    """Parse and validate: (units, [(curve, feed_mm_s or inf)])."""
    where = str(path)
    text = text.removeprefix("\ufeff")  # a UTF-8 BOM (json.loads refuses it)
    try:
        data = json.loads(text, parse_constant=_reject_constants)
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc.msg}",
                         Location(where, exc.lineno, exc.colno)) from None
    except _NonStandardNumber as exc:
        raise InputError(f"not valid JSON: {exc}",
                         _text_location(text, where, max(text.find(exc.name), 0))) from None
    if not isinstance(data, dict):
        raise InputError("expected a JSON object with 'curves' (or a single curve object)",
                         Location(where, 1, 1))
    units = data.get("units", "mm")
    if units not in ("mm", "in"):
        raise InputError(f"'units' must be \"mm\" or \"in\", not {units!r}",
                         _key_location(text, where, "units", 0))
    unknown_top = sorted(set(data) - FILE_KEYS) if "curves" in data else []
    if unknown_top:  # (a single curve object's keys are checked as curves[0]'s)
        raise InputError(f"unknown key '{unknown_top[0]}' (known: curves, units)",
                         _key_location(text, where, unknown_top[0], 0))
    raw_curves = data["curves"] if "curves" in data else [data]
    if not isinstance(raw_curves, list) or not raw_curves:
        raise InputError("'curves' must be a non-empty list of curve objects",
                         _key_location(text, where, "curves", 0))
    curves = []
    for i, raw in enumerate(raw_curves):
        if not isinstance(raw, dict):
            raise InputError(f"curves[{i}] must be an object", _key_location(text, where,
                                                                            "curves", 0))
        unknown = sorted(set(raw) - CURVE_KEYS)
        if unknown:
            raise InputError(f"curves[{i}]: unknown key '{unknown[0]}' (known: "
                             f"{', '.join(sorted(CURVE_KEYS))})",
                             _key_location(text, where, unknown[0], 0))
        for key in ("degree", "knots", "control_points"):
            if key not in raw:
                raise InputError(f"curves[{i}]: missing '{key}'",
                                 _key_location(text, where, "degree" if key != "degree"
                                               else "knots", i))
        for key in ("knots", "control_points", "weights"):
            wrong = _not_number(raw[key], key) if raw.get(key) is not None else None
            if wrong is not None:
                raise InputError(f"curves[{i}]: {wrong}", _key_location(text, where, key, i))
        try:
            curve = NurbsCurve.build(raw["degree"], raw["knots"], raw["control_points"],
                                     raw.get("weights"),
                                     comment_safe(str(raw.get("name", f"curve{i}"))))
        except CurveError as exc:
            field = _field_of(exc.message)
            raise CurveError(f"curves[{i}]: {exc.message}",
                             _key_location(text, where, field, i)) from None
        feed = raw.get("feed")
        if feed is None:
            feed_mm_s = math.inf
        elif (isinstance(feed, bool) or not isinstance(feed, (int, float))
              or not math.isfinite(feed) or feed <= 0):
            raise InputError(f"curves[{i}]: 'feed' must be a positive number (length/min), "
                             f"not {feed!r}", _key_location(text, where, "feed", i))
        else:
            feed_mm_s = feed / 60.0
        curves.append((curve, feed_mm_s))
    return units, curves


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


def json_program(path: Path, text: str, decimals: int = 4) -> Iterator[ProgramItem]:
    """The JSON file as a program stream: header lines, then per curve a G0 and the curve."""
    text = text.removeprefix("\ufeff")
    units, curves = read_json_curves(path, text)
    count = f"{len(curves)} curve" + ("" if len(curves) == 1 else "s")  # no "(s)": a comment
    yield PassThrough(f"(nurbsfeed: {count} from {comment_safe(path.name)})\n")  # nests none
    yield PassThrough(("G21" if units == "mm" else "G20") + " G90\n")
    for i, (curve, feed_mm_s) in enumerate(curves):
        start = curve.points[0]
        yield PassThrough("G0 " + " ".join(f"{axis}{format_number(v, decimals)}"
                                           for axis, v in zip("XYZ", start)) + "\n")
        yield CurveBlock(curve=curve, location=_key_location(text, str(path), "degree", i),
                         units=units,
                         feed_u=np.array([curve.u_min]), feed_mm_s=np.array([feed_mm_s]))
    yield PassThrough("M2\n")
