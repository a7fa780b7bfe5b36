"""Issue 12: programs as people write them. LinuxCNC's own G5.2 example in each plane converts
without the axis it never sets; with an unknown axis, a line's own error is reported as that."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.errors import CurveError
from nurbsfeed.files import InputFile
from nurbsfeed.program import CurveBlock, PassThrough
from nurbsfeed.readers.gcode import read_gcode
from tests.conftest import SAMPLES


def convert_to(source: Path, target: Path) -> Path:
    """`nurbsfeed convert SOURCE -o TARGET`, which must succeed."""
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(target)],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.stderr
    return target


def convert(source: Path, tmp_path: Path) -> str:
    return convert_to(source, tmp_path / "out.nc").read_text()


def read(text: str) -> list:
    return list(read_gcode(Path("t.nc"), InputFile(Path("t.nc"), text.encode()).lines(), "auto"))


@pytest.mark.parametrize(("name", "unset"), [("xy", "Z"), ("yz", "X"), ("zx", "Y")])
def test_linuxcnc_reference_example_converts_without_its_unset_axis(tmp_path: Path, name: str,
                                                                     unset: str) -> None:
    source = SAMPLES / f"linuxcnc-nurbs-{name}.ngc"
    out = convert(source, tmp_path)
    written = out.splitlines()
    comment = next(i for i, line in enumerate(written) if line.startswith("(nurbsfeed: curve"))
    moves = written[comment + 1:-2]  # up to the restored F and M2
    record = next(i for i, line in enumerate(written) if line.startswith("(nurbsfeed profile"))
    assert len(moves) > 100
    assert moves[0].startswith("G1 ")
    assert not any(re.search(unset, move) for move in moves)
    plane = {"xy": "XY", "yz": "YZ", "zx": "ZX"}[name]
    assert {letter for move in moves for letter in re.findall("[XYZ]", move)} == set(plane)
    # everything else passes through byte for byte
    source_lines = source.read_text().splitlines()
    assert written[:record] == source_lines[:record]
    assert all(line.startswith("(nurbsfeed profile: ") for line in written[record:comment])
    assert written[-2:] == ["F100.", "M2"]


def test_an_unknown_held_axis_stays_unknown_after_the_curve() -> None:
    text = ("G17 G21 G0 X0 Y0\nF100\nG5.2 X0 Y1 P1 L3\nX2 Y2 P1\nX2 Y0 P1\nX0 Y0 P2\nG5.3\n"
            "G5.2\nX1 Y1 P1\nX2 Y0 P1\nG5.3\n")
    blocks = [item for item in read(text) if isinstance(item, CurveBlock)]
    assert len(blocks) == 2
    assert all((block.curve.points[:, 2] == 0.0).all() for block in blocks)  # held, not written
    fanuc = "G21 G90 G0 X0 Y0\nF900\nG06.2 P3 K0 X0 Y0\nK0 X10 Y10\nK0 X20 Y0\nK1\nK1\nK1\n"
    after = fanuc + "G1 X5\nG06.2 P3 K0 X5 Y0\nK0 X10 Y10\nK0 X20 Y0 Z1\nK1\nK1\nK1\n"
    with pytest.raises(Exception, match=r"^t.nc:10:1: Z is unknown here \(no move has set it"):
        read(after)
    assert sum(isinstance(item, PassThrough) for item in read(fanuc)) == 2


FANUC_UNKNOWN_Z = ("G21 G90 G0 X0 Y0\nF900\nG06.2 P3 K0 X0 Y0\nK0 X10 Y10\nK0 X20 Y0\n{}\n"
                   "K1\nK1\nK1\n")


@pytest.mark.parametrize(("line", "message"), [
    ("K-1 X30 Y5", r"^t.nc:6:1: K-1: knots must not decrease"),
    ("K0.5 X30 Y5 R-1", r"^t.nc:6:13: R-1: a weight R must be positive"),
    ("K0.5 X30 Y5 Z1 R-1", r"^t.nc:6:16: R-1: a weight R must be positive"),
])
def test_fanuc_line_errors_come_before_an_unknown_axis(line: str, message: str) -> None:
    with pytest.raises(CurveError, match=message):
        read(FANUC_UNKNOWN_Z.format(line))


def test_linuxcnc_weight_error_comes_before_an_unknown_plane_axis() -> None:
    text = "G17 G21 G0 Y0\nF100\nG5.2\nX1 Y1 P1\nX2 Y0 P-1\nG5.3\n"
    with pytest.raises(CurveError, match=r"^t.nc:5:7: P-1: a weight P must be positive"):
        read(text)


G52_WITH_LINES = ("G17 G21 G0 X0 Y0 Z0\nF600\nG5.2 X0 Y1 P1 L3\n(first comment)\n"
                  "     X2 Y2 P1\n\nN35\n; semicolon line\n     X2 Y0 P1\n(MSG, halfway)\n"
                  "     X0 Y0 P2\nG5.3\nM2\n")
G62_WITH_LINES = ("G21 G90 G0 X0 Y0 Z0\r\nF900\r\nG06.2 P3 K0 X0 Y0\r\n(c1)\r\nK0 X10 Y10\r\n\r\n"
                  "K0 X20 Y0\r\n; c2\r\nK1\r\nN10\r\nK1\r\n  (MSG, done)\r\nK1\r\nM30\r\n")


@pytest.mark.parametrize(("text", "kept"), [
    (G52_WITH_LINES, "(first comment)\n\nN35\n; semicolon line\n(MSG, halfway)\n"),
    (G62_WITH_LINES, "(c1)\r\n\r\n; c2\r\nN10\r\n  (MSG, done)\r\n"),
], ids=["linuxcnc-g5.2", "fanuc-g06.2"])
def test_lines_inside_a_nurbs_block_are_kept_in_order_before_its_moves(
        tmp_path: Path, text: str, kept: str) -> None:
    items = read(text)
    curve = next(i for i, item in enumerate(items) if isinstance(item, CurveBlock))
    assert items[curve - 1] == PassThrough(kept)
    source = tmp_path / ("in.ngc" if "G5.2" in text else "in.nc")
    source.write_bytes(text.encode())
    target = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(target)],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.stderr
    out = target.read_bytes().decode()
    record = out.index("(nurbsfeed profile: ")  # then the comment of curve 0
    assert out[:record].endswith(kept)
    assert out.count(kept) == 1
    check = CliRunner().invoke(main, ["check", str(source), str(target)], catch_exceptions=False)
    assert check.exit_code == 0, check.stdout


CURVE = ('"degree": 2, "knots": [0, 0, 0, 1, 1, 1], '
         '"control_points": [[0, 0, 0], [1, 1, 0], [2, 0, 0]]')


@pytest.mark.parametrize(("text", "message"), [
    ('{' + CURVE.replace('[0, 0, 0, 1', '[0, 0, "0", 1') + '}',
     r'1:15: curves\[0\]: knots\[2\] must be a number, not "0" \(a string\)'),
    ('{' + CURVE.replace('[1, 1, 0]', '[1, true, 0]') + '}',
     r"1:44: curves\[0\]: control_points\[1\]\[1\] must be a number, not true \(a boolean\)"),
    ('{' + CURVE + ', "weights": [1, "2", 1]}',
     r'1:\d+: curves\[0\]: weights\[1\] must be a number, not "2" \(a string\)'),
    ('{' + CURVE + ', "weights": [1, null, 1]}',
     r"1:\d+: curves\[0\]: weights\[1\] must be a number, not null$"),
    ('{"units": "mm", "curves": [{' + CURVE + '}], "feedrate": 3}',
     r"1:\d+: unknown key 'feedrate' \(known: curves, units\)"),
    ('{' + CURVE + ', "feedrate": 3}', r"1:\d+: curves\[0\]: unknown key 'feedrate'"),
])
def test_json_values_of_the_wrong_type_and_unknown_keys_are_refused(
        tmp_path: Path, text: str, message: str) -> None:
    source = tmp_path / "c.json"
    source.write_text(text)
    result = CliRunner().invoke(main, ["convert", str(source), "-o", str(tmp_path / "o.nc")])
    assert result.exit_code == 2
    assert re.search(rf"^{re.escape(str(source))}:{message}", result.stderr.strip(), re.M), \
        result.stderr
    assert not (tmp_path / "o.nc").exists()


def convert_bytes(tmp_path: Path, data: bytes, name: str = "in.ngc") -> bytes:
    source = tmp_path / name
    source.write_bytes(data)
    return convert_to(source, tmp_path / "out.nc").read_bytes()


def test_a_utf8_bom_is_accepted_and_kept(tmp_path: Path) -> None:
    program = (SAMPLES / "linuxcnc-nurbs-xy.ngc").read_bytes()
    out = convert_bytes(tmp_path, b"\xef\xbb\xbf" + program)
    assert out.startswith(b"\xef\xbb\xbf" + program[:program.index(b"F100\n") + 5])
    assert out == b"\xef\xbb\xbf" + convert_bytes(tmp_path, program)
    json_bom = b"\xef\xbb\xbf" + (SAMPLES / "circle.json").read_bytes()
    assert convert_bytes(tmp_path, json_bom, "c.json").count(b"\nG1 ") == 1


def test_cr_only_line_endings_are_lines(tmp_path: Path) -> None:
    program = (SAMPLES / "linuxcnc-nurbs-xy.ngc").read_bytes()
    out = convert_bytes(tmp_path, program.replace(b"\n", b"\r"))
    assert b"\n" not in out
    assert out == convert_bytes(tmp_path, program).replace(b"\n", b"\r")
    assert out.count(b"\rX") > 100


def profile(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "m.yaml"
    path.write_text("period_s: 0.001\nmax_feed_mm_s: 100\nchord_error_mm: 0.001\n"
                    "max_acc_mm_s2: 2000\nmax_normal_acc_mm_s2: 2000\n"
                    "max_normal_jerk_mm_s3: 50000\n" + text)
    return path


def test_yaml_exponent_without_point_or_sign_is_a_number(tmp_path: Path) -> None:
    from nurbsfeed.machine import load_machine

    assert load_machine(str(profile(tmp_path, "max_jerk_mm_s3: 1.0e9\n"))).limits.jerk_mm_s3 == 1e9
    assert load_machine(str(profile(tmp_path, "max_jerk_mm_s3: 5E4\n"))).limits.jerk_mm_s3 == 5e4


def test_yaml_duplicate_key_is_refused_at_the_second(tmp_path: Path) -> None:
    from nurbsfeed.errors import ProfileError
    from nurbsfeed.machine import load_machine

    path = profile(tmp_path, "max_jerk_mm_s3: 50000\nperiod_s: 0.002\n")
    with pytest.raises(ProfileError, match=r"m.yaml:8:1: not valid YAML \(key 'period_s' appears "
                                           r"twice\)"):
        load_machine(str(path))


@pytest.mark.parametrize("name", ["part(1).json", "a)\nG0 Z-50 (b.json", "tab\tand\x7f.json"])
def test_a_json_file_name_cannot_break_or_inject_into_the_header(tmp_path: Path,
                                                                 name: str) -> None:
    text = (SAMPLES / "circle.json").read_text()
    text = text.replace('"name": "circle"', '"name": "ci(r)cle\\u000b\\u2028"')
    out = convert_bytes(tmp_path, text.encode(), name).decode()
    header, second = out.splitlines()[:2]
    assert header.startswith("(nurbsfeed: 1 curve from ") and header.endswith(")")
    assert header.count("(") == 1 and header.count(")") == 1
    assert header.isprintable() and second == "G21 G90"
    assert "curve 0 ci[r]cle??," in out


def test_a_converted_json_program_reads_back(tmp_path: Path) -> None:
    """nurbsfeed's own output of a JSON input is a G-code program nurbsfeed reads: all its
    lines pass through unchanged (the header once nested "(s)" inside its comment)."""
    first = convert_to(SAMPLES / "butterfly.json", tmp_path / "first.nc")
    again = convert_to(first, tmp_path / "again.nc")
    assert again.read_bytes() == first.read_bytes()
