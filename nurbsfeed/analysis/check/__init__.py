"""`nurbsfeed check`: a converted program verified against its source, without running the
planner. One module per job:

- `output_program`: the source as tokens and curves, the output as tokens and move sections;
- `structure`: pass-through lines and curve sections diffed against the source;
- `projection`: written points mapped back to their curve;
- `estimates`: derivatives by divided differences and their rounding-noise bounds;
- `curve_checks`: one curve's geometry, coverage, timing and kinematics (its opening comment
  defines every check and tolerance);
- `report`: check names and messages, the report and its rendering.
"""

from __future__ import annotations

from pathlib import Path

from nurbsfeed.analysis.check.curve_checks import check_section
from nurbsfeed.analysis.check.output_program import parse_output, source_tokens
from nurbsfeed.analysis.check.projection import project_points
from nurbsfeed.analysis.check.report import (
    CHECKS,
    STRUCTURE_CHECKS,
    CheckReport,
    Findings,
    Violation,
    first_per_check,
    reduce_check,
    render_check,
)
from nurbsfeed.analysis.check.structure import compare_structure
from nurbsfeed.files import InputFile
from nurbsfeed.machine import Machine

__all__ = ["CHECKS", "CheckReport", "Violation", "check_files", "project_points", "render_check"]


def check_files(source: Path, output: Path, machine: Machine,
                dialect: str = "auto") -> CheckReport:
    """Check the converted program `output` against `source`."""
    # both programs split into lines as a conversion reads them (a CR-only file too)
    src_tokens, blocks, following, joint_lines = source_tokens(source, machine, dialect)
    out_lines = list(InputFile(output).lines())
    findings = Findings(str(output))
    out_tokens, token_lines, sections = parse_output(out_lines, blocks, following, findings,
                                                    joint_lines)
    compare_structure(src_tokens, out_tokens, token_lines, blocks, len(out_lines), findings)
    for section in sections:
        if section.index < len(blocks):
            check_section(section, blocks[section.index], machine, findings)
    structural = findings.violations
    shown = first_per_check(structural)
    measures = []
    for name in CHECKS:
        measure, listed = reduce_check(name, findings.arrays.get(name, []), str(output))
        measures.append(measure)
        shown += listed
    shown.sort(key=lambda v: int(v.where.rsplit(":", 1)[1]))
    structure = {name: sum(1 for v in structural if v.check == name)
                 for name in STRUCTURE_CHECKS}
    return CheckReport(str(source), str(output), len(blocks),
                       sum(len(s.moves) for s in sections),
                       sum(1 for t in src_tokens if t[0] == "line"), tuple(findings.estimation),
                       tuple(measures), structure, tuple(shown),
                       len(structural) + sum(m.n_violations for m in measures),
                       tuple(findings.notes), machine.limits.jerk_model)
