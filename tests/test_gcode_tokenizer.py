"""The G-code tokenizer: words, columns, comments, parameters, and one message per bad input."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nurbsfeed.errors import InputError
from nurbsfeed.gcode.tokenizer import (
    Block,
    Param,
    ParamKey,
    _scan_line,
    printable,
    tokenize_line,
)


def words(line: str, params: dict[int, Param] | None = None) -> list[tuple[str, float, int]]:
    block = tokenize_line(line, 7, "t.nc", params or {})
    return [(w.letter, w.value, w.col) for w in block.words]


@pytest.mark.parametrize("line, expected", [
    ("G01X10.5Y-.5", [("G", 1.0, 1), ("X", 10.5, 4), ("Y", -0.5, 9)]),
    ("G1 X 10.0 Y - 2", [("G", 1.0, 1), ("X", 10.0, 4), ("Y", -2.0, 11)]),
    ("x-.5 y+3", [("X", -0.5, 1), ("Y", 3.0, 6)]),
    ("\tN10 G0 X0Y0", [("N", 10.0, 2), ("G", 0.0, 6), ("X", 0.0, 9), ("Y", 0.0, 11)]),
    ("O1001 (PART)", [("O", 1001.0, 1)]),
    ("G0 (X9 Y9) X1 ; Y2 (no)", [("G", 0.0, 1), ("X", 1.0, 12)]),
    ("(only a comment)", []),
    ("", []),
])
def test_words_values_and_columns(line: str, expected: list[tuple[str, float, int]]) -> None:
    assert words(line) == expected


def test_line_number_and_text_are_kept() -> None:
    block = tokenize_line("G1 X+010.250 F#3\n", 12, "t.nc", {3: Param(1200.0, None)})
    x, f = block.words[1], block.words[2]
    assert (x.line, x.text, x.decimals, x.name) == (12, "+010.250", 3, "X+010.250")
    assert (f.value, f.text, f.col) == (1200.0, "#3", 14)


@pytest.mark.parametrize("text, decimals", [("X10", None), ("X10.", None), ("X10.50", 2),
                                            ("X.5", 1), ("X-0.0001", 4)])
def test_decimals_written(text: str, decimals: int | None) -> None:
    assert tokenize_line(text, 1, "t.nc", {}).words[0].decimals == decimals


@pytest.mark.parametrize("text, code", [("G06.2", 62), ("G6.2", 62), ("G6.20", 62), ("G01", 10),
                                        ("G1", 10), ("G17", 170), ("M06", 60), ("G5.3", 53)])
def test_g_and_m_codes_compare_by_value(text: str, code: int) -> None:
    assert tokenize_line(text, 1, "t.nc", {}).words[0].code == code


@pytest.mark.parametrize("line, eol, body_words", [
    ("G0 X1\r\n", "\r\n", 2), ("G0 X1\n", "\n", 2), ("G0 X1", "", 2),
    ("G0\rX1\n", "\n", 2),  # a lone CR inside a line is a space
])
def test_line_endings(line: str, eol: str, body_words: int) -> None:
    block = tokenize_line(line, 1, "t.nc", {})
    assert block.eol == eol and len(block.words) == body_words


def test_percent_and_block_delete() -> None:
    assert tokenize_line("%\r\n", 1, "t.nc", {}).delimiter
    assert tokenize_line("  % anything", 1, "t.nc", {}).words == ()
    skipped = tokenize_line("/G0 X5", 1, "t.nc", {})
    assert skipped.block_delete and [w.letter for w in skipped.words] == ["G", "X"]
    assert tokenize_line("/2 G0 X5", 1, "t.nc", {}).words[0].col == 4  # Fanuc /2 skip level
    assert not tokenize_line("G0 X5", 1, "t.nc", {}).block_delete


def test_inert_blocks() -> None:
    assert tokenize_line("N100 (comment)", 1, "t.nc", {}).is_inert
    assert not tokenize_line("#1=2", 1, "t.nc", {}).is_inert
    assert not tokenize_line("M5", 1, "t.nc", {}).is_inert


def test_parameters_read_before_the_lines_own_assignments() -> None:
    block = tokenize_line("#1=10.5 #2 = -#1 X#1 Y-#1", 1, "t.nc", {1: Param(2.0, 1)})
    assert [(w.letter, w.value, w.decimals) for w in block.words] == [("X", 2.0, 1),
                                                                       ("Y", -2.0, 1)]
    assert [(a.key, a.param, a.col) for a in block.assignments] == [
        (1, Param(10.5, 1), 1), (2, Param(-2.0, 1), 9)]


@pytest.mark.parametrize("line, col, message", [
    ("G1 X", 4, "X has no number after it (found the end of the line); write e.g. X10.5"),
    ("G1 XNaN", 4, "X has no number after it (found 'NaN'); write e.g. X10.5"),
    ("G1 Xinf", 4, "X has no number after it (found 'inf'); write e.g. X10.5"),
    ("G1 X1" + "0" * 400, 4, "X10000000000000000000... is too large to be a number"),
    ("G1 X[1+2]", 5, "expressions in [...] are not supported; write the value as a number"),
    ("G1 X sin[30]", 6, "'sin[...]' is an expression; expressions are not supported, write the "
                        "value as a number"),
    ("ATAN[1]/[2]", 1, "'ATAN[...]' is an expression; expressions are not supported, write the "
                       "value as a number"),
    ("G1 X#7", 5, "#7 is used before it is assigned (write #7=value on an earlier line)"),
    ("#7", 1, "'#7' must be assigned (#7=value) or follow a letter (X#7)"),
    ("G1 X##1", 5, "'#' must be followed by a parameter number or a name in <> (#1=10.5, "
                   "X#1, #<depth>=2.5); indirect (##1) parameters are not supported"),
    ("G1 Z-#<depth>", 5, "Named parameter #<depth> not defined (LinuxCNC): assign it "
                         "(#<depth> = value) on an earlier line"),
    ("G1 F#<Feed Rate>", 5, "Named parameter #<feedrate> not defined (LinuxCNC): assign it "
                            "(#<feedrate> = value) on an earlier line"),
    ("#<depth>", 1, "'#<depth>' must be assigned (#<depth>=value) or follow a letter "
                    "(X#<depth>)"),
    ("#<depth=1", 1, "'#<' starts a named parameter but no '>' closes its name on this line "
                     "(write #<depth>)"),
    ("G1 X#<depth", 5, "'#<' starts a named parameter but no '>' closes its name on this line "
                       "(write #<depth>)"),
    ("#<>=1", 1, "'#<>' is not a parameter name: a name is letters, digits and '_' between < "
                 "and > (#<depth>, #<_safe_z>)"),
    ("#<a-b>=1", 1, "'#<a-b>' is not a parameter name: a name is letters, digits and '_' "
                    "between < and > (#<depth>, #<_safe_z>)"),
    ("#<depth>=[1+1]", 10, "expressions in [...] are not supported; write the value as a number"),
    ("#1=", 1, "#1= has no number after it (found the end of the line); write e.g. #1=10.5"),
    ("WHILE [#1 LT 3] DO1", 1, "'WHILE' starts a macro or O-word statement; nurbsfeed reads "
                               "literal G-code only (no subroutines, IF/WHILE/GOTO or "
                               "expressions)"),
    ("o100 sub", 6, "'sub' starts a macro or O-word statement; nurbsfeed reads literal G-code "
                    "only (no subroutines, IF/WHILE/GOTO or expressions)"),
    ("O<probe> call", 2, "'O<name>' starts an O-word statement; nurbsfeed reads literal G-code "
                         "only (no subroutines, IF/WHILE/GOTO or expressions)"),
    ("G1 X1 (finish", 7, "comment '(' is not closed by ')' on this line"),
    ("G1.25 X1", 1, "G1.25 is not a valid G code: a whole number or one decimal from 0 to 10000 "
                    "(e.g. G6.2)"),
    ("M-3", 1, "M-3 is not a valid M code: a whole number or one decimal from 0 to 10000 "
               "(e.g. M30)"),
    ("G1 X1 /Y2", 7, "'/' (block delete) must be the first character of the line"),
    ("G1 X1 2.5", 7, "'2.5' has no letter in front of it (a word is a letter and a number, "
                     "e.g. X10.5)"),
    ("G1 X1 @2", 7, "unexpected character '@' (a word is a letter and a number, e.g. X10.5)"),
    ("G1 X1 \udc8f", 7, "unexpected character '\\x8f' (a word is a letter and a number, e.g. "
                        "X10.5)"),
    ("G1 X1 é", 7, "unexpected character 'é' (a word is a letter and a number, e.g. X10.5)"),
])
def test_bad_lines(line: str, col: int, message: str) -> None:
    with pytest.raises(InputError) as caught:
        tokenize_line(line + "\n", 4, "dir/t.nc", {})
    assert str(caught.value) == f"dir/t.nc:4:{col}: {message}"


def test_named_parameters_are_case_insensitive_and_read_before_the_lines_assignments() -> None:
    params: dict[ParamKey, Param] = {"depth": Param(2.5, 1), "_safez": Param(5.0, None)}
    block = tokenize_line("#<Depth> = 3 G1 Z-#<DEPTH> F#<_Safe Z>\n", 1, "t.nc", params)
    assert [(w.letter, w.value, w.text, w.col) for w in block.words] == [
        ("G", 1.0, "1", 14), ("Z", -2.5, "-#<depth>", 17), ("F", 5.0, "#<_safez>", 28)]
    assert block.words[1].decimals == 1
    assert [(a.key, a.param, a.col) for a in block.assignments] == [("depth", Param(3.0, None), 1)]


def test_named_and_numbered_parameters_are_separate() -> None:
    block = tokenize_line("#<1>=4 #1=7 X#1 Y#<1>\n", 1, "t.nc",
                          {1: Param(1.0, None), "1": Param(2.0, None)})
    assert [(w.letter, w.value) for w in block.words] == [("X", 1.0), ("Y", 2.0)]
    assert [a.key for a in block.assignments] == ["1", 1]


def test_printable_escapes_undecodable_bytes_and_controls() -> None:
    assert printable("a\udcff\x00b") == "a\\xff\\x00b"


# ---- properties ---------------------------------------------------------------------------------
LETTERS = "ABCDEFHIJKLNOPQRSTUVWXYZ"  # G and M carry their own value rules


@st.composite
def word_lines(draw: st.DrawFn) -> tuple[str, list[tuple[str, float, int]]]:
    """A line of well-formed words with random case and spacing, and what it must read as."""
    parts: list[str] = []
    expected = []
    col = 1
    for _ in range(draw(st.integers(1, 6))):
        letter = draw(st.sampled_from(LETTERS))
        whole = draw(st.integers(0, 99999))
        frac = draw(st.text("0123456789", max_size=4))
        sign = draw(st.sampled_from(["", "-", "+"]))
        number = f"{sign}{whole}" + (f".{frac}" if frac or draw(st.booleans()) else "")
        gap = draw(st.sampled_from(["", " ", "  "]))
        lead = draw(st.sampled_from(["", " ", "\t"])) if parts else ""
        shown = letter.lower() if draw(st.booleans()) else letter
        col += len(lead)
        expected.append((letter, float(number), col))
        parts.append(f"{lead}{shown}{gap}{number}")
        col += len(shown) + len(gap) + len(number)
    return "".join(parts), expected


@given(word_lines())
def test_generated_words_read_back_with_their_columns(case: tuple[str, list]) -> None:
    line, expected = case
    assert words(line) == expected


@settings(max_examples=400, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(alphabet=st.sampled_from(list("GXYZKPRFNO#=[]()/;%.+- 0123456789\t\r\nabcé@\udc80")),
               max_size=40))
def test_any_line_reads_or_fails_with_an_input_error(line: str) -> None:
    try:
        tokenize_line(line, 1, "t.nc", {1: Param(1.5, 1)})
    except InputError as exc:
        assert exc.location is not None and exc.location.line == 1
        assert 1 <= exc.location.col <= len(line) + 1


@settings(max_examples=400)
@given(st.text(alphabet=st.sampled_from(list("GMXYZKFN()#;/%[. +-0123456789\t\rabé")),
               max_size=30))
def test_fast_path_reads_like_the_scanner(line: str) -> None:
    """A line of plain words takes one regex pass; it must give what the full scanner gives."""
    def outcome(read: Callable[[], Block]) -> Block | str:
        try:
            return read()
        except InputError as exc:
            return str(exc)

    scanned = outcome(lambda: _scan_line(line, "", 1, "t.nc", {}))
    assert outcome(lambda: tokenize_line(line, 1, "t.nc", {})) == scanned
