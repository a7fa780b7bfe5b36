"""Machine profiles: every key's range, at both ends and just outside, from a file and from an
option; and what a profile file may not be (an alias bomb, too many values, too large)."""

from __future__ import annotations

import configparser
import math
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.errors import ProfileError
from nurbsfeed.machine import (
    AXIS_KEYS,
    INT_KEYS,
    MAX_PROFILE_BYTES,
    MAX_PROFILE_NODES,
    RANGES,
    load_machine,
)
from tests.conftest import ROOT, SAMPLES
from tests.gcode_parse import moves

SOURCE = SAMPLES / "quarter-circle.json"
DEFAULT = (ROOT / "configs" / "default.yaml").read_text()
ENDS = [(key, end) for key, (low, high) in RANGES.items() for end in (low, high)]
NUMBER = re.compile(r"[XYZF]([^ \r\n]*)")


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def option(key: str) -> str:
    return "--" + key.replace("_", "-")


def model_for(key: str) -> dict[str, str]:
    """The jerk model a key needs: per-axis limits hold only under the path model."""
    return {"jerk_model": "path"} if key in AXIS_KEYS else {}


def profile_with(tmp_path: Path, key: str, text: str) -> tuple[Path, int]:
    """The default profile with `key: text` in place of its own line (and `jerk_model: path`
    for a per-axis key); the file and that line."""
    model = model_for(key)
    lines = [line for line in DEFAULT.splitlines() if line.split(":")[0] not in {key, *model}]
    lines += [f"{k}: {v}" for k, v in model.items()]
    path = tmp_path / "m.yaml"
    path.write_text("\n".join(lines + [f"{key}: {text}"]) + "\n")
    return path, len(lines) + 1


@pytest.mark.parametrize(("key", "value"), ENDS)
def test_each_end_of_each_range_converts_or_is_refused_at_the_curve(tmp_path: Path, key: str,
                                                                    value: float) -> None:
    out = tmp_path / "q.nc"
    model = ["--jerk-model", "path"] if key in AXIS_KEYS else []
    code, _, stderr = run("convert", str(SOURCE), option(key), str(value), *model, "-o",
                          str(out), "-q")
    if code == 0:
        words = NUMBER.findall(re.sub(r"\(.*?\)", "", out.read_text()))
        assert words and all("." in w and math.isfinite(float(w)) for w in words)
    else:  # the curve would run for hours (a slow feed), or longer than a tiny limit
        assert code == 2 and not out.exists()
        if key == "min_block_time_s":  # a floor above the default's 1 ms moves
            assert stderr.startswith(f"option {option(key)}: a written move of move_periods x "
                                     "period_s = 1 ms is shorter than min_block_time_s"), stderr
            return
        # (under the path model a lower bound refuses it before the fix rounds: "of at least")
        assert re.fullmatch(rf"{re.escape(str(SOURCE))}:\d+:\d+: curve 0 \S+: (planned cycle|"
                            r"cycle of at least) \S+ s exceeds max_curve_time_s = \S+ s \(.*\)\n",
                            stderr), stderr


@pytest.mark.parametrize(("key", "value"), ENDS)
def test_each_end_of_each_range_is_accepted_in_a_file(tmp_path: Path, key: str,
                                                      value: float) -> None:
    path, _ = profile_with(tmp_path, key, repr(value))
    if key == "min_block_time_s" and value > 0.001:  # see the floor tests below
        path.write_text(path.read_text() + "move_periods: 1000\n")
        assert load_machine(str(path)) == load_machine("default", {key: value,
                                                                   "move_periods": 1000})
        return
    assert load_machine(str(path)) == load_machine("default", {key: value, **model_for(key)})


def outside(key: str) -> list[float]:
    low, high = RANGES[key]
    if key in INT_KEYS:
        return [low - 1, high + 1]
    if low == 0:
        return [-1e-300, -1e-9, high * 1.001, 1e308]
    return [low * 0.999, high * 1.001, 1e-300, 1e308]


