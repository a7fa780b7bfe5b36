"""Hypothesis strategies for the four fuzz families: G-code programs, JSON curve documents, YAML
machine profiles, and byte-level mutations of the bundled samples.

Each strategy draws a valid input first (small curves, a few mm long, so that a good share of
cases really converts in milliseconds) and then, for most cases, perturbs it the way people and
tools do: a word missing or twice, comments and blank lines inside blocks, odd numbers, other
line endings, stray bytes. A case is `Case`.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

from hypothesis import strategies as st


@dataclass(frozen=True)
class Case:
    """One input: its file name (the suffix picks the reader), bytes, an optional machine
    profile, and whether it was drawn valid (then it must convert and pass `nurbsfeed check`)."""

    name: str
    data: bytes
    profile: bytes | None = None
    valid: bool = False

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
SAMPLE_FILES = sorted(p for p in SAMPLES.iterdir() if p.is_file())
EASY_GCODE = SAMPLES / "linuxcnc-nurbs-xy.ngc"  # the input of the profile family

# ---- numbers ----------------------------------------------------------------------------------

ODD_NUMBERS = ["5", "5.", ".5", "+5", "-.5", "-0.", "+.0", "1e3", "1E-3", "0x10", "5..", "--5",
               "+-5", "9" * 40, "9" * 400 + ".", "0." + "0" * 400 + "1", "1" * 5000, "#1",
               "#99", "-#1", "#" + "9" * 5000, "#<x>", "##1", "[1+2]", "SIN[0]", "\uff15",
               "\u0665", "5\uff0e", "nan", "inf", "", " ", "\t5", "5 .5", "1_000"]


@functools.cache  # one strategy per range: hypothesis validates each new one
def numbers(low: float, high: float) -> st.SearchStrategy[str]:
    """A value in [low, high] written as people write it: 5. 5.0 .5 +5 5 05.000"""
    def spell(value: float, style: int) -> str:
        text = f"{value:.4f}".rstrip("0")
        if style == 0:
            return text
        if style == 1:
            return text if not text.endswith(".") else text[:-1]  # calculator style: "5"
        if style == 2:
            return text if text.startswith("-") else "+" + text
        if style == 3:
            return text[1:] if text.startswith("0.") and len(text) > 2 else text
        return f"{value:.6f}"
    return st.builds(spell, st.floats(low, high, allow_nan=False).map(lambda v: round(v, 3)),
                     st.integers(0, 4))


# ---- G-code programs --------------------------------------------------------------------------

@st.composite
def fanuc_curve(draw: st.DrawFn, start: tuple[float, float, float], linuxcnc: bool
                ) -> list[str]:
    """A G06.2 (or LinuxCNC G6.2) curve from `start`: control point lines, then knot lines."""
    order = draw(st.integers(2, 4 if not linuxcnc else 5))
    n_points = draw(st.integers(order, order + 4))
    interior = sorted(draw(st.lists(st.integers(1, 9), min_size=n_points - order,
                                    max_size=n_points - order)))
    # an interior value at most order - 1 times: spread repeats
    seen: dict[int, int] = {}
    spread = []
    for value in interior:
        while seen.get(value, 0) >= order - 1:
            value += 10
        seen[value] = seen.get(value, 0) + 1
        spread.append(value)
    interior = sorted(spread)
    top = (max(interior) + 1) if interior else 1
    knots = [0] * order + interior + [top] * order
    num = lambda low, high: draw(numbers(low, high))  # noqa: E731
    lines = []
    point = start
    for j in range(n_points):
        words = [f"K{knots[j]}" if draw(st.booleans()) else f"K{knots[j]}."]
        if j == 0:
            axes = [f"X{point[0]:g}.", f"Y{point[1]:g}.", f"Z{point[2]:g}."]
            words = (["G06.2" if not linuxcnc else "G6.2", f"P{order}"]
                     + (["Q1"] if linuxcnc else []) + words + axes)
        else:
            axes = [f"X{num(0, 5)}", f"Y{num(0, 5)}"]
            if draw(st.booleans()):
                axes.append(f"Z{num(-1, 1)}")
            words += axes
        if draw(st.integers(0, 3)) == 0:
            words.append(f"R{num(0.5, 2)}")
        if draw(st.integers(0, 5)) == 0:
            words.append(f"F{draw(st.integers(300, 3000))}.")
        lines.append(" ".join(words))
    for knot in knots[n_points:]:
        lines.append(("G6.2 " if linuxcnc and draw(st.booleans()) else "") + f"K{knot}.")
    return lines


@st.composite
def g52_block(draw: st.DrawFn, plane: tuple[str, str]) -> list[str]:
    """A LinuxCNC G5.2 ... G5.3 block in the current plane, from the current position."""
    order = draw(st.integers(3, 5))
    n_points = draw(st.integers(max(order - 1, 1), order + 3))  # the start point counts too
    num = lambda low, high: draw(numbers(low, high))  # noqa: E731
    lines = []
    for j in range(n_points):
        words = [f"{plane[0]}{num(0, 5)}", f"{plane[1]}{num(0, 5)}", f"P{num(0.5, 2)}"]
        if j == 0:
            words = ["G5.2"] + words + ([f"L{order}"] if order != 3 or draw(st.booleans())
                                        else [])
        lines.append(("     " if j else "") + " ".join(words))
    if n_points + 1 < order:
        lines.append(f"{plane[0]}1 {plane[1]}1 P1")
    lines.append("G5.3")
    return lines


@st.composite
def valid_program(draw: st.DrawFn) -> tuple[str, list[str]]:
    """(suffix, lines) of a program with one to three NURBS curves of one dialect."""
    dialect = draw(st.sampled_from(["fanuc", "linuxcnc-g52", "linuxcnc-g62"]))
    inch = draw(st.integers(0, 5)) == 0
    lines = ["%"] if draw(st.booleans()) else []
    lines += ["(fuzz program)", f"G17 {'G20' if inch else 'G21'} G40 G49 G80 G90 G94"]
    plane = ("X", "Y")
    if dialect == "linuxcnc-g52" and draw(st.booleans()):
        plane = draw(st.sampled_from([("Z", "X"), ("Y", "Z")]))
        lines[-1] = lines[-1].replace("G17", "G18" if plane == ("Z", "X") else "G19")
    start = (draw(st.integers(0, 3)), draw(st.integers(0, 3)), 0)
    lines.append(f"G0 X{start[0]}. Y{start[1]}. Z{start[2]}.")
    lines.append(f"G1 F{draw(st.integers(200, 3000))}.")
    for _ in range(draw(st.integers(1, 3))):
        if dialect == "fanuc":
            lines += draw(fanuc_curve(start, linuxcnc=False))
        elif dialect == "linuxcnc-g62":
            lines += draw(fanuc_curve(start, linuxcnc=True))
        else:
            lines += draw(g52_block(plane))
        start = (draw(st.integers(0, 3)), draw(st.integers(0, 3)), 0)
        lines.append(f"G1 X{start[0]}. Y{start[1]}. Z{start[2]}.")
    lines += [draw(st.sampled_from(["M30", "M2", "G0 Z5.\nM30"]))]
    if lines[0] == "%":
        lines.append("%")
    return (".nc" if dialect == "fanuc" else ".ngc"), "\n".join(lines).split("\n")


INSERTED_LINES = ["", "(a comment)", "; semicolon comment", "N100", "N0005", "(MSG, halfway)",
                  "%", "G20", "G21", "G90", "G91", "G17", "G18", "G19", "G40", "G41 D1", "G93",
                  "G95", "F0", "F600", "#1=5.", "#1=2", "#2=#1", "M3 S1000", "G1 X1. Y1.",
                  "G0 Z5.", "G5.3", "G5.2", "G06.2", "G6.2 K1.", "K1.", "K0.", "X1 Y1 P1",
                  "G2.2", "G5.4", "O100 sub", "IF [#1 GT 0] GOTO 10", "/N10 G1 X0", "(", ")",
                  "G05.1 Q1", "G05.1 Q0", "G28 Z0.", "G4 X1.5", "T1 M6", "M30", "N10 G06.2 P3"]
NURBS_TYPOS = {"G06.2": ["G06.3", "G6", "G062", "G06,2", "G06.2.", "G 06 .2", "G06.20"],
               "G6.2": ["G6.3", "G62", "G6..2", "G6.2.2", "G06.2"],
               "G5.2": ["G2.2", "G52", "G5.1", "G05.2", "G5.20", "G5 .2", "G5.3"],
               "G5.3": ["G3.3", "G53", "G5.2", "G05.3", "G5.4"]}
ODD_BYTES = [b"\x00", b"\xff", b"\xc3", b"\xed\xa0\x80", b"\xef\xbb\xbf", b"\r", b"\t", b"\x0b",
             b"\x1a", b"\xe2\x80\xa8", b"\xc2\xa0"]


@st.composite
def perturbed_lines(draw: st.DrawFn, lines: list[str]) -> list[str]:
    """`lines` with a few edits of the kinds people make."""
    lines = list(lines)
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.integers(0, 10))
        at = draw(st.integers(0, max(len(lines) - 1, 0)))
        if not lines:
            lines.append(draw(st.sampled_from(INSERTED_LINES)))
        elif kind == 0:
            del lines[at]
        elif kind == 1:
            lines.insert(at, lines[at])
        elif kind in (2, 3):
            lines.insert(at, draw(st.sampled_from(INSERTED_LINES)))
        elif kind == 4:  # a word dropped or given twice
            words = lines[at].split()
            if words:
                w = draw(st.integers(0, len(words) - 1))
                if draw(st.booleans()):
                    del words[w]
                else:
                    words.insert(w, words[w])
                lines[at] = " ".join(words)
        elif kind == 5:  # a number written oddly
            words = lines[at].split()
            if words:
                w = draw(st.integers(0, len(words) - 1))
                words[w] = words[w][:1] + draw(st.sampled_from(ODD_NUMBERS))
                lines[at] = " ".join(words)
        elif kind == 6:  # spacing: tabs, none, many
            sep = draw(st.sampled_from(["\t", "", "  ", " \t "]))
            lines[at] = sep.join(lines[at].split(" "))
        elif kind == 7:  # case
            lines[at] = lines[at].lower() if draw(st.booleans()) else lines[at].upper()
        elif kind == 8:  # a trailing comment or an inline one
            comment = draw(st.sampled_from(["(c)", ";c", "(MSG, x)", "( nested ( )", "(K1.)"]))
            lines[at] = lines[at] + comment if draw(st.booleans()) else comment + lines[at]
        elif kind == 10:  # a NURBS code mistyped
            for code, typos in NURBS_TYPOS.items():
                if code in lines[at]:
                    lines[at] = lines[at].replace(code, draw(st.sampled_from(typos)), 1)
                    break
        else:  # a word with a letter nobody expects
            lines[at] += " " + draw(st.sampled_from(["Q1", "E5.", "A10.", "U1.", "L4", "P2",
                                                     "R0", "R-1", "K-1.", "H1", "D1", "S100"]))
    return lines


@st.composite
def encode_program(draw: st.DrawFn, lines: list[str], perturb: bool) -> bytes:
    eol = draw(st.sampled_from(["\n", "\r\n", "\r"])) if perturb or draw(st.booleans()) else "\n"
    data = (eol.join(lines) + (eol if draw(st.integers(0, 4)) else "")).encode("utf-8")
    if perturb and draw(st.integers(0, 3)) == 0:
        data = b"\xef\xbb\xbf" + data
    if perturb and draw(st.integers(0, 3)) == 0:
        at = draw(st.integers(0, len(data)))
        data = data[:at] + draw(st.sampled_from(ODD_BYTES)) + data[at:]
    return data


@st.composite
def gcode_cases(draw: st.DrawFn) -> Case:
    """Half the programs are left valid."""
    suffix, lines = draw(valid_program())
    perturb = draw(st.booleans())
    if perturb:
        lines = draw(perturbed_lines(lines))
    return Case("in" + suffix, draw(encode_program(lines, perturb)), valid=not perturb)


# ---- JSON curve documents ---------------------------------------------------------------------

@st.composite
def json_curve(draw: st.DrawFn) -> dict:
    degree = draw(st.integers(1, 4))
    n_points = draw(st.integers(degree + 1, degree + 5))
    interior = sorted(draw(st.lists(st.floats(0.05, 0.95).map(lambda v: round(v, 3)),
                                    min_size=n_points - degree - 1,
                                    max_size=n_points - degree - 1, unique=True)))
    coord = st.floats(-5, 5).map(lambda v: round(v, 3))
    curve = {"degree": degree, "knots": [0] * (degree + 1) + interior + [1] * (degree + 1),
             "control_points": draw(st.lists(st.lists(coord, min_size=3, max_size=3),
                                             min_size=n_points, max_size=n_points))}
    if draw(st.booleans()):
        curve["weights"] = draw(st.lists(st.floats(0.5, 2).map(lambda v: round(v, 3)),
                                         min_size=n_points, max_size=n_points))
    if draw(st.booleans()):
        curve["feed"] = draw(st.floats(5, 50).map(lambda v: round(v, 2)))
    if draw(st.booleans()):
        curve["name"] = draw(st.text(max_size=12))
    return curve


JSON_ODD_VALUES = [None, True, False, "1", "", [], {}, [[]], -1, 0, 1e308, -1e308, 1e-320,
                   10**400, "\ud800", "\udfff", "x" * 10000, [1] * 1000, 2**63, 0.5, "mm", "in",
                   "inch", 3.5, -0.0]


def _deep(depth: int) -> str:
    return "[" * depth + "]" * depth


@st.composite
def perturbed_json(draw: st.DrawFn, document: dict) -> str:
    kind = draw(st.integers(0, 7))
    curves = document["curves"]
    curve = curves[draw(st.integers(0, len(curves) - 1))]
    if kind == 0:  # a key dropped
        victim = draw(st.sampled_from(sorted(curve)))
        del curve[victim]
    elif kind == 1:  # a value of another type or size
        key = draw(st.sampled_from(sorted(curve) + ["units"]))
        target = document if key == "units" else curve
        target[key] = draw(st.sampled_from(JSON_ODD_VALUES))
    elif kind == 2:  # one element of a list
        key = draw(st.sampled_from(["knots", "control_points", "weights"]))
        if curve.get(key):
            index = draw(st.integers(0, len(curve[key]) - 1))
            curve[key][index] = draw(st.sampled_from(JSON_ODD_VALUES))
    elif kind == 3:  # an extra key
        curve[draw(st.sampled_from(["feedrate", "Degree", "knots ", "", "\ud800"]))] = 1
    elif kind == 4:  # the document's shape
        choice = draw(st.integers(0, 5))
        text = ["[]", "null", "{}", '{"curves": []}', '{"curves": {}}', '"curves"'][choice]
        return text
    elif kind == 5:  # deep nesting somewhere
        text = json.dumps(document)
        depth = draw(st.sampled_from([10, 1000, 100000]))
        return text.replace('"knots": [', '"knots": [' + _deep(depth) + ",", 1)
    elif kind == 6:  # huge numbers as text
        text = json.dumps(document)
        return text.replace("0,", draw(st.sampled_from(["1" * 5000 + ",", "1e999,", "-1e999,",
                                                        "NaN,", "Infinity,", "0." + "0" * 5000 +
                                                        "1,"])), 1)
    else:  # a cut or a stray byte
        text = json.dumps(document)
        at = draw(st.integers(0, len(text)))
        return text[:at] + draw(st.sampled_from(["", "\x00", "}", ",", "\\", '"'])) + \
            text[at + draw(st.integers(0, 3)):]
    return json.dumps(document)


@st.composite
def json_cases(draw: st.DrawFn) -> Case:
    document = {"units": draw(st.sampled_from(["mm", "in"])),
                "curves": draw(st.lists(json_curve(), min_size=1, max_size=3))}
    perturb = draw(st.booleans())
    text = draw(perturbed_json(document)) if perturb else json.dumps(document)
    data = text.encode("utf-8", "surrogatepass")
    if perturb and draw(st.integers(0, 5)) == 0:
        data = b"\xef\xbb\xbf" + data
    return Case("in.json", data, valid=not perturb)


# ---- YAML machine profiles --------------------------------------------------------------------

PROFILE = {"period_s": 0.001, "max_feed_mm_s": 100.0, "chord_error_mm": 0.001,
           "max_acc_mm_s2": 2000.0, "max_jerk_mm_s3": 50000.0, "max_normal_acc_mm_s2": 2000.0,
           "max_normal_jerk_mm_s3": 50000.0, "max_curve_time_s": 3600.0, "decimals": 4,
           "feed_decimals": 3}
YAML_ODD_VALUES = ["0", "-1", "1e-300", "1e308", "1.0e9", "5E4", ".inf", ".nan", "~", "null",
                   "yes", "'0.001'", "[1, 2]", "{a: 1}", "0x10", "1_000", "!!binary aGk=",
                   "!!python/object:os.system x", "1" * 400, "3.5", "20", "-0.0", "1:30",
                   "2001-12-14", "*anchor", "&anchor 1"]


@st.composite
def profile_cases(draw: st.DrawFn) -> Case:
    profile = {key: draw(st.sampled_from([value, value * 2, value / 2]))
               for key, value in PROFILE.items()}
    profile["decimals"] = draw(st.integers(3, 6))
    profile["feed_decimals"] = draw(st.integers(1, 4))
    lines = [f"{key}: {value}" for key, value in profile.items()]
    perturb = draw(st.booleans())
    if perturb:
        for _ in range(draw(st.integers(1, 3))):
            kind = draw(st.integers(0, 5))
            at = draw(st.integers(0, len(lines) - 1))
            key = lines[at].split(":")[0]
            if kind == 0:
                lines[at] = f"{key}: {draw(st.sampled_from(YAML_ODD_VALUES))}"
            elif kind == 1:
                del lines[at]
            elif kind == 2:
                lines.append(lines[at])  # a duplicate key
            elif kind == 3:
                lines.append(draw(st.sampled_from(["unknown_key: 1", "max_feed: 100",
                                                   "- 1", "[", "a: &x [*x]", ":"])))
            elif kind == 4:  # an alias bomb, small enough to stay a test of the refusal
                lines = ["a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1]"] + [
                    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]"
                    for i in range(draw(st.integers(1, 6)))] + lines
            else:
                lines[at] = "  " + lines[at] if draw(st.booleans()) else "\t" + lines[at]
    return Case("in.ngc", EASY_GCODE.read_bytes(), "\n".join(lines).encode() + b"\n",
                valid=not perturb)


# ---- byte-level mutations of the samples -----------------------------------------------------

@st.composite
def sample_mutations(draw: st.DrawFn) -> Case:
    source = draw(st.sampled_from(SAMPLE_FILES))
    data = source.read_bytes()
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.integers(0, 7))
        at = draw(st.integers(0, max(len(data) - 1, 0)))
        if kind == 0:  # flip bits of a byte
            if data:
                data = data[:at] + bytes([data[at] ^ draw(st.integers(1, 255))]) + data[at + 1:]
        elif kind == 1:  # insert bytes
            data = data[:at] + draw(st.binary(min_size=1, max_size=4) |
                                    st.sampled_from(ODD_BYTES)) + data[at:]
        elif kind == 2:  # delete bytes
            data = data[:at] + data[at + draw(st.integers(1, 8)):]
        elif kind == 3:  # duplicate bytes
            data = data[:at] + data[at:at + draw(st.integers(1, 16))] + data[at:]
        elif kind in (4, 5):  # delete or duplicate a line
            lines = data.split(b"\n")
            index = draw(st.integers(0, len(lines) - 1))
            if kind == 4:
                del lines[index]
            else:
                lines.insert(index, lines[index])
            data = b"\n".join(lines)
        elif kind == 6:  # swap two lines
            lines = data.split(b"\n")
            i, j = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
            data = b"\n".join(lines)
        else:  # splice with another sample
            other = draw(st.sampled_from(SAMPLE_FILES)).read_bytes()
            data = data[:at] + other[draw(st.integers(0, max(len(other) - 1, 0))):]
    return Case("in" + source.suffix, data)


FAMILIES = {"gcode": gcode_cases(), "json": json_cases(), "profile": profile_cases(),
            "samples": sample_mutations()}
