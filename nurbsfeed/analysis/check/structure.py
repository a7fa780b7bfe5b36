"""The output's pass-through lines and curve sections diffed against the source, in order."""

from __future__ import annotations

import difflib

from nurbsfeed.analysis.check.output_program import Token, body
from nurbsfeed.analysis.check.report import Findings
from nurbsfeed.program import CurveBlock


def compare_structure(src: list[Token], out: list[Token], out_lines: list[int],
                      blocks: list[CurveBlock], n_lines: int, findings: Findings) -> None:
    """Every source line present, byte-identical and in order; every curve once."""
    if src == out:
        return
    matcher = difflib.SequenceMatcher(None, src, out, autojunk=False)

    def line_at(j: int) -> int:
        return out_lines[j] if j < len(out_lines) else n_lines + 1

    for op, i1, i2, j1, j2 in matcher.get_opcodes():
        if op == "equal":
            continue
        gone = src[i1:i2]
        extra = out[j1:j2]
        if op == "replace":
            gone_lines = [t for t in gone if t[0] == "line"]
            extra_lines = [t for t in extra if t[0] == "line"]
            for (_, want), j in zip(gone_lines, [j for j in range(j1, j2)
                                                 if out[j][0] == "line"]):
                findings.add("pass-through", line_at(j), f"line changed: expected "
                             f"{body(want)!r}, found {body(out[j][1])!r}")
            gone = [t for t in gone if t[0] == "curve"] + gone_lines[len(extra_lines):]
            extra = [t for t in extra if t[0] == "curve"] + extra_lines[len(gone_lines):]
        for kind, value in gone:
            if kind == "curve":
                findings.add("curve-missing", line_at(j1), f"curve {value} "
                             f"({blocks[value].curve.name}, {blocks[value].location}) is missing "
                             f"from the output")
            else:
                findings.add("pass-through", line_at(j1), f"source line missing here: "
                             f"{body(value)!r}")
        for kind, value in extra:
            j = j1 + out[j1:j2].index((kind, value))
            if kind == "curve":
                findings.add("curve-extra", line_at(j), f"section for curve {value} is not "
                             f"expected here (the source has {len(blocks)} curves)")
            else:
                findings.add("pass-through", line_at(j), f"line not in the source: "
                             f"{body(value)!r}")
