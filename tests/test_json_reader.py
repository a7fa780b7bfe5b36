"""JSON curves read as a stream: one curve in memory, every key located inside its own curve,
and input at the extremes (huge numbers, deep nesting, bytes that are not UTF-8, lone
surrogates) refused with FILE:LINE:COL, exit 2 and no output, or converted into valid UTF-8."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from nurbsfeed.readers import json_text
from nurbsfeed.readers.json_curves import read_json_curves
from tests.bench.programs import json_program
from tests.test_cli import run

LINE = '"degree": 1, "knots": [0,0,1,1], "control_points": [[0,0],[1,1]]'
POINT = '{"curves": [{"degree": 1, "knots": [0,0,1,1], "control_points": [[0,0],[%s,1]]}]}'
DEEP = 100_000

EXTREME_JSON = [
    (POINT % ("1" * 5000), "1:73: an integer of more than 4300 digits is out of range"),
    # json reads these as inf and int(): out of a double's range, said so where written
    (POINT % "1e400", "1:73: curves[0]: 'control_points' holds a number out of range (a double "
     "holds magnitudes up to 1.798e+308)"),
    (POINT % "-1e999999999", "1:73: curves[0]: 'control_points' holds a number out of range"),
    (POINT % ("1" * 400), "1:73: curves[0]: 'control_points' holds a number out of range"),
    ('{"curves": [{%s, "feed": %s}]}' % (LINE, "9" * 400),
     "1:88: curves[0]: 'feed' holds a number out of range"),
    ('{"curves": [{"degree": 1e309, "knots": [0,0,1,1], "control_points": [[0,0],[1,1]]}]}',
     "1:24: curves[0]: 'degree' holds a number out of range"),
    ('{"curves": ' + "[" * DEEP + "]" * DEEP + "}",
     "1:913: nested deeper than nurbsfeed reads JSON (a curve needs 2 levels of lists)"),
    (POINT % ("[" * DEEP + "]" * DEEP), "1:970: nested deeper"),  # past 900 levels in a curve
    # nested, but within what the decoder follows
    (POINT % ("[" * 500 + "]" * 500), "1:47: curves[0]: control points must be lists of 2 or 3 "
     "numbers"),
    (POINT % ('{"a": ' * 500 + "1" + "}" * 500), '1:47: curves[0]: control_points[1][0] must be a '
     'number, not {"a": {"a": {"a": {"a": {"a": {"a": {"a": {"a": {"a": {"a... (an object)'),
    ('{"curves": [{"name": %s, %s}]}' % ("[" * 500 + "]" * 500, LINE),
     "1:14: curves[0]: 'name' must be a string, not a list"),
    ('{"curves": [{%s, "feed": [[[[1]]]]}]}' % LINE,
     "1:80: curves[0]: 'feed' must be a positive number (length/min), not [[[[1]]]]"),
    ('{"units": ' + "[" * 500 + "]" * 500 + ', "curves": [{%s}]}' % LINE,
     "1:2: 'units' must be \"mm\" or \"in\", not [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["
     "[[[[[[[[..."),
    ('{"units": "\\udc80", "curves": [{%s}]}' % LINE,
     "1:2: 'units' must be \"mm\" or \"in\", not '\\udc80'"),
    ('{"curves": [{%s}], "curves": [{%s}]}' % (LINE, LINE), "1:82: 'curves' appears twice"),
    ('{"curves": [{%s}]} {}' % LINE, "1:82: not valid JSON: Extra data"),
    ('{"curves": [{%s},]}' % LINE, "1:80: not valid JSON: Expecting value"),
    ('{"curves": [{%s}]' % LINE, "1:80: not valid JSON: Expecting ',' delimiter"),
    ("", "1:1: not valid JSON: Expecting value"),
]


@pytest.mark.parametrize(("content", "message"), EXTREME_JSON)
def test_extreme_json_gives_file_line_col_exit_2_and_no_output(tmp_path: Path, content: str,
                                                               message: str) -> None:
    src = tmp_path / "in.json"
    src.write_text(content, encoding="utf-8", errors="surrogatepass")
    out = tmp_path / "out.nc"
    code, _, stderr = run("convert", str(src), "-o", str(out))
    assert code == 2
    assert stderr.startswith(f"{src}:{message}") and stderr.count("\n") == 1
    assert "Traceback" not in stderr and "internal error" not in stderr
    assert os.listdir(tmp_path) == ["in.json"]


@pytest.mark.parametrize(("content", "message"), [
    (b'{"curves": [{"name": "caf\xe9",\n' + LINE.encode() + b"}]}",
     "1:26: not UTF-8: byte 0xE9 (a JSON file is UTF-8)"),
    (b'{"curves": [\n{"name": "\xe2\x82\xac \xe2\x82",' + LINE.encode() + b"}]}",
     "2:13: not UTF-8: byte 0xE2 (a JSON file is UTF-8)"),
    ('{"curves": []}'.encode("utf-16"), "1:1: not UTF-8: byte 0xFF (a JSON file is UTF-8)"),
])
def test_a_json_file_that_is_not_utf8_is_refused_at_the_byte(tmp_path: Path, content: bytes,
                                                             message: str) -> None:
    src = tmp_path / "in.json"
    src.write_bytes(content)
    code, _, stderr = run("convert", str(src), "-o", str(tmp_path / "out.nc"))
    assert (code, stderr) == (2, f"{src}:{message}\n")


@pytest.mark.parametrize("name", ["\\ud800", "\\udc80", "a\\udfffb", "\\u0000)(\\n"])
def test_a_lone_surrogate_or_control_character_in_a_name_gives_valid_utf8(tmp_path: Path,
                                                                          name: str) -> None:
    """json decodes "\\ud800" to a lone surrogate, which the output encoding would turn into
    bytes that are not UTF-8 (or fail on): the name is made comment-safe first."""
    src = tmp_path / "in.json"
    src.write_text('{"curves": [{"name": "%s", %s}]}' % (name, LINE))
    out = tmp_path / "out.nc"
    assert run("convert", str(src), "-o", str(out), "-q")[0] == 0
    text = out.read_bytes().decode("utf-8")  # strict
    comment = next(line for line in text.splitlines() if line.startswith("(nurbsfeed: curve"))
    assert comment.startswith("(nurbsfeed: curve 0 ") and comment.count("(") == 1
    assert run("convert", str(out), "-o", str(tmp_path / "again.nc"), "-q")[0] == 0


def test_negative_zero_is_written_as_zero(tmp_path: Path) -> None:
    src = tmp_path / "in.json"
    src.write_text('{"degree": 1, "knots": [0,0,1,1], "control_points": [[-0,-0.0],[1,1]]}')
    out = tmp_path / "out.nc"
    assert run("convert", str(src), "-o", str(out), "-q")[0] == 0
    assert out.read_text().splitlines()[2] == "G0 X0. Y0. Z0."


def test_a_single_curve_object_may_give_its_units(tmp_path: Path) -> None:
    src = tmp_path / "in.json"
    src.write_text('{"units": "in", %s}' % LINE)
    out = tmp_path / "out.nc"
    assert run("convert", str(src), "-o", str(out), "-q")[0] == 0
    assert out.read_text().splitlines()[1:3] == ["G20 G90", "G0 X0. Y0. Z0."]


def test_errors_point_into_their_own_curve(tmp_path: Path) -> None:
    """A key is found inside the curve it belongs to, whatever the curves before it hold (the
    n-th occurrence of the key in the file is not the n-th curve's when one omits it)."""
    src = tmp_path / "in.json"
    src.write_text('{"curves": [\n {%s},\n {%s, "weights": [1, 1]},\n {%s, "weights": [1, -1]}'
                   "]}" % (LINE, LINE, LINE))
    code, _, stderr = run("convert", str(src), "-o", str(tmp_path / "out.nc"))
    assert (code, stderr) == (2, f"{src}:4:69: curves[2]: weight 1 must be positive and finite, "
                                 "not -1.0\n")


def test_curves_read_in_small_pieces_are_the_curves_read_whole(tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch
                                                              ) -> None:
    """Pieces of 7 bytes cut numbers, keys, escapes and multi-byte characters anywhere."""
    curves = json.loads(json_program(5))["curves"]
    for i, curve in enumerate(curves):
        curve["name"] = f"courbe \u00e9t\u00e9 \u20ac{i} \U0001f600 \\\" \u2028"
    src = tmp_path / "in.json"
    src.write_text(json.dumps({"curves": curves, "units": "in"}, ensure_ascii=False, indent=1))
    whole = read_json_curves(src)
    monkeypatch.setattr(json_text, "PIECE_BYTES", 7)
    pieces = read_json_curves(src)
    assert whole[0] == pieces[0] == "in"
    assert [c.name for c, _ in whole[1]] == [c.name for c, _ in pieces[1]]
    assert [c.name for c, _ in whole[1]][1] == "courbe \u00e9t\u00e9 \u20ac1 \U0001f600 \\\" ?"
    for (a, _), (b, _) in zip(whole[1], pieces[1]):
        assert (a.points == b.points).all() and (a.knots == b.knots).all()


def test_memory_holds_one_curve_not_the_file(tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """The decoded text in memory (the window) stays within a piece and the longest curve
    however many curves the file holds; a value longer than a piece (a long line) is read."""
    src = tmp_path / "in.json"
    curves = json.loads(json_program(200))["curves"]
    curves[30]["name"] = "x" * 50_000  # one long value, on the one line of the file
    src.write_text(json.dumps({"curves": curves}))
    longest = max(len(json.dumps(c)) for c in curves)
    monkeypatch.setattr(json_text, "PIECE_BYTES", 1024)
    widest = 0
    more = json_text.JsonText._more

    def measured(self: json_text.JsonText) -> bool:
        nonlocal widest
        grew = more(self)
        widest = max(widest, len(self.window))
        return grew

    monkeypatch.setattr(json_text.JsonText, "_more", measured)
    units, read = read_json_curves(src)
    bound = 2 * longest + 3 * 1024
    assert len(read) == 200 and read[30][0].name == "x" * 50_000
    assert widest < bound < src.stat().st_size / 4
