"""The plain-move fast path of the G-code reader (gcode.plain_moves): a line it reads yields the
item the words would, joins and words flags included, leaves the same modal state behind (the
lines after it read the same), and every line it cannot execute exactly goes to the words."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings

from nurbsfeed.errors import InputError
from nurbsfeed.program import PassThrough
from nurbsfeed.readers import gcode as gcode_reader
from tests.conftest import examples
from tests.test_gcode_reader import PREAMBLE, mutated_programs, points_curve, read

CURVE = "G06.2 P3 K0 X0 Y0 Z0 F600\nK0 X1 Y1 Z0\nK0 X2 Y0 Z0\nK1\nK1\nK1\n"
CASES = {
    "every form": PREAMBLE + ("G1 X1. Y2.5 Z-3.25 F1200.\nN10 G01 X1.5\nG0 Z5.\nG00 X-.5 Y+2\n"
                              "X1 Y2\nY3\nZ0.125 F600\nF900\nN20 X4 F300.\nG1 Z1\n"),
    "crlf, and no newline at the end": (PREAMBLE + "G1 X1 Y2\nX3 Y4 F500\nZ1").replace("\n",
                                                                                      "\r\n"),
    "a lone CR at the end": PREAMBLE + "G1 X1 Y2\r",
    "a negative F": PREAMBLE + "G1 X1 F-5.\n",
    "a number too large": PREAMBLE + "G1 X1" + "9" * 400 + "\n",
    "an exponent": PREAMBLE + "G1 X1e3\n",
    "words out of order, repeated, lower case, spaced": PREAMBLE + ("G1 Y1 X2\nG1 X1 X2\ng1 x1\n"
                                                                  "G1  X1\nG1 X1 \nG1\tX1\n"),
    "G2 in force, a canned cycle in force": PREAMBLE + ("G2 X1 Y1 I.5 J0\nX2 Y2\nG81 Z-1 R1\n"
                                                        "X1 Y1\nG80\nX3 Y3\n"),
    "no motion mode yet": "G21 G90\nX1 Y2 Z3\nG1 X2\n",
    "G91, positions unknown and known": "G21 G91\nG1 X1 Y1\nG90 G0 X0 Y0 Z0\nG91\nG1 X1.5 Y-.25\n"
                                        "Z.125\nG90\n" + CURVE.replace("X0 Y0 Z0 F600",
                                                                       "X1.5 Y-.25 Z.125 F600"),
    "inches": "G20 G90 G0 X0 Y0 Z0\nG1 X.1 Y.2 F10\nG21\nG1 X3 Y4\n",
    "after a curve: modal G06.2, then moves": (PREAMBLE + CURVE + "X1 Y2\n"),
    "after a curve: G1 ends it": (PREAMBLE + CURVE + "G1 X1 Y2\nX3\n"),
    "between curves of a chain": (PREAMBLE + CURVE + "G1 X2 Y0 Z0\nN5 G1 F600\nG1 X2. Y0. Z0.\n"
                                  + CURVE.replace("X0 Y0 Z0", "X2 Y0 Z0").replace("K0 X1 Y1",
                                                                                  "K0 X3 Y1")
                                  .replace("K0 X2 Y0", "K0 X4 Y0") + "G1 X4.0004 Y0\nM30\n"),
    "a point after a run": points_curve([f"K{j} X{j} Y{j} Z0\n" for j in range(1, 9)])
                           + "G1 X8 Y8 Z0\n",
    "after a G5 in G2": ("G21 G90 G17\nG0 X0 Y0 Z0 F600\nG2 X1 Y1 I.5 J0\n"
                         "G5 I1 J0 P1 Q0 X2 Y1\nX3 Y3\nG1 X4\n"),
}


def outcome(text: str, dialect: str) -> object:
    """Everything a read yields, pass-through flags included (or the error it raises)."""
    try:
        items = read(text, dialect)
    except InputError as exc:
        return type(exc).__name__, str(exc)
    return [(item.text, item.joins, item.words) if isinstance(item, PassThrough) else
            (item.curve.knots.tolist(), item.curve.points.tolist(), item.location, item.units,
             item.incremental, item.feed_word_after, item.feed_u.tolist(),
             item.feed_mm_s.tolist()) for item in items]


def by_the_words(text: str, dialect: str) -> object:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(gcode_reader, "plain_move", lambda line_text, line: None)
        return outcome(text, dialect)


@pytest.mark.parametrize("dialect", ["auto", "fanuc", "linuxcnc", "siemens"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_plain_moves_read_like_the_words(name: str, dialect: str) -> None:
    assert outcome(CASES[name], dialect) == by_the_words(CASES[name], dialect)


def test_plain_moves_are_read_without_the_words() -> None:
    taken = 0
    plain_move = gcode_reader.plain_move

    def counting(line_text: str, line: int) -> object:
        nonlocal taken
        read_move = plain_move(line_text, line)
        taken += read_move is not None
        return read_move

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(gcode_reader, "plain_move", counting)
        read(CASES["every form"])
    assert taken == 11  # all but "G17 G21 G90 G94"


@settings(max_examples=examples(500), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(mutated_programs())
def test_plain_moves_read_mutated_programs_like_the_words(case: tuple[str, str]) -> None:
    text, dialect = case
    assert outcome(text, dialect) == by_the_words(text, dialect)
