"""compare, check and plot as a user meets them: key lines of the output and exact exit codes."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

import nurbsfeed
from nurbsfeed.cli import main
from tests.conftest import SAMPLES, default_paper_profile

BUTTERFLY = str(SAMPLES / "butterfly.json")


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


@pytest.fixture(scope="module")
def butterfly_nc(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "butterfly.nc"
    assert run("convert", BUTTERFLY, "-m", "paper-table1", "-o", str(out), "-q")[0] == 0
    return out


def test_compare_prints_table_2_with_the_paper_alongside() -> None:
    code, stdout, _ = run("compare", BUTTERFLY, "-m", "paper-table1", "--repeat", "2")
    assert code == 0
    lines = stdout.splitlines()
    assert lines[0] == f"{BUTTERFLY}: 1 curve(s), machine paper-table1"
    assert lines[1].split() == ["method", "max", "FF", "%", "mean", "FF", "%", "points",
                                "us/step", "paper", "max", "FF", "%", "paper", "us/step"]
    rows = {line.split()[0]: line.split() for line in lines[2:5]}
    assert list(rows) == ["taylor1", "rk4", "rk2c"]
    assert [rows[m][-2:] for m in rows] == [["6.84", "3.9"], ["0.36", "16.1"], ["0.0281", "11.5"]]
    max_ff = [float(rows[m][1]) for m in rows]
    assert max_ff[0] > max_ff[1] > max_ff[2]
    assert "median of 2 compiled kernel runs" in stdout
    assert "aggregated" not in stdout


def test_compare_json_and_multi_curve_aggregation() -> None:
    code, stdout, _ = run("compare", str(SAMPLES / "fanuc-multi-curve.nc"), "--repeat", "1",
                          "--json")
    assert code == 0
    data = json.loads(stdout)
    assert data["curves"] == 3 and data["machine"] == "default" and data["repeat"] == 1
    assert data["aggregate"].startswith("max: largest per-curve maximum; mean: over every period")
    assert [m["method"] for m in data["methods"]] == ["taylor1", "rk4", "rk2c"]
    assert {"max_ff_pct", "mean_ff_pct", "n_points", "us_per_step"} <= set(data["methods"][0])


def test_check_passes_a_correct_conversion(butterfly_nc: Path) -> None:
    code, stdout, _ = run("check", BUTTERFLY, str(butterfly_nc), "-m", "paper-table1")
    assert code == 0
    lines = stdout.splitlines()
    assert lines[0].startswith(f"check {butterfly_nc} against {BUTTERFLY} (machine "
                               "paper-table1): 1 curve(s), ")
    titles = [line[:31].strip() for line in lines[2:18]]
    assert titles == ["path deviation", "chord error", "curve covered per move",
                      "least time along the curve", "segment time off whole periods",
                      "multi-period move length", "feed", "tangential acceleration",
                      "tangential jerk", "normal acceleration v^2 kappa",
                      "normal jerk v^3 kappa^2", "acceleration from positions",
                      "tangential acc. from positions", "normal acc. from positions",
                      "corner: acc. from positions", "speed where velocity flips"]
    assert all(line.split()[-2] == "0" or line.split()[-1] == "0"
               for line in lines[2:18])  # nothing broken (empty rows end in "0 0")
    assert "source lines, curves, number format, curve ends, G90/G91 and F restore: ok" in lines
    assert "divided differences of the projected arc length over 2 ms, 9 ms" in stdout
    assert "second divided differences of the written points over 2 ms" in stdout
    assert lines[-1] == "result: OK: 0 violation(s)"


def test_a_curve_of_a_few_periods_converts_and_checks(tmp_path: Path) -> None:
    """A 0.6 um curve, 8 periods: its last points round onto the end and are held before it
    (the moves cover every announced period), and the checker, with too few moves for its
    jerk estimate, reports that row as empty instead of failing."""
    source = tmp_path / "tiny.nc"
    source.write_text("G21 G90\nG0 X0. Y0. Z0.\nG06.2 P4 K0. X0. Y0. Z0. F6000.\n"
                      "K0. X0.0002 Y0.0001\nK0. X0.0004 Y0.0001\nK0. X0.0006 Y0.\n"
                      "K1.\nK1.\nK1.\nK1.\nM30\n")
    out = tmp_path / "tiny.out.nc"
    profile = tmp_path / "paper.yaml"  # the law's own jerk is a row of the paper model only
    profile.write_text(yaml.safe_dump(default_paper_profile()))
    assert run("convert", str(source), "-m", str(profile), "-o", str(out), "-q")[0] == 0
    assert len(re.findall(r"^G1 ", out.read_text(), re.M)) <= 10
    code, stdout, stderr = run("check", str(source), str(out), "-m", str(profile))
    assert code == 0 and stderr == ""
    assert "announced periods" not in stdout
    assert re.search(r"^tangential jerk +mm/s\^3 +- +- +- +- +0 +0$", stdout, re.M)
    assert stdout.rstrip().endswith("result: OK: 0 violation(s)")


def test_check_exits_1_and_names_the_violation(butterfly_nc: Path, tmp_path: Path) -> None:
    lines = butterfly_nc.read_text().splitlines(keepends=True)
    lines[2] = "G0 X0. Y0. Z0.\n"
    bad = tmp_path / "bad.nc"
    bad.write_text("".join(lines))
    code, stdout, _ = run("check", BUTTERFLY, str(bad), "-m", "paper-table1")
    assert code == 1
    assert (f"{bad}:3: pass-through: line changed: expected 'G0 X54.493 Y52.139 Z0.', found "
            "'G0 X0. Y0. Z0.'") in stdout.splitlines()
    assert stdout.splitlines()[-1] == "result: FAILED: 1 violation(s)"
    code, stdout, _ = run("check", BUTTERFLY, str(bad), "-m", "paper-table1", "--json")
    assert code == 1
    data = json.loads(stdout)
    assert data["ok"] is False and data["violation_count"] == 1
    assert data["violations"][0]["check"] == "pass-through"
    assert {c["name"] for c in data["checks"]} >= {"path-deviation", "tangential-jerk"}


def test_check_exits_2_on_unreadable_inputs(butterfly_nc: Path, tmp_path: Path) -> None:
    code, _, stderr = run("check", BUTTERFLY, str(tmp_path / "none.nc"))
    assert code == 2 and "does not exist" in stderr
    broken = tmp_path / "broken.json"
    broken.write_text('{"curves": [')
    code, stdout, stderr = run("check", str(broken), str(butterfly_nc))
    assert code == 2 and stdout == ""
    assert stderr.strip() == f"{broken}:1:13: not valid JSON: Expecting value"


def test_check_without_m_uses_the_profile_recorded_in_the_output(butterfly_nc: Path) -> None:
    """The output was made under paper-table1 (not the default): `check` without -m reads that
    from the output's profile record and passes, as the README's Usage runs it."""
    code, stdout, stderr = run("check", BUTTERFLY, str(butterfly_nc))
    assert code == 0 and stderr == ""
    assert stdout.startswith(f"check {butterfly_nc} against {BUTTERFLY} (machine "
                             "paper-table1): 1 curve(s), ")
    assert stdout.splitlines()[-1] == "result: OK: 0 violation(s)"


def test_check_under_another_profile_exits_2_and_names_what_differs(butterfly_nc: Path) -> None:
    """-m default (or an override) against an output made under paper-table1: no check runs
    (its violations would be the profiles' difference, not the program's), exit 2 at the
    record, every key that differs named with both values."""
    record_line = butterfly_nc.read_text().splitlines().index(
        next(line for line in butterfly_nc.read_text().splitlines()
             if line.startswith("(nurbsfeed profile: "))) + 1
    code, stdout, stderr = run("check", BUTTERFLY, str(butterfly_nc), "-m", "default")
    assert code == 2 and stdout == ""
    assert stderr.startswith(f"{butterfly_nc}:{record_line}:1: converted under the profile "
                             "paper-table1 (recorded here), but checked under default, which "
                             "differs: jerk_model paper -> path; planner scurve -> optimal; "
                             "max_feed_mm_s 100.0 -> 200.0; ")
    assert "max_vel_x_mm_s unset -> 250.0" in stderr and "\n" not in stderr.rstrip("\n")
    code, stdout, stderr = run("check", BUTTERFLY, str(butterfly_nc), "--max-feed-mm-s", "90")
    assert code == 2 and stdout == ""
    assert stderr.rstrip("\n").endswith("which differs: max_feed_mm_s 100.0 -> 90.0 (leave out "
                                         "-m and the overrides to check under the recorded "
                                         "profile)")
    code, _, _ = run("check", BUTTERFLY, str(butterfly_nc), "-m", "paper-table1",
                     "--max-feed-mm-s", "100")  # the same values: agreed
    assert code == 0


def test_check_refuses_a_profile_record_that_does_not_load(butterfly_nc: Path,
                                                           tmp_path: Path) -> None:
    """An edited record goes through the profile's own checks, located at its line."""
    lines = butterfly_nc.read_text().splitlines(keepends=True)
    at = next(i for i, line in enumerate(lines) if "max_feed_mm_s" in line)
    bad = tmp_path / "bad.nc"
    for wrong, message in ((lines[at].replace("max_feed_mm_s 100.0", "max_feed_mm_s -5.0"),
                            "'max_feed_mm_s' must be positive and finite, not -5.0"),
                           (lines[at].replace("max_feed_mm_s 100.0", "max_feed_mm_s"),
                            "cannot read 'max_feed_mm_s' in the profile record (write 'key "
                            "value')"),
                           (lines[at].replace("max_feed_mm_s", "max_speed_mm_s"),
                            "unknown key 'max_speed_mm_s'")):
        bad.write_text("".join(lines[:at] + [wrong] + lines[at + 1:]))
        code, stdout, stderr = run("check", BUTTERFLY, str(bad))
        assert code == 2 and stdout == ""
        assert stderr.startswith(f"{bad}:{at + 1}:1: ") and message in stderr


