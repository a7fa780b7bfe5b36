"""The profile a program was converted under, recorded in the program itself (design §5).

Written once per program, just before the first curve's comment line, as comment lines the
controller skips (parentheses: Fanuc, LinuxCNC and the other dialects read them as comments;
"; nurbsfeed profile: ..." in a Sinumerik program, whose comments are ';'):

    (nurbsfeed profile: name default, nurbsfeed 0.1.0, jerk_model path, planner scurve)
    (nurbsfeed profile: period_s 0.001, max_feed_mm_s 200.0, chord_error_mm 0.001)
    ...

Every profile key is there with its value in force (Machine.profile), floats in Python's
shortest round-trip form, so that the lines load back, through the profile's own checks, into
the very machine the program was made with. They are new lines, never a change to a line of
the input, and sit after a program's `%` and O number, where both controllers expect them first.
A line stays below RECORD_WIDTH characters (LinuxCNC reads 255 at most, some Fanuc settings
fewer). The name is the profile's (a built-in name, or a YAML file's name without its folder),
kept to NAME_WIDTH characters that every controller takes in a comment.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import PurePath

from nurbsfeed import __version__
from nurbsfeed.errors import Location, ProfileError
from nurbsfeed.machine import Machine, machine_from_mapping

RECORD_START = "(nurbsfeed profile: "
SEMICOLON_START = "; nurbsfeed profile: "  # the same line in a Sinumerik program
RECORD_WIDTH = 100
NAME_WIDTH = 60
_NAME_UNSAFE = re.compile(r"[^A-Za-z0-9._/+-]")
_PAIR = re.compile(r"([a-z][a-z0-9_]*) (\S+)")


def record_lines(machine: Machine) -> list[str]:
    """The record of `machine`'s profile: comment lines, without line endings."""
    name = _NAME_UNSAFE.sub("_", PurePath(machine.name).name)[:NAME_WIDTH] or "_"
    pairs = [f"name {name}", f"nurbsfeed {__version__}"]
    pairs += [f"{key} {value!r}" if isinstance(value, float) else f"{key} {value}"
              for key, value in machine.profile]
    lines: list[str] = []
    current: list[str] = []
    for pair in pairs:
        if current and len(RECORD_START + ", ".join(current + [pair]) + ")") > RECORD_WIDTH:
            lines.append(RECORD_START + ", ".join(current) + ")")
            current = []
        current.append(pair)
    lines.append(RECORD_START + ", ".join(current) + ")")
    return lines


class Recorded:
    """A profile record read from a program: the machine it loads into, its name, the version
    that wrote it, and where it starts."""

    def __init__(self, machine: Machine, name: str, version: str, location: Location) -> None:
        self.machine, self.name, self.version, self.location = machine, name, version, location


def read_record(lines: Iterable[str], where: str) -> Recorded | None:
    """The profile recorded in a program's lines (None: there is none, e.g. a program without
    curves, or one converted before the record existed). A record that does not load (a key
    this version does not know, a value out of range) is a ProfileError at its line."""
    values: dict[str, str] = {}
    places: dict[str, Location] = {}
    first: Location | None = None
    for number, line in enumerate(lines, 1):
        text = line.rstrip("\r\n")
        if text.startswith(SEMICOLON_START):
            text = "(" + text[2:] + ")"
        if not text.startswith(RECORD_START):
            if first is not None:
                break  # the record's lines are consecutive
            continue
        here = Location(where, number, 1)
        first = first or here
        if not text.endswith(")"):
            raise ProfileError("a profile record line must end with ')'", here)
        for item in text[len(RECORD_START):-1].split(", "):
            match = _PAIR.fullmatch(item)
            if match is None:
                raise ProfileError(f"cannot read {item!r} in the profile record (write "
                                   "'key value')", here)
            values[match[1]] = match[2]
            places[match[1]] = here
    if first is None:
        return None
    name = values.pop("name", "?")
    version = values.pop("nurbsfeed", "?")
    places.pop("name", None)
    places.pop("nurbsfeed", None)
    data = {key: _number(value) for key, value in values.items()}
    machine = machine_from_mapping(data, f"{where} (its profile record)", places, name=name)
    return Recorded(machine, name, version, first)


def _number(text: str) -> float | int | str:
    """A recorded value as the profile loader takes it: an int, a float, or a word."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def differences(recorded: Machine, given: Machine) -> list[str]:
    """The profile keys on which two machines differ, as `key recorded -> given`."""
    a, b = dict(recorded.profile), dict(given.profile)
    return [f"{key} {a.get(key, 'unset')} -> {b.get(key, 'unset')}"
            for key in list(a) + [key for key in b if key not in a]
            if a.get(key) != b.get(key)]