@pytest.mark.parametrize(("key", "value"), [(key, v) for key in RANGES for v in outside(key)])
def test_a_value_outside_its_range_is_refused_at_its_key(tmp_path: Path, key: str,
                                                         value: float) -> None:
    path, line = profile_with(tmp_path, key, repr(value))
    low, high = RANGES[key]
    if key in INT_KEYS:
        what = f"must be a whole number from {low} to {high}"
    else:
        what = f"must be from {low:g} to {high:g}"
    out = tmp_path / "q.nc"
    code, stdout, stderr = run("convert", str(SOURCE), "-m", str(path), "-o", str(out))
    assert (code, stdout) == (2, "") and not out.exists()
    assert stderr == f"{path}:{line}:1: '{key}' {what}, not {value!r}\n"
    code, _, stderr = run("convert", str(SOURCE), option(key), str(value), "-o", str(out))
    number = value if key in INT_KEYS else float(value)
    assert (code, stderr) == (2, f"option {option(key)}: '{key}' {what}, not {number!r}\n")


def test_an_alias_bomb_is_refused_at_its_first_anchor(tmp_path: Path) -> None:
    # nine levels of ten: 10^9 values once expanded, in a file of a few hundred bytes
    levels = ["a: &a [" + ", ".join(["x"] * 10) + "]"]
    for level in "bcdefghi":
        before = chr(ord(level) - 1)
        levels.append(f"{level}: &{level} [" + ", ".join([f"*{before}"] * 10) + "]")
    path, line = profile_with(tmp_path, "period_s", "*i")
    path.write_text("\n".join(levels) + "\n" + path.read_text())
    code, _, stderr = run("convert", str(SOURCE), "-m", str(path))
    assert (code, stderr) == (2, f"{path}:1:4: anchors and aliases (&name, *name) have no "
                                 "place in a machine profile\n")


def test_a_lone_alias_is_refused_too(tmp_path: Path) -> None:
    path, _ = profile_with(tmp_path, "max_acc_mm_s2", "&acc 2000.0")
    text = path.read_text() + "max_normal_acc_mm_s2: *acc\n"
    path.write_text("\n".join(line for line in text.splitlines()
                              if not line.startswith("max_normal_acc_mm_s2: 2")) + "\n")
    code, _, stderr = run("convert", str(SOURCE), "-m", str(path))
    assert code == 2 and re.fullmatch(rf"{re.escape(str(path))}:\d+:\d+: anchors and aliases "
                                      r".*\n", stderr)


def test_a_profile_with_too_many_values_is_refused_where_they_overflow(tmp_path: Path) -> None:
    path, line = profile_with(tmp_path, "decimals", "4")
    path.write_text(path.read_text() + "extra: [" + ", ".join(["1"] * MAX_PROFILE_NODES) + "]\n")
    code, _, stderr = run("convert", str(SOURCE), "-m", str(path))
    assert code == 2
    assert re.fullmatch(rf"{re.escape(str(path))}:{line + 1}:\d+: more than "
                        rf"{MAX_PROFILE_NODES} YAML values: .*\n", stderr)