def test_check_of_an_output_without_a_record_uses_m(butterfly_nc: Path, tmp_path: Path) -> None:
    """A program converted before the record existed: checked under -m (the default profile
    without one), as before."""
    old = tmp_path / "old.nc"
    old.write_text("".join(line for line in butterfly_nc.read_text().splitlines(True)
                           if not line.startswith("(nurbsfeed profile: ")))
    assert run("check", BUTTERFLY, str(old), "-m", "paper-table1")[0] == 0
    code, stdout, _ = run("check", BUTTERFLY, str(old))
    assert code == 1 and "(machine default)" in stdout.splitlines()[0]


def test_plot_writes_a_png(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")  # the optional `plot` extra
    out = tmp_path / "quarter.png"
    code, stdout, stderr = run("plot", str(SAMPLES / "quarter-circle.json"), "-o", str(out),
                               "--method", "rk4")
    assert code == 0 and stdout == "" and stderr == ""
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 50_000


def test_plot_of_a_curve_that_is_not_there_exits_2(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    code, _, stderr = run("plot", BUTTERFLY, "-o", str(tmp_path / "x.png"), "--curve", "1")
    assert code == 2
    assert stderr.strip() == (f"{BUTTERFLY}: there is no curve 1: the input has 1 NURBS curve(s), "
                              "numbered from 0")
    assert not (tmp_path / "x.png").exists()


def test_plan_reference_without_scipy_says_how_to_get_it(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in [m for m in sys.modules if m.split(".")[0] == "scipy"] + ["scipy"]:
        monkeypatch.setitem(sys.modules, name, None)  # as if not installed: imports fail
    monkeypatch.delitem(sys.modules, "nurbsfeed.analysis.bound.solve", raising=False)
    monkeypatch.delattr("nurbsfeed.analysis.bound.solve", raising=False)
    code, stdout, stderr = run("plan", BUTTERFLY, "--reference")
    assert code == 2 and stdout == ""
    assert stderr == ("nurbsfeed plan --reference needs scipy: "
                      "pip install 'nurbsfeed[reference]'\n")


def test_plot_without_matplotlib_says_how_to_get_it(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    for name in [m for m in sys.modules if m.split(".")[0] == "matplotlib"] + ["matplotlib"]:
        monkeypatch.setitem(sys.modules, name, None)  # as if not installed: imports fail
    monkeypatch.delitem(sys.modules, "nurbsfeed.plotting", raising=False)
    monkeypatch.delattr(nurbsfeed, "plotting", raising=False)
    code, stdout, stderr = run("plot", BUTTERFLY, "-o", str(tmp_path / "x.png"))
    assert code == 2 and stdout == ""
    assert stderr == "nurbsfeed plot needs matplotlib: pip install 'nurbsfeed[plot]'\n"
