"""Whole programs through the whole pipeline: dialect equivalence, pass-through, bad programs."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from tests.conftest import SAMPLES
from tests.gcode_parse import moves

# one rational cubic; uniform clamped integer knots (what LinuxCNC G5.2 generates for 6 points)
POINTS = [(0.0, 0.0), (10.0, 15.0), (25.0, 15.0), (35.0, 0.0), (45.0, -15.0), (60.0, -10.0)]
WEIGHTS = [1.0, 1.5, 0.8, 1.0, 1.2, 1.0]
KNOTS = [0, 0, 0, 0, 1, 2, 3, 3, 3, 3]


def as_json() -> str:
    cps = ", ".join(f"[{x}, {y}]" for x, y in POINTS)
    return (f'{{"degree": 3, "knots": {KNOTS}, "control_points": [{cps}], '
            f'"weights": {WEIGHTS}, "feed": 3000}}')


def as_fanuc() -> str:
    lines = ["%", "O0001", "G17 G21 G90 G94", "G0 X0. Y0. Z0."]
    for j, ((x, y), w) in enumerate(zip(POINTS, WEIGHTS)):
        head = "G06.2 P4 " if j == 0 else ""
        tail = " F3000." if j == 0 else ""
        lines.append(f"{head}K{KNOTS[j]}. X{x} Y{y} R{w}{tail}")
    lines += [f"K{k}." for k in KNOTS[len(POINTS):]]
    lines += ["G1 X70.", "M30", "%"]
    return "\r\n".join(lines) + "\r\n"


def as_linuxcnc() -> str:
    # the current position (0, 0) is the first control point, with weight 1
    lines = ["G17 G21 G90", "G0 X0 Y0 Z0", "F3000"]
    (x1, y1), w1 = POINTS[1], WEIGHTS[1]
    lines.append(f"G5.2 X{x1} Y{y1} P{w1} L4")
    lines += [f"X{x} Y{y} P{w}" for (x, y), w in zip(POINTS[2:], WEIGHTS[2:])]
    lines += ["G5.3", "G1 X70", "M2"]
    return "\n".join(lines) + "\n"


def our_lines(text: str) -> list[str]:
    """Every line nurbsfeed wrote in place of the curves (moves, G90/G91, F restore)."""
    out, inside = [], False
    for line in text.splitlines():
        if line.startswith("(nurbsfeed: curve"):
            inside = True
        elif inside and re.match(r"^(G1 )?[XYZF][-\d.]|^G9[01]$", line):
            out.append(line)
        else:
            inside = False
    return out


def moves_of(text: str) -> list[str]:
    """The G1 lines written in place of the first curve."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("(nurbsfeed: curve 0"))
    out = []
    for line in lines[start + 1:]:
        if not re.match(r"^(G1 )?[XYZ]", line) or line.startswith("G1 X70"):
            break
        out.append(line)
    return out


def convert(tmp_path: Path, name: str, text: str, *args: str) -> tuple[int, str, str]:
    src = tmp_path / name
    src.write_bytes(text.encode())
    result = CliRunner().invoke(main, ["convert", str(src), "-m", "paper-table1", *args],
                                catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def test_same_curve_as_json_fanuc_and_linuxcnc_gives_identical_moves(tmp_path: Path) -> None:
    outputs = {}
    for name, text in (("c.json", as_json()), ("c.nc", as_fanuc()), ("c.ngc", as_linuxcnc())):
        code, stdout, stderr = convert(tmp_path, name, text)
        assert code == 0, stderr
        outputs[name] = moves_of(stdout)
    assert len(outputs["c.json"]) > 500
    assert outputs["c.json"] == outputs["c.nc"] == outputs["c.ngc"]
    end = moves(outputs["c.json"] and "\n".join(["(x)"] + outputs["c.json"]), [0, 0, 0])[0][-1]
    assert np.array_equal(end, [60.0, -10.0, 0.0])


def test_every_non_nurbs_line_passes_through_byte_for_byte(tmp_path: Path) -> None:
    code, stdout, _ = convert(tmp_path, "c.nc", as_fanuc())
    out = (tmp_path / "o.nc")
    CliRunner().invoke(main, ["convert", str(tmp_path / "c.nc"), "-m", "paper-table1", "-o",
                              str(out)])
    data = out.read_bytes()
    kept = [line for line in as_fanuc().encode().split(b"\r\n")
            if line and not line.startswith((b"G06.2", b"K"))]
    produced = iter(data.split(b"\r\n"))
    assert all(any(line == out for out in produced) for line in kept)  # in order, unchanged
    assert b"\n" not in data.replace(b"\r\n", b"")


@pytest.mark.parametrize("sample", sorted(p.name for p in SAMPLES.iterdir()
                                          if p.suffix in (".nc", ".ngc")))
def test_every_sample_program_converts_and_keeps_its_other_lines(tmp_path: Path,
                                                                  sample: str) -> None:
    out = tmp_path / sample
    result = CliRunner().invoke(main, ["convert", str(SAMPLES / sample), "-o", str(out), "-q"])
    assert result.exit_code == 0, result.stderr
    source = (SAMPLES / sample).read_bytes()
    produced = out.read_bytes()
    assert produced.count(b"(nurbsfeed: curve") >= 1  # a curve, or a chain of curves
    # numbers written by us always carry a decimal point, never -0.
    ours = [line.encode() for line in our_lines(produced.decode())]
    assert ours and not any(re.search(rb"[XYZF]-?\d+(\s|$)", line) for line in ours)
    assert not any(re.search(rb"-0\.0*(\s|$)", line) for line in ours)
    # the first and last line of the program are untouched
    assert produced.splitlines()[0] == source.splitlines()[0]
    assert produced.splitlines()[-1] == source.splitlines()[-1]


def test_a_malformed_program_fails_with_its_line_and_leaves_no_file(tmp_path: Path) -> None:
    bad = as_fanuc().replace("K3.\r\nK3.\r\nK3.\r\nK3.\r\n", "K3.\r\nK3.\r\nK2.\r\nK3.\r\n")
    src = tmp_path / "bad.nc"
    src.write_bytes(bad.encode())
    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["convert", str(src), "-o", str(out)])
    assert result.exit_code == 2
    assert result.stderr.startswith(f"{src}:")
    line = int(result.stderr.split(":")[1])
    assert bad.split("\r\n")[line - 1].startswith("K") and "Traceback" not in result.stderr
    assert not out.exists() and sorted(os.listdir(tmp_path)) == ["bad.nc"]
