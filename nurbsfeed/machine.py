"""Machine profile: the kinematic limits and output settings, loaded and validated from YAML.

Units live in the key names. "mm" means the program's length unit: an inch program converts the
profile once with `in_program_units` and from then on every length in nurbsfeed is in inches.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import yaml

from nurbsfeed.errors import Location, ProfileError

MM_PER_INCH = 25.4


@dataclass(frozen=True)
class Machine:
    """Limits of one machine (design §4). Every field is positive and finite."""

    period_s: float
    max_feed_mm_s: float
    chord_error_mm: float
    max_acc_mm_s2: float  # tangential
    max_jerk_mm_s3: float  # tangential
    max_normal_acc_mm_s2: float
    max_normal_jerk_mm_s3: float
    # the longest planned cycle of one curve that is converted: a longer one is refused (a
    # mistyped feed or period would otherwise step for hours)
    max_curve_time_s: float = 3600.0
    decimals: int = 4  # coordinate decimals in the output
    feed_decimals: int = 3  # F word decimals (more when F is small; see gcode.writer)

    def in_program_units(self, units: str) -> "Machine":
        """This profile with every length converted to `units` ("mm" or "in")."""
        if units == "mm":
            return self
        scale = 1.0 / MM_PER_INCH
        return dataclasses.replace(
            self,
            max_feed_mm_s=self.max_feed_mm_s * scale,
            chord_error_mm=self.chord_error_mm * scale,
            max_acc_mm_s2=self.max_acc_mm_s2 * scale,
            max_jerk_mm_s3=self.max_jerk_mm_s3 * scale,
            max_normal_acc_mm_s2=self.max_normal_acc_mm_s2 * scale,
            max_normal_jerk_mm_s3=self.max_normal_jerk_mm_s3 * scale,
            decimals=self.decimals + 1,
        )


FLOAT_KEYS = tuple(f.name for f in dataclasses.fields(Machine) if f.type == "float")
# keys a profile must give; the others have the Machine's default
REQUIRED_KEYS = tuple(f.name for f in dataclasses.fields(Machine)
                      if f.default is dataclasses.MISSING)
INT_KEYS = ("decimals", "feed_decimals")
INT_RANGES = {"decimals": (0, 8), "feed_decimals": (0, 6)}


def _check_value(key: str, value: Any) -> float | int:
    """One key's value, checked; ProfileError (without a place) when it is not valid."""
    if key in INT_KEYS:
        low, high = INT_RANGES[key]
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ProfileError(f"'{key}' must be a whole number from {low} to {high}, "
                               f"not {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProfileError(f"'{key}' must be a number, not {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise ProfileError(f"'{key}' must be positive and finite, not {value!r}")
    return float(value)


def machine_from_mapping(data: Any, where: str, places: Mapping[str, Location] | None = None,
                         overrides: Mapping[str, Any] | None = None) -> Machine:
    """Validate a parsed profile and apply CLI overrides.

    where: the profile's name for messages; places: the location of each key in the file.
    """
    places = places or {}
    here = Location(where)
    if not isinstance(data, dict):
        raise ProfileError("a machine profile is a mapping of keys to values, not "
                           f"{type(data).__name__}", here)
    known = set(FLOAT_KEYS) | set(INT_KEYS)
    for key in data:
        if key not in known:
            raise ProfileError(f"unknown key '{key}' (known keys: {', '.join(sorted(known))})",
                               places.get(key, here))
    values: dict[str, float | int] = {}
    for key in FLOAT_KEYS + INT_KEYS:
        if key in data:
            try:
                values[key] = _check_value(key, data[key])
            except ProfileError as exc:
                raise exc.at(places.get(key, here)) from None
        elif key in REQUIRED_KEYS:
            raise ProfileError(f"missing key '{key}'", here)
    for key, value in (overrides or {}).items():
        if value is not None:
            try:
                values[key] = _check_value(key, value)
            except ProfileError as exc:
                raise ProfileError(f"option --{key.replace('_', '-')}: {exc.message}") from None
    return Machine(**values)  # type: ignore[arg-type]


def builtin_profiles() -> list[str]:
    """Names accepted by `--machine NAME`."""
    folder = resources.files("nurbsfeed.configs")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


class _ProfileLoader(yaml.SafeLoader):
    """PyYAML's safe loader with two YAML 1.2 rules: `1e9` and `1.0e9` are floats (YAML 1.1's
    resolver wants a point and a signed exponent, and reads them as strings), and a key given
    twice in one mapping is an error (PyYAML keeps the last silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if not isinstance(key, (str, int, float, bool)):
                continue  # an unhashable key: SafeLoader's own message
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key '{key}' appears twice", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


_ProfileLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


def _key_places(text: str, where: str) -> dict[str, Location]:
    """Line and column of each top-level key, from the YAML node tree."""
    node = yaml.compose(text)
    if not isinstance(node, yaml.MappingNode):
        return {}
    return {str(k.value): Location(where, k.start_mark.line + 1, k.start_mark.column + 1)
            for k, _ in node.value}


def load_machine(name_or_path: str, overrides: Mapping[str, Any] | None = None) -> Machine:
    """A profile by built-in name (`default`, `paper-table1`) or by path to a YAML file."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.exists():
        where = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) else "not UTF-8 text"
            raise ProfileError(f"cannot read machine profile ({reason})",
                               Location(where)) from None
    else:
        if name_or_path not in builtin_profiles():
            raise ProfileError(f"unknown machine '{name_or_path}': give a YAML file or one of "
                               f"{', '.join(builtin_profiles())}")
        where = f"{name_or_path}.yaml"
        text = (resources.files("nurbsfeed.configs") / where).read_text(encoding="utf-8")
    try:
        data = yaml.load(text, Loader=_ProfileLoader)  # a SafeLoader subclass
        places = _key_places(text, where)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        loc = Location(where, mark.line + 1, mark.column + 1) if mark else Location(where)
        raise ProfileError(f"not valid YAML ({getattr(exc, 'problem', exc)})", loc) from None
    return machine_from_mapping(data, where, places, overrides)
