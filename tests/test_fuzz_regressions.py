"""Bugs the fuzzing tier (tests/fuzz, README "Fuzzing") found in the G-code readers, one test
each, through the command line as the fuzzer saw them."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main

HEAD = "G21 G90 G0 X0 Y0\nF100\n"


def refused(tmp_path: Path, text: str, name: str = "in.nc") -> str:
    """Convert `text`; it must be refused with exit 2 and no output: the message."""
    source = tmp_path / name
    source.write_bytes(text.encode("utf-8", "surrogateescape"))
    target = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(target)])
    assert result.exit_code == 2, result.output
    assert not target.exists()
    assert "internal error" not in result.stderr
    return result.stderr.strip().removeprefix(str(source))


@pytest.mark.parametrize(("line", "message"), [
    ("X#" + "9" * 5000, ":3:2: #99999999...: parameter numbers go from 0 to 999999"),
    ("#" + "9" * 5000 + "=5", ":3:1: #99999999...: parameter numbers go from 0 to 999999"),
    ("#1=#1000000", ":3:4: #1000000: parameter numbers go from 0 to 999999"),
    ("G1 X- # 1234567", ":3:7: #1234567: parameter numbers go from 0 to 999999"),
])
def test_a_parameter_number_of_thousands_of_digits_is_refused_at_its_place(
        tmp_path: Path, line: str, message: str) -> None:
    """int() of a 5000-digit string raises ValueError (Python's 4300-digit limit): it was an
    internal error."""
    assert refused(tmp_path, HEAD + line + "\n") == message


def test_the_largest_parameter_number_and_leading_zeros_are_read(tmp_path: Path) -> None:
    source = tmp_path / "in.nc"
    source.write_text(HEAD + "#999999=5.\n#0007=2.5\nG1 X#999999 Y#7\n")
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(tmp_path / "o.nc")])
    assert result.exit_code == 0, result.stderr
    assert (tmp_path / "o.nc").read_text() == source.read_text()


def test_a_bug_while_loading_a_profile_is_one_line_not_a_traceback(tmp_path: Path) -> None:
    """A 400-digit integer in a profile raised OverflowError in the profile check, outside any
    conversion: the traceback reached the user (tests/fuzz/findings/profile-huge-integer.yaml;
    the profile loader should refuse it at its line; until then it is an internal error)."""
    profile = Path(__file__).parent / "fuzz" / "findings" / "profile-huge-integer.yaml"
    source = tmp_path / "in.ngc"
    source.write_text("G17 G21 G0 X0 Y0\nM2\n")
    result = CliRunner().invoke(main, ["convert", str(source), "-m", str(profile), "-o",
                                       str(tmp_path / "out.nc")])
    assert result.exit_code == 2
    assert "Traceback" not in result.stderr and result.stderr.count("\n") == 1, result.stderr
    assert not (tmp_path / "out.nc").exists()


def test_usage_errors_are_still_clicks_own(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["convert", "a.nc", "b.nc"])
    assert result.exit_code == 2
    assert result.stderr.endswith("Error: several inputs need -o DIR\n")