def test_a_profile_file_above_the_size_bound_is_refused_before_parsing(tmp_path: Path) -> None:
    path = tmp_path / "m.yaml"
    padding = "#" * 99 + "\n"  # valid YAML: without the bound, it would load
    path.write_text(DEFAULT + padding * ((MAX_PROFILE_BYTES - len(DEFAULT)) // len(padding)))
    assert path.stat().st_size <= MAX_PROFILE_BYTES
    assert load_machine(str(path)) == load_machine("default")
    path.write_text(path.read_text() + padding)
    code, _, stderr = run("convert", str(SOURCE), "-m", str(path))
    assert (code, stderr) == (2, f"{path}: a machine profile of more than {MAX_PROFILE_BYTES} "
                                 "bytes: it is a flat mapping of a few numbers\n")


@pytest.mark.parametrize("key", ["max_acc_mm_s2", "decimals"])
@pytest.mark.parametrize(("digits", "what"), [
    (400, "must be {range}, not an integer of 400 digits"),  # beyond a float's range
    (5000, "an integer too long to be a number"),  # beyond what Python converts from text
])
def test_an_integer_of_hundreds_or_thousands_of_digits_is_refused_at_its_place(
        tmp_path: Path, key: str, digits: int, what: str) -> None:
    path, line = profile_with(tmp_path, key, "9" * digits)
    low, high = RANGES[key]
    span = (f"a whole number from {low} to {high}" if key in INT_KEYS
            else f"from {low:g} to {high:g}")
    out = tmp_path / "q.nc"
    code, stdout, stderr = run("convert", str(SOURCE), "-m", str(path), "-o", str(out))
    assert (code, stdout) == (2, "") and not out.exists()
    if digits == 400:
        assert stderr == f"{path}:{line}:1: '{key}' {what.format(range=span)}\n"
    else:  # the YAML scalar itself, after the key
        assert stderr == f"{path}:{line}:{len(key) + 3}: {what}\n"


# ---- the keys that describe the controller: move_periods, min_block_time_s -----------------

@pytest.mark.parametrize("text", ["0", "-2", "2.5", "2.0", "'2'", "true", "1001"])
def test_move_periods_other_than_a_whole_number_from_1_is_refused_at_its_key(
        tmp_path: Path, text: str) -> None:
    path, line = profile_with(tmp_path, "move_periods", text)
    code, _, stderr = run("convert", str(SOURCE), "-m", str(path))
    shown = {"'2'": "'2'", "true": "True"}.get(text, text)
    assert (code, stderr) == (2, f"{path}:{line}:1: 'move_periods' must be a whole number "
                                 f"from 1 to 1000, not {shown}\n")


@pytest.mark.parametrize("text, what", [("-0.001", "must be from 0 to 1, not -0.001"),
                                        (".nan", "must be positive and finite, not nan"),
                                        ("fast", "must be a number, not 'fast'")])
def test_a_min_block_time_that_is_no_time_is_refused_at_its_key(tmp_path: Path, text: str,
                                                                what: str) -> None:
    path, line = profile_with(tmp_path, "min_block_time_s", text)
    code, _, stderr = run("convert", str(SOURCE), "-m", str(path))
    assert (code, stderr) == (2, f"{path}:{line}:1: 'min_block_time_s' {what}\n")


def test_a_move_shorter_than_the_block_time_floor_is_refused_naming_the_key_to_raise(
        tmp_path: Path) -> None:
    """LinuxCNC's floor, 1.02 servo periods, under 1 ms moves: every move would be stretched."""
    path, _ = profile_with(tmp_path, "min_block_time_s", "0.00102")
    path.write_text(path.read_text() + "move_periods: 1\n")
    out = tmp_path / "q.nc"
    code, stdout, stderr = run("convert", str(SOURCE), "-m", str(path), "-o", str(out))
    assert (code, stdout) == (2, "") and not out.exists()
    last_line = len(path.read_text().splitlines())
    assert stderr == (f"{path}:{last_line}:1: a written move of move_periods x period_s = 1 ms "
                      "is shorter than min_block_time_s = 1.02 ms: the controller would stretch "
                      "every move and not run the planned cycle; raise move_periods to 2\n")
    code, _, stderr = run("convert", str(SOURCE), "-m", str(path), "--move-periods", "2",
                          "-o", str(out))
    assert code == 0 and out.exists(), stderr


def test_the_floor_message_points_at_the_option_that_set_it(tmp_path: Path) -> None:
    code, _, stderr = run("convert", str(SOURCE), "--min-block-time-s", "0.0025")
    assert (code, stderr) == (2, "option --min-block-time-s: a written move of move_periods x "
                                 "period_s = 1 ms is shorter than min_block_time_s = 2.5 ms: the "
                                 "controller would stretch every move and not run the planned "
                                 "cycle; raise move_periods to 3\n")


@pytest.mark.parametrize("move_periods, floor_s, accepted", [
    (2, 0.002, True),  # equal: the floor is met
    (2, 0.0020001, False),
    (3, 0.003, True),  # 3 x 0.001 is 0.0030000000000000005 in binary
    (1, 0.0, True),
])
def test_both_sides_of_the_block_time_floor(move_periods: int, floor_s: float,
                                            accepted: bool) -> None:
    overrides = {"move_periods": move_periods, "min_block_time_s": floor_s}
    if accepted:
        assert load_machine("default", overrides).min_block_time_s == floor_s
    else:
        with pytest.raises(ProfileError, match="shorter than min_block_time_s"):
            load_machine("default", overrides)


def test_a_move_longer_than_a_second_is_refused(tmp_path: Path) -> None:
    path, _ = profile_with(tmp_path, "period_s", "0.5")
    path.write_text(path.read_text() + "move_periods: 3\n")
    code, _, stderr = run("convert", str(SOURCE), "-m", str(path))
    assert (code, stderr) == (2, f"{path}:{len(path.read_text().splitlines())}:1: a written "
                                 "move of move_periods x period_s = 1.5 s: at most 1 s\n")


def test_the_planner_and_writer_work_with_moves_of_move_periods(tmp_path: Path) -> None:
    """Two-period moves: the plan steps by 2 ms and every written move lasts 2 ms (Σ L / F is
    the planned cycle); the controller period stays the profile's period_s."""
    machine = load_machine("default", {"move_periods": 2})
    assert (machine.limits.period_s, machine.controller_period_s) == (0.002, 0.001)
    out = tmp_path / "q.nc"
    assert run("convert", str(SOURCE), "--move-periods", "2", "-o", str(out), "-q")[0] == 0
    text = out.read_text()
    comment = re.search(r"(\d+) points, period 2 ms, .* planned cycle ([\d.]+) s", text)
    assert comment is not None, text[:300]
    written, feeds, _ = moves(text, [10.0, 0.0, 0.0])
    steps = np.linalg.norm(np.diff(np.vstack([[10.0, 0.0, 0.0], written]), axis=0), axis=1)
    periods = steps / (feeds / 60.0) / 0.002
    assert np.allclose(periods, np.round(periods), rtol=5e-3) and np.all(np.round(periods) >= 1)
    assert int(np.round(periods).sum()) == int(comment[1]) - 1
    assert math.isclose(float(np.sum(steps / (feeds / 60.0))), float(comment[2]), abs_tol=5e-4)


# ---- decimals chosen from the move duration and the limits ---------------------------------

def spike_mm_s2(decimals: int, machine) -> float:
    """The largest acceleration a controller reads from rounding at a junction: 4 r / (D T)."""
    return 4 * 0.5 * 10.0**-decimals / (machine.limits.period_s * machine.controller_period_s)


@pytest.mark.parametrize("name, decimals", [("default", 5), ("linuxcnc", 6),
                                            ("paper-table1", 4)])
def test_the_built_in_profiles_write_the_decimals_their_limits_ask_for(name: str,
                                                                      decimals: int) -> None:
    """default and linuxcnc give no decimals: the fewest whose rounding spike is at most 1 % of
    the smaller acceleration limit; paper-table1 keeps the paper's 4."""
    machine = load_machine(name)
    assert machine.decimals == decimals
    if name != "paper-table1":
        acc = min(machine.limits.acc_mm_s2, machine.limits.normal_acc_mm_s2)
        assert spike_mm_s2(decimals, machine) <= 0.01 * acc * (1 + 1e-9)
        assert spike_mm_s2(decimals - 1, machine) > 0.01 * acc
        assert 0.5 * 10.0**-decimals * math.sqrt(3) <= machine.limits.chord_mm / 10


@pytest.mark.parametrize("acc, decimals", [(2000.0, 5), (1999.0, 6), (20000.0, 4),
                                           (19999.0, 5), (1e-3, 8)])
def test_both_sides_of_the_rounding_spike_bound(acc: float, decimals: int) -> None:
    """At 1 ms moves 10^-d / 1e-6 s² <= 0.01 A: A = 2000 just meets 5 decimals, 1999 does not;
    a tiny limit asks for more than 8 and gets the profile's maximum."""
    overrides = {"max_acc_mm_s2": acc, "max_normal_acc_mm_s2": 1e7, "chord_error_mm": 10.0}
    assert load_machine("default", overrides).decimals == decimals


@pytest.mark.parametrize("chord_mm, decimals", [(8.7e-4, 4), (8.6e-4, 5)])
def test_both_sides_of_the_rounding_chord_bound(chord_mm: float, decimals: int) -> None:
    """r sqrt 3 <= delta / 10 with r = 0.5e-4: delta >= 8.66e-4 mm for 4 decimals."""
    overrides = {"max_acc_mm_s2": 1e7, "max_normal_acc_mm_s2": 1e7, "chord_error_mm": chord_mm}
    assert load_machine("default", overrides).decimals == decimals


def test_the_profiles_decimals_and_the_option_override_the_choice(tmp_path: Path) -> None:
    path, _ = profile_with(tmp_path, "decimals", "3")
    assert load_machine(str(path)).decimals == 3
    assert load_machine("linuxcnc", {"decimals": 4}).decimals == 4
    out = tmp_path / "q.nc"
    assert run("convert", str(SOURCE), "-m", "linuxcnc", "-o", str(out), "-q")[0] == 0
    digits = {len(w.partition(".")[2]) for w in re.findall(r"[XYZ](-?[\d.]+)", out.read_text())}
    assert max(digits) == 6


def test_the_linuxcnc_profile_holds_each_axis_to_the_simulated_mills_joint_limits() -> None:
    """Its axes' limits are the INI's (tests/linuxcnc/sim/sim.ini, [JOINT_n] MAX_VELOCITY and
    MAX_ACCELERATION), planned under the path model, which holds each axis to its own; the
    path's accelerations leave each axis within them even without it, sqrt(A_t² + A_n²)."""
    ini = configparser.ConfigParser(strict=False, inline_comment_prefixes=("#",))
    ini.read(ROOT / "tests" / "linuxcnc" / "sim" / "sim.ini")
    limits = load_machine("linuxcnc").limits
    assert (limits.jerk_model, limits.planner) == ("path", "optimal")
    for x in range(3):
        joint = ini[f"JOINT_{x}"]
        assert limits.axis_vel_mm_s[x] == float(joint["MAX_VELOCITY"])
        assert limits.axis_acc_mm_s2[x] == float(joint["MAX_ACCELERATION"])
        assert math.isinf(limits.axis_jerk_mm_s3[x])  # LinuxCNC 2.9 has no jerk limit
    assert math.hypot(limits.acc_mm_s2, limits.normal_acc_mm_s2) <= min(limits.axis_acc_mm_s2)
    assert limits.feed_mm_s <= min(limits.axis_vel_mm_s)


@pytest.mark.parametrize("name, overrides", [
    ("default", {}), ("paper-table1", {}), ("linuxcnc", {}),
    ("default", {"max_feed_mm_s": 123.456789012345, "decimals": 6, "jerk_model": "path"}),
    ("linuxcnc", {"period_s": 0.00025, "move_periods": 7, "min_block_time_s": 0.0017}),
])
def test_the_profile_record_loads_back_into_the_same_machine(name: str, overrides: dict) -> None:
    """Every key in the record, floats to the last bit, lines short enough for a controller:
    read back through the profile's own checks it is the machine the program was made with."""
    from nurbsfeed.gcode.profile_record import RECORD_WIDTH, differences, read_record, record_lines

    machine = load_machine(name, overrides)
    lines = record_lines(machine)
    assert all(line.startswith("(nurbsfeed profile: ") and line.endswith(")")
               and len(line) <= RECORD_WIDTH and line.count("(") == 1 for line in lines)
    recorded = read_record(["%\n", "O1\n"] + [line + "\r\n" for line in lines] + ["G1 X1.\n"],
                           "out.nc")
    assert recorded is not None and recorded.location.line == 3
    assert recorded.machine == machine and recorded.name == name
    assert differences(recorded.machine, machine) == []
    other = load_machine(name, {**overrides, "chord_error_mm": 0.0042})
    assert differences(machine, other) == [
        f"chord_error_mm {machine.limits.chord_mm!r} -> 0.0042"]


def test_a_profile_file_name_is_recorded_in_characters_a_comment_takes(tmp_path: Path) -> None:
    from nurbsfeed.gcode.profile_record import read_record, record_lines

    path = tmp_path / "my (odd) mill.yaml"
    path.write_text((ROOT / "configs" / "default.yaml").read_text())
    lines = record_lines(load_machine(str(path)))
    assert lines[0] == ("(nurbsfeed profile: name my__odd__mill.yaml, nurbsfeed 0.1.0, "
                        "jerk_model path, planner optimal)")
    long = tmp_path / ("x" * 200 + ".yaml")
    long.write_text(path.read_text())
    assert record_lines(load_machine(str(long)))[0] == f"(nurbsfeed profile: name {'x' * 60})"
    recorded = read_record(lines, "out.nc")
    assert recorded is not None and recorded.machine.profile == load_machine("default").profile
