"""Machine profile: the kinematic limits and output settings, loaded and validated from YAML.

Units live in the key names and are what they say: mm and seconds, whatever the program's unit
(an inch program's curves are converted to mm when they are read, `CurveBlock.in_mm`). Every key
has a range (`RANGES`, docs/profiles.md): a value that passes is one the planner, the
stepping loop and the writer compute with in finite numbers.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from nurbsfeed.errors import Location, ProfileError

if TYPE_CHECKING:  # imported where a profile is loaded: numpy is not needed before that
    from nurbsfeed.planning.limits import Limits


@dataclass(frozen=True)
class Machine:
    """One machine (design §4): its kinematic limits, in mm and s, and the output settings."""

    # limits.period_s is the duration of one written move: move_periods controller periods
    limits: Limits
    # the longest planned cycle of one curve that is converted: a longer one is refused (a
    # mistyped feed or period would otherwise step for hours)
    max_curve_time_s: float = 3600.0
    # coordinate decimals in mm programs (inch programs: one more): the profile's, or
    # `auto_decimals` when it gives none
    decimals: int = 4
    feed_decimals: int = 3  # F word decimals (more when F is small; see gcode.writer)
    move_periods: int = 1  # controller periods per written move
    min_block_time_s: float = 0.0  # the controller's floor on one block's time
    # the shortest move from or into a rest (pipeline.RestMoves); 0: a move a period there too
    rest_move_s: float = 0.0
    # the profile as loaded: its name (built-in name or YAML path) and every key with the value
    # in force (overrides applied, defaults filled in, per-axis limits only where set), which
    # `machine_from_mapping` turns back into this machine (the record in each output, design
    # §5 "Profile record"); the name labels the machine, it is not part of what the machine is
    name: str = field(default="", compare=False)
    profile: tuple[tuple[str, float | int | str], ...] = ()

    @property
    def controller_period_s(self) -> float:
        """The profile's period_s: the controller's interpolation (servo) period."""
        return self.limits.period_s / self.move_periods


# profile key -> the Limits field it sets (the keys say "max", the fields are the limits)
LIMIT_KEYS = {"period_s": "period_s", "max_feed_mm_s": "feed_mm_s",
              "chord_error_mm": "chord_mm", "max_acc_mm_s2": "acc_mm_s2",
              "max_jerk_mm_s3": "jerk_mm_s3", "max_normal_acc_mm_s2": "normal_acc_mm_s2",
              "max_normal_jerk_mm_s3": "normal_jerk_mm_s3"}
REQUIRED_KEYS = tuple(LIMIT_KEYS)  # the others have the Machine's default (decimals: auto)
AXES = ("x", "y", "z")
# per-axis limits (path model only): key -> (Limits field, axis index)
# per-axis kind: key word, unit, Limits field, the path key whose range it shares
AXIS_KINDS = (("vel", "mm_s", "axis_vel_mm_s", "max_feed_mm_s"),
              ("acc", "mm_s2", "axis_acc_mm_s2", "max_acc_mm_s2"),
              ("jerk", "mm_s3", "axis_jerk_mm_s3", "max_jerk_mm_s3"))
AXIS_KEYS = {f"max_{what}_{axis}_{unit}": (field, i)
             for what, unit, field, _ in AXIS_KINDS for i, axis in enumerate(AXES)}
FLOAT_KEYS = (REQUIRED_KEYS + ("max_curve_time_s", "min_block_time_s", "rest_move_s")
              + tuple(AXIS_KEYS))
INT_KEYS = ("decimals", "feed_decimals", "move_periods")
JERK_MODELS = ("paper", "path")  # profile key jerk_model (planning.path_model)
# profile key planner: the paper's key points and S-curves, or the path model's controllable
# sets (planning.reach_schedule); "envelope", an earlier path-model planner, plans as
# "optimal" (a profile written for it keeps working)
PLANNERS = ("scurve", "optimal", "envelope")
PLANNER_ALIASES = {"envelope": "optimal"}
# The accepted values, ends included (docs/profiles.md says why each is physical).
RANGES: dict[str, tuple[float, float]] = {
    "period_s": (1e-6, 1.0),
    "max_feed_mm_s": (1e-3, 1e5),
    "chord_error_mm": (1e-6, 10.0),
    "max_acc_mm_s2": (1e-3, 1e7),
    "max_jerk_mm_s3": (1e-3, 1e10),
    "max_normal_acc_mm_s2": (1e-3, 1e7),
    "max_normal_jerk_mm_s3": (1e-3, 1e10),
    "max_curve_time_s": (1e-3, 1e6),
    "min_block_time_s": (0.0, 1.0),
    "rest_move_s": (0.0, 1.0),
    "decimals": (0, 8),
    "feed_decimals": (0, 6),
    "move_periods": (1, 1000),
}
RANGES.update({f"max_{what}_{axis}_{unit}": RANGES[path_key]
               for what, unit, _, path_key in AXIS_KINDS for axis in AXES})
MAX_MOVE_S = RANGES["period_s"][1]
# a move this much (relative) shorter than min_block_time_s still meets it: 2 x 0.00051 is not
# 0.00102 in binary
FLOOR_MARGIN = 1e-9  # move_periods * period_s: the planner's period
# Automatic output resolution (`auto_decimals`): the largest acceleration spike rounding may
# put at a junction, as a share of the profile's smaller acceleration limit, and the farthest a
# written point may be from the computed one, as a share of the chord tolerance.
ROUNDING_SPIKE_SHARE = 0.01
ROUNDING_CHORD_SHARE = 0.1
# A profile is a flat mapping of ten numbers: these bounds are far above any real one, and far
# below what makes a YAML parser slow.
MAX_PROFILE_BYTES = 1 << 20
MAX_PROFILE_NODES = 1000


def _key_shown(key: Any) -> str:
    """A key the user wrote, for a message: escaped by repr (its newline or control character
    never reaches the message raw: a key "odd\\nkey" split one in two lines), cut at 60."""
    shown = _shown(key)
    return shown if len(shown) <= 60 else shown[:57] + "..."


def _shown(value: Any) -> str:
    """`value` for a message: a huge integer by its size (Python will not even print one of
    more than 4300 digits)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 64:
        digits = int(value.bit_length() * math.log10(2)) + 1  # at most one too many
        if abs(value) < 10 ** (digits - 1):
            digits -= 1
        return f"an integer of {digits} digits"
    return repr(value)


