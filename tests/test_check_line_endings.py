"""`nurbsfeed check` splits both programs into lines as a conversion reads them: a program whose
lines end in "\\r" alone (accepted by convert, docs/refusals.md "Accepted as written") is
checked line by line like its "\\n" twin. It once read such a program as one line (found by
tests/fuzz: 7 violations, pass-through lines and the curve missing)."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main

SAMPLES = Path(__file__).parent.parent / "samples"
# a Fanuc block with comment, blank and N-only lines inside it: the reader hands them over as
# one pass-through item of several lines, which check splits again
KEPT_INSIDE = (b"G21 G90 G0 X0 Y0 Z0\nF900\nG06.2 P3 K0 X0 Y0\n(c1)\nK0 X10 Y10\n\nK0 X20 Y0\n"
               b"; c2\nK1\nN10\nK1\n  (MSG, done)\nK1\nM30\n")


def convert_and_check(folder: Path, name: str, program: bytes) -> tuple[Path, Path, str]:
    source = folder / name
    source.write_bytes(program)
    target = folder / ("out-" + name)
    converted = CliRunner().invoke(main, ["convert", str(source), "-o", str(target)])
    assert converted.exit_code == 0, converted.output
    checked = CliRunner().invoke(main, ["check", str(source), str(target)])
    assert checked.exit_code == 0, checked.output
    return source, target, checked.stdout


@pytest.mark.parametrize("program", [(SAMPLES / "linuxcnc-nurbs-xy.ngc").read_bytes(),
                                     KEPT_INSIDE], ids=["linuxcnc-nurbs-xy", "kept-inside"])
def test_a_cr_only_program_checks_as_its_lf_twin(tmp_path: Path, program: bytes) -> None:
    _, _, lf_report = convert_and_check(tmp_path, "lf.ngc", program)
    _, target, cr_report = convert_and_check(tmp_path, "cr.ngc", program.replace(b"\n", b"\r"))
    assert b"\n" not in target.read_bytes()
    assert "result: OK" in cr_report
    assert cr_report == lf_report.replace("lf.ngc", "cr.ngc")


def test_a_changed_line_of_a_cr_only_output_is_found_at_its_line(tmp_path: Path) -> None:
    source, target, _ = convert_and_check(tmp_path, "cr.ngc",
                                          KEPT_INSIDE.replace(b"\n", b"\r"))
    lines = target.read_bytes().split(b"\r")
    changed = lines.index(b"; c2")
    lines[changed] = b"; c3"
    target.write_bytes(b"\r".join(lines))
    checked = CliRunner().invoke(main, ["check", str(source), str(target)])
    assert checked.exit_code == 1
    assert f"{target}:{changed + 1}" in checked.stdout
