"""Machine profiles: every key's range, at both ends and just outside, from a file and from an
option; and what a profile file may not be (an alias bomb, too many values, too large)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.machine import (INT_KEYS, MAX_PROFILE_BYTES, MAX_PROFILE_NODES, RANGES,
                               load_machine)
from tests.conftest import ROOT, SAMPLES

SOURCE = SAMPLES / "quarter-circle.json"
DEFAULT = (ROOT / "configs" / "default.yaml").read_text()
ENDS = [(key, end) for key, (low, high) in RANGES.items() for end in (low, high)]
NUMBER = re.compile(r"[XYZF]([^ \r\n]*)")


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def option(key: str) -> str:
    return "--" + key.replace("_", "-")


def profile_with(tmp_path: Path, key: str, text: str) -> tuple[Path, int]:
    """The default profile with `key: text` in place of its own line; the file and that line."""
    lines = [line for line in DEFAULT.splitlines() if not line.startswith(key + ":")]
    path = tmp_path / "m.yaml"
    path.write_text("\n".join(lines + [f"{key}: {text}"]) + "\n")
    return path, len(lines) + 1


@pytest.mark.parametrize(("key", "value"), ENDS)
def test_each_end_of_each_range_converts_or_is_refused_at_the_curve(tmp_path: Path, key: str,
                                                                    value: float) -> None:
    out = tmp_path / "q.nc"
    code, _, stderr = run("convert", str(SOURCE), option(key), str(value), "-o", str(out), "-q")
    if code == 0:
        words = NUMBER.findall(re.sub(r"\(.*?\)", "", out.read_text()))
        assert words and all("." in w and math.isfinite(float(w)) for w in words)
    else:  # the curve would run for hours (a slow feed), or longer than a tiny limit
        assert code == 2 and not out.exists()
        assert re.fullmatch(rf"{re.escape(str(SOURCE))}:\d+:\d+: curve 0 \S+: planned cycle "
                            r"\S+ s exceeds max_curve_time_s = \S+ s \(.*\)\n", stderr), stderr


@pytest.mark.parametrize(("key", "value"), ENDS)
def test_each_end_of_each_range_is_accepted_in_a_file(tmp_path: Path, key: str,
                                                      value: float) -> None:
    path, _ = profile_with(tmp_path, key, repr(value))
    assert load_machine(str(path)) == load_machine("default", {key: value})


def outside(key: str) -> list[float]:
    low, high = RANGES[key]
    if key in INT_KEYS:
        return [low - 1, high + 1]
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
    span = f"a whole number from {low} to {high}" if key in INT_KEYS else f"from {low:g} to {high:g}"
    out = tmp_path / "q.nc"
    code, stdout, stderr = run("convert", str(SOURCE), "-m", str(path), "-o", str(out))
    assert (code, stdout) == (2, "") and not out.exists()
    if digits == 400:
        assert stderr == f"{path}:{line}:1: '{key}' {what.format(range=span)}\n"
    else:  # the YAML scalar itself, after the key
        assert stderr == f"{path}:{line}:{len(key) + 3}: {what}\n"