def _check_value(key: str, value: Any) -> float | int:
    """One key's value, checked; ProfileError (without a place) when it is not valid."""
    low, high = RANGES[key]
    if key in INT_KEYS:
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ProfileError(f"'{key}' must be a whole number from {low} to {high}, "
                               f"not {_shown(value)}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProfileError(f"'{key}' must be a number, not {_shown(value)}")
    # compared before any conversion: an integer beyond a float's range is just out of range
    if isinstance(value, float) and not math.isfinite(value) or (value <= 0 and low > 0):
        raise ProfileError(f"'{key}' must be positive and finite, not {_shown(value)}")
    if not low <= value <= high:
        raise ProfileError(f"'{key}' must be from {low:g} to {high:g}, not {_shown(value)}")
    return float(value)


def machine_from_mapping(data: Any, where: str, places: Mapping[str, Location] | None = None,
                         overrides: Mapping[str, Any] | None = None, name: str = "") -> Machine:
    """Validate a parsed profile and apply CLI overrides.

    where: the profile's place for messages; places: the location of each key in the file;
    name: the profile's name (default: `where`).
    """
    places = places or {}
    here = Location(where)
    if not isinstance(data, dict):
        raise ProfileError("a machine profile is a mapping of keys to values, not "
                           f"{type(data).__name__}", here)
    known = set(FLOAT_KEYS) | set(INT_KEYS) | {"jerk_model", "planner"}
    for key in data:
        if key not in known:
            raise ProfileError(f"unknown key {_key_shown(key)} (known keys: "
                               f"{', '.join(sorted(known))})",
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
    jerk_model = _choice(data, "jerk_model", JERK_MODELS, places, overrides, here)
    planner = _choice(data, "planner", PLANNERS, places, overrides, here)
    planner = PLANNER_ALIASES.get(planner, planner)
    for key, value in (overrides or {}).items():
        if key in ("jerk_model", "planner"):
            continue
        if value is not None:
            try:
                values[key] = _check_value(key, value)
            except ProfileError as exc:
                raise ProfileError(f"option --{key.replace('_', '-')}: {exc.message}") from None
    profile = dict(values)  # as given, before period_s becomes the written move's
    move_periods = int(values.get("move_periods", 1))
    move_s = move_periods * values["period_s"]
    if move_s > MAX_MOVE_S:
        raise _refused(f"a written move of move_periods x period_s = {move_s:g} s: at most "
                       f"{MAX_MOVE_S:g} s", ("move_periods", "period_s"), places, overrides,
                       here)
    floor_s = values.get("min_block_time_s", 0.0)
    if move_s < floor_s * (1.0 - FLOOR_MARGIN):
        needed = math.ceil(floor_s * (1.0 - FLOOR_MARGIN) / values["period_s"])
        raise _refused(f"a written move of move_periods x period_s = {move_s * 1e3:g} ms is "
                       f"shorter than min_block_time_s = {floor_s * 1e3:g} ms: the controller "
                       "would stretch every move and not run the planned cycle; raise "
                       f"move_periods to {needed}",
                       ("move_periods", "min_block_time_s", "period_s"), places, overrides,
                       here)
    values["period_s"] = move_s  # what the planner, the stepping and the writer step by
    axis_given = [key for key in AXIS_KEYS if key in values]
    if axis_given and jerk_model != "path":
        raise _refused(f"per-axis limits ({', '.join(axis_given)}) hold only under "
                       "jerk_model: path (the paper's model limits the path alone)",
                       (*axis_given, "jerk_model"), places, overrides, here)
    if planner == "optimal" and jerk_model != "path":
        raise _refused(f"planner: {planner} plans under jerk_model: path only (the paper's planner "
                       "is the paper's model's)", ("planner", "jerk_model"), places, overrides,
                       here)
    axis: dict[str, list[float]] = {field: [math.inf] * 3 for field, _ in AXIS_KEYS.values()}
    for key in axis_given:
        field, i = AXIS_KEYS[key]
        axis[field][i] = float(values.pop(key))
    from nurbsfeed.planning.limits import Limits

    path = {field: float(values.pop(key)) for key, field in LIMIT_KEYS.items()}
    limits = Limits(path["period_s"], path["feed_mm_s"], path["chord_mm"], path["acc_mm_s2"],
                    path["jerk_mm_s3"], path["normal_acc_mm_s2"], path["normal_jerk_mm_s3"],
                    jerk_model, _xyz(axis["axis_vel_mm_s"]), _xyz(axis["axis_acc_mm_s2"]),
                    _xyz(axis["axis_jerk_mm_s3"]), planner)
    if "decimals" not in values:
        values["decimals"] = auto_decimals(limits, limits.period_s / move_periods)
    return Machine(limits, **values, name=name or where,  # type: ignore[arg-type]
                   profile=_in_force(profile, values, jerk_model, planner))


def _in_force(given: dict[str, float | int], values: dict[str, float | int], jerk_model: str,
              planner: str) -> tuple[tuple[str, float | int | str], ...]:
    """Every profile key with its value in force, jerk_model and planner first, then in
    FLOAT_KEYS + INT_KEYS order: the given ones, else the Machine's default (`values`: the
    output settings as the Machine gets them, decimals included); per-axis limits only where
    given."""
    defaults: dict[str, Any] = {f.name: f.default for f in fields(Machine)}
    pairs: list[tuple[str, float | int | str]] = [("jerk_model", jerk_model),
                                                  ("planner", planner)]
    for key in FLOAT_KEYS + INT_KEYS:
        if key in given:
            pairs.append((key, given[key]))
        elif key in values:
            pairs.append((key, values[key]))
        elif key not in AXIS_KEYS:
            pairs.append((key, defaults[key]))
    return tuple(pairs)


def _choice(data: dict, key: str, choices: tuple[str, ...], places: Mapping[str, Location],
            overrides: Mapping[str, Any] | None, here: Location) -> str:
    """A key that names one of `choices` (the first by default); the option's value, if given,
    wins (click has checked it)."""
    value = data.get(key, choices[0])
    if value not in choices:
        raise ProfileError(f"'{key}' must be one of {', '.join(choices)}, not {_shown(value)}",
                           places.get(key, here))
    given = (overrides or {}).get(key)
    return str(given) if given is not None else str(value)


def _xyz(values: list[float]) -> tuple[float, float, float]:
    return values[0], values[1], values[2]


def _refused(message: str, keys: tuple[str, ...], places: Mapping[str, Location],
             overrides: Mapping[str, Any] | None, here: Location) -> ProfileError:
    """The error of a check of several keys: at the options that set one of them, else at the
    first of them in the file (else the profile)."""
    options = [f"--{key.replace('_', '-')}" for key in keys
               if (overrides or {}).get(key) is not None]
    if options:
        return ProfileError(f"option {', '.join(options)}: {message}")
    return ProfileError(message, next((places[key] for key in keys if key in places), here))


def auto_decimals(limits: Limits, controller_period_s: float) -> int:
    """The fewest coordinate decimals (mm programs) at which rounding makes no junction a
    controller reads as a corner and keeps the written points near the computed ones; at most
    the profile's maximum (RANGES["decimals"]).

    A coordinate written with d decimals is off by up to r = 10^-d / 2. One axis's velocity
    over a move of duration D is off by up to 2r / D, and its change from one move to the next,
    what a controller looks at where two moves meet, by up to 4r / D. A controller spreads that
    change over its own period T: LinuxCNC (tp.c, tpSetupTangent) counts it as an acceleration
    4r / (D T) against the axis's limit, takes a junction whose share is above its kink ratio
    (0.1) as a corner to slow down for, and below it lowers the move's acceleration by that
    share. Held to ROUNDING_SPIKE_SHARE (1 %) of the smaller of the profile's tangential and
    normal acceleration, rounding costs at most 1 % of the acceleration the plan counts on and
    leaves the kink budget to the curve's own turning. And the point, off by up to r sqrt(3),
    stays within ROUNDING_CHORD_SHARE (a tenth) of the chord tolerance, so that rounding
    hardly adds to the chord error. A bound met with equality is met (1e-9 margin: the limits
    are decimal numbers, powers of ten in binary are not).
    """
    acc_mm_s2 = min(limits.acc_mm_s2, limits.normal_acc_mm_s2)
    spike_r = ROUNDING_SPIKE_SHARE * acc_mm_s2 * limits.period_s * controller_period_s / 4.0
    chord_r = ROUNDING_CHORD_SHARE * limits.chord_mm / math.sqrt(3.0)
    largest_r = min(spike_r, chord_r) * (1.0 + 1e-9)
    low, high = RANGES["decimals"]
    decimals = int(low)
    while decimals < high and 0.5 * 10.0**-decimals > largest_r:
        decimals += 1
    return decimals


def builtin_profiles() -> list[str]:
    """Names accepted by `--machine NAME`."""
    folder = resources.files("nurbsfeed.configs")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


class _NotAProfile(yaml.MarkedYAMLError):
    """Valid YAML that no profile holds (an alias, too many nodes)."""


class _ProfileLoader(yaml.SafeLoader):
    """PyYAML's safe loader with two YAML 1.2 rules: `1e9` and `1.0e9` are floats (YAML 1.1's
    resolver wants a point and a signed exponent, and reads them as strings), and a key given
    twice in one mapping is an error (PyYAML keeps the last silently). A profile is a flat
    mapping of numbers: anchors and aliases, which can make a short file expand into billions
    of values, are refused, as are more than MAX_PROFILE_NODES nodes."""

    nodes = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
            raise _NotAProfile(problem="anchors and aliases (&name, *name) have no place in a "
                               "machine profile", problem_mark=event.start_mark)
        self.nodes += 1
        if self.nodes > MAX_PROFILE_NODES:
            raise _NotAProfile(problem=f"more than {MAX_PROFILE_NODES} YAML values: a machine "
                               "profile is a flat mapping of a few numbers",
                               problem_mark=event.start_mark)
        return super().compose_node(parent, index)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if not isinstance(key, (str, int, float, bool)):
                continue  # an unhashable key: SafeLoader's own message
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {_key_shown(key)} appears twice", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        try:
            return super().construct_yaml_int(node)
        except ValueError:  # more digits than Python converts (sys.get_int_max_str_digits)
            raise _NotAProfile(problem="an integer too long to be a number",
                               problem_mark=node.start_mark) from None


_ProfileLoader.add_constructor("tag:yaml.org,2002:int", _ProfileLoader.construct_yaml_int)
_ProfileLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


def _key_places(node: yaml.Node | None, where: str) -> dict[str, Location]:
    """Line and column of each top-level key, from the YAML node tree."""
    if not isinstance(node, yaml.MappingNode):
        return {}
    return {str(k.value): Location(where, k.start_mark.line + 1, k.start_mark.column + 1)
            for k, _ in node.value}


def _read_profile(path: Path) -> str:
    """The profile file's text, refused unreadable, not UTF-8 or above MAX_PROFILE_BYTES (read
    no further: a device or a FIFO can be endless)."""
    where = Location(str(path))
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_PROFILE_BYTES + 1)
    except OSError as exc:
        raise ProfileError(f"cannot read machine profile ({exc.strerror})", where) from None
    if len(data) > MAX_PROFILE_BYTES:
        raise ProfileError(f"a machine profile of more than {MAX_PROFILE_BYTES} bytes: it is a "
                           "flat mapping of a few numbers", where)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ProfileError("cannot read machine profile (not UTF-8 text)", where) from None


def load_machine(name_or_path: str, overrides: Mapping[str, Any] | None = None) -> Machine:
    """A profile by built-in name (`default`, `paper-table1`) or by path to a YAML file."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.exists():
        where = str(path)
        text = _read_profile(path)
    else:
        if name_or_path not in builtin_profiles():
            raise ProfileError(f"unknown machine {name_or_path!r}: give a YAML file or one of "
                               f"{', '.join(builtin_profiles())}")
        where = f"{name_or_path}.yaml"
        text = (resources.files("nurbsfeed.configs") / where).read_text(encoding="utf-8")
    loader = _ProfileLoader(text)  # a SafeLoader subclass
    try:
        node = loader.get_single_node()
        data = loader.construct_document(node) if node is not None else None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        loc = Location(where, mark.line + 1, mark.column + 1) if mark else Location(where)
        problem = getattr(exc, "problem", exc)
        raise ProfileError(str(problem) if isinstance(exc, _NotAProfile)
                           else f"not valid YAML ({problem})", loc) from None
    finally:
        loader.dispose()
    return machine_from_mapping(data, where, _key_places(node, where), overrides,
                                name=name_or_path)
