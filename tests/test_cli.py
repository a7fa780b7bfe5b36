"""The command line as a user meets it: outputs, golden files, exact messages and exit codes."""

from __future__ import annotations

import csv
import difflib
import io
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.jit import JIT_ENABLED
from nurbsfeed.machine import load_machine
from nurbsfeed.readers.json_curves import read_json_curves
from tests.conftest import ROOT, SAMPLES
from tests.gcode_parse import moves
from tests.test_bound import scurve_rest_to_rest_s

GOLDEN = ROOT / "tests" / "golden"
# the default profile's coordinate decimals (chosen from its limits: tests/test_profile.py)
DECIMALS = load_machine("default").decimals


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args), catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def test_convert_json_writes_a_complete_program_with_trace(tmp_path: Path) -> None:
    out, trace = tmp_path / "q.nc", tmp_path / "q.csv"
    code, stdout, stderr = run("convert", str(SAMPLES / "quarter-circle.json"), "-o", str(out),
                               "--machine", "paper-table1", "--trace", str(trace))
    assert code == 0 and stdout == ""
    assert ": 1 curve, " in stderr and str(out) in stderr
    text = out.read_text()
    lines = text.splitlines()
    assert lines[1] == "G21 G90" and lines[2] == "G0 X10. Y0. Z0." and lines[-1] == "M2"
    record = [line for line in lines if line.startswith("(nurbsfeed profile: ")]
    assert lines[3:3 + len(record)] == record and record[0].startswith(
        "(nurbsfeed profile: name paper-table1, nurbsfeed ")
    assert lines[3 + len(record)].startswith("(nurbsfeed: curve 0 quarter-circle-r10, ")
    rows = list(csv.reader(io.StringIO(trace.read_text())))
    assert rows[0] == ["curve", "k", "t", "u", "s", "v", "a", "j", "x", "y", "z"]
    table = np.array(rows[1:], dtype=float)
    assert np.array_equal(table[:, 1], np.arange(len(table)))
    assert np.allclose(table[:, 2], table[:, 1] * 0.001, rtol=0, atol=1e-15)
    # trace points on the circle of radius 10, G-code points = trace points rounded
    assert np.allclose(np.hypot(table[:, 8], table[:, 9]), 10.0, atol=1e-9)
    written, feeds, _ = moves(text, [10.0, 0.0, 0.0])
    rounded = np.round(table[1:, 8:11], 4)
    keep = np.any(np.diff(np.round(table[:, 8:11], 4), axis=0) != 0, axis=1)
    assert np.allclose(written, rounded[keep], atol=1e-9)
    # the programmed F3000 caps the planned speed at 50 mm/s; F words come from the written
    # (rounded) coordinates, each end within sqrt(3)/2 * 1e-4 mm of the true point
    assert table[:, 5].max() <= 50.0 * (1 + 1e-9)
    assert feeds.max() <= 60 * (50.0 * 0.001 + np.sqrt(3) * 1e-4) / 0.001


def test_golden_output(request: pytest.FixtureRequest, tmp_path: Path) -> None:
    """The converted sample, byte for byte. Regenerate with `pytest --update-golden` after a
    deliberate change, and read the diff; the invariants below hold for the golden file itself."""
    golden = GOLDEN / "quarter-circle.nc"
    out = tmp_path / "q.nc"
    assert run("convert", str(SAMPLES / "quarter-circle.json"), "-m", "paper-table1", "-o",
               str(out), "-q")[0] == 0
    produced = out.read_text()
    if request.config.getoption("--update-golden"):
        golden.write_text(produced)
    expected = golden.read_text()
    diff = "".join(difflib.unified_diff(expected.splitlines(True), produced.splitlines(True),
                                        "golden", "produced", n=1))
    assert produced == expected, diff[:4000]
    written, feeds, _ = moves(expected, [10.0, 0.0, 0.0])
    assert np.allclose(np.hypot(written[:, 0], written[:, 1]), 10.0, atol=1e-4)
    assert np.array_equal(written[-1], [0.0, 10.0, 0.0])
    step = np.linalg.norm(np.diff(np.vstack([[10.0, 0, 0], written]), axis=0), axis=1)
    periods = step / (feeds / 60.0) / 0.001
    assert np.allclose(periods, np.round(periods), rtol=5e-3) and np.all(np.round(periods) >= 1)


def test_convert_to_stdout_and_exactly_the_same_bytes_as_to_a_file(tmp_path: Path) -> None:
    code, stdout, _ = run("convert", str(SAMPLES / "quarter-circle.json"), "-m", "paper-table1")
    out = tmp_path / "q.nc"
    run("convert", str(SAMPLES / "quarter-circle.json"), "-m", "paper-table1", "-o", str(out))
    assert code == 0 and stdout == out.read_text()


def test_options_override_single_profile_values(tmp_path: Path) -> None:
    out = tmp_path / "q.nc"
    code, _, stderr = run("convert", str(SAMPLES / "quarter-circle.json"), "-m", "paper-table1",
                          "--max-feed-mm-s", "20", "--decimals", "3", "-o", str(out))
    assert code == 0
    written, feeds, raw = moves(out.read_text(), [10.0, 0.0, 0.0])
    assert feeds.max() <= 60 * (20 * 0.001 + np.sqrt(3) * 1e-3) / 0.001  # 3 decimals
    assert all(len(w.split(".")[-1]) <= 3 for line in raw for w in line.split() if w[0] in "XY")


def test_plan_reports_key_points_segments_and_the_bound() -> None:
    code, stdout, _ = run("plan", str(SAMPLES / "butterfly.json"), "-m", "paper-table1")
    assert code == 0
    assert "kappa0 0.1 1/mm; 25 curvature peaks >= kappa0" in stdout
    assert "time-optimal bound 5.47" in stdout
    cycle = float(stdout.split("cycle time ")[1].split(" s")[0])
    assert 5.48 < cycle < 7.0


@pytest.mark.parametrize(("command", "options"), [
    ("convert", {"--output", "--machine", "--method", "--dialect", "--trace", "--jobs", "--quiet"}),
    ("plan", {"--reference", "--machine", "--dialect"}),
    ("compare", {"--machine", "--dialect", "--repeat", "--json"}),
    ("check", {"--machine", "--dialect", "--json"}),
    ("plot", {"--output", "--curve", "--machine", "--method", "--dialect"}),
])
def test_each_commands_help_lists_its_own_options_and_an_example(command: str,
                                                                  options: set[str]) -> None:
    """Not a line per profile key: the overrides are named once, in a paragraph; each command
    shows examples of itself; check, which plans nothing, has no --planner."""
    code, stdout, _ = run(command, "--help")
    assert code == 0
    section = stdout.split("Options:\n")[1].split("\n\n")[0]
    listed = set(re.findall(r"^  (?:-\w, )?(--[a-z-]+)", section, re.M))
    assert listed == options | {"--help"}
    examples = stdout.split("Examples:\n")[1].split("\n\n")[0].splitlines()
    assert examples and all(line.startswith(f"    nurbsfeed {command} ") for line in examples)
    overrides = stdout.split("Profile overrides")[1]
    assert "--max-feed-mm-s" in overrides and "--jerk-model paper|path" in overrides
    assert ("--planner" in overrides) == (command != "check")
    assert len(stdout.splitlines()) < 40


def test_check_refuses_planner_which_it_has_no_use_for() -> None:
    code, _, stderr = run("check", str(SAMPLES / "butterfly.json"), "x.nc", "--planner",
                          "optimal")
    assert code == 2 and "No such option '--planner'" in stderr


def test_plans_time_optimal_bound_respects_the_programmed_feed(tmp_path: Path) -> None:
    """The bound is a lower bound on the cycle under every cap the plan obeys, the programmed F
    among them: a slow F makes it at least length / F (and the plan, which F caps too, stays
    above it, by the time it takes to start and stop)."""
    source = tmp_path / "slow.nc"
    source.write_text((SAMPLES / "fanuc-quadratic.nc").read_text().replace("F3000.", "F290."))
    code, stdout, _ = run("plan", str(source))
    assert code == 0
    length_mm = float(re.search(r"length ([\d.]+) mm", stdout)[1])
    bound = float(re.search(r"time-optimal bound ([\d.]+) s", stdout)[1])
    cycle = float(re.search(r"cycle time ([\d.]+) s", stdout)[1])
    above = float(re.search(r"planned is \+([\d.]+)%", stdout)[1])
    assert length_mm / (290.0 / 60.0) <= bound <= cycle
    assert above < 5.0  # not +3019 %: the machine's 200 mm/s is not what caps this curve


def test_plan_reference_is_the_jerk_limited_optimum_on_a_quarter_circle() -> None:
    """The quarter circle (r 10 mm, 15.708 mm at F50, default profile) is slow enough for the
    curvature never to bind (v^2 kappa = 250 of 2000 mm/s^2, v^3 kappa^2 = 1,250 of 50,000
    mm/s^3): its jerk-limited optimum is a straight line's, in closed form."""
    code, stdout, _ = run("plan", str(SAMPLES / "quarter-circle.json"), "--reference")
    assert code == 0
    line = next(x for x in stdout.splitlines() if "jerk-limited reference" in x)
    ref = float(line.split("reference ")[1].split(" s")[0])
    cycle = float(stdout.split("cycle time ")[1].split(" s")[0])
    exact = scurve_rest_to_rest_s(0.5 * math.pi * 10.0, 50.0, 2000.0, 50000.0)
    assert exact * (1 - 1e-3) <= ref <= exact * 1.01
    # the ratio of the unrounded times: within the 3-decimal rounding of the two shown
    percent = float(line.split("planned is ")[1].rstrip("%"))
    slack = 100 * 0.0005 * (1 / ref + cycle / ref**2) + 0.05
    assert abs(percent - 100 * (cycle / ref - 1)) <= slack


def test_batch_keeps_names_reports_each_file_and_fails_on_one_bad_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"curves": [}')
    out = tmp_path / "out"
    code, _, stderr = run("convert", str(SAMPLES / "quarter-circle.json"),
                          str(SAMPLES / "circle.json"), str(bad), "-o", str(out))
    assert code == 2
    assert sorted(p.name for p in out.iterdir()) == ["circle.nc", "quarter-circle.nc"]
    assert f"FAILED: {bad}:1:13: not valid JSON: Expecting value" in stderr
    assert "2 of 3 files converted" in stderr


def test_parallel_jobs_give_the_same_files(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    inputs = [str(SAMPLES / "quarter-circle.json"), str(SAMPLES / "circle.json")]
    assert run("convert", *inputs, "-o", str(a), "-q")[0] == 0
    assert run("convert", *inputs, "-o", str(b), "-q", "--jobs", "2")[0] == 0
    for name in ("circle.nc", "quarter-circle.nc"):
        assert (a / name).read_bytes() == (b / name).read_bytes()


BAD_JSON = [
    ('{"curves": [', "1:13: not valid JSON: Expecting value"),
    ('[1, 2]', "1:1: expected a JSON object with 'curves' (or a single curve object)"),
    ('{"units": "cm", "curves": []}', "1:2: 'units' must be \"mm\" or \"in\", not 'cm'"),
    ('{"curves": []}', "1:2: 'curves' must be a non-empty list of curve objects"),
    ('{"degree": 2, "knots": [0,0,0,1,1,1], "control_points": [[0,0],[1,1],[2,0]],\n'
     ' "weights": [1, 0, 1]}',
     "2:2: curves[0]: weight 1 must be positive and finite, not 0.0"),
    ('{"degree": 2, "knots": [0,0,0,1,1], "control_points": [[0,0],[1,1],[2,0]]}',
     "1:15: curves[0]: 3 control points of degree 2 need 6 knots (control points + order), "
     "got 5"),
    ('{"degree": 2, "control_points": [[0,0],[1,1],[2,0]]}', "1:2: curves[0]: missing 'knots'"),
    ('{"degree": 1, "knots": [0,0,1,1], "control_points": [[0,0],[1,1]], "feed": -5}',
     "1:68: curves[0]: 'feed' must be a positive number (length/min), not -5"),
    ('{"degree": 1, "knots": [0,0,1,1], "control_points": [[0,0],[1,1]], "speed": 5}',
     "1:68: curves[0]: unknown key 'speed' (known: control_points, degree, feed, knots, name, "
     "weights)"),
    ('{"degree": 1, "knots": [0,0,1,1], "control_points": [[0,0],[1,NaN]]}',
     "1:63: not valid JSON: NaN is not a number JSON allows"),
    # just outside the input envelope (docs/refusals.md "Input envelope"), refused before any work
    ('{"degree": 1000000000000, "knots": [0, 1], "control_points": [[0, 0]]}',
     "1:2: curves[0]: degree 1000000000000 is above 9, the highest nurbsfeed evaluates "
     "accurately"),
    ('{"curves": [{"degree": 1, "knots": [0,0,1,1], "control_points": [[0,0],[1,1]]},\n'
     ' {"degree": 10, "knots": [], "control_points": []}]}',
     "2:3: curves[1]: degree 10 is above 9, the highest nurbsfeed evaluates accurately"),
    ('{"degree": 1, "knots": [0,0,1,1],\n "control_points": [[0,0],[1000000.001,1]]}',
     "2:2: curves[0]: control point 1 [1000000.001, 1.0] has a coordinate beyond +-1000000, "
     "the range nurbsfeed converts"),
    ('{"degree": 2, "knots": [0,0,0,1,1,1], "control_points": [[0,0],[1,1],[2,0]],\n'
     ' "weights": [1, 1000.5, 1]}',
     "2:2: curves[0]: weight 1 (1000.5) is more than 1000 times weight 0 (1); nurbsfeed plans "
     "curves up to that ratio"),
    ('{"degree": 1, "knots": [5,5,6,6.000000000001,7,7],\n'
     ' "control_points": [[0,0],[1,1],[2,0],[3,1]]}',
     "1:15: curves[0]: knot span 6.0 .. 6.000000000001 is 5.0e-13 of the knot range; at least "
     "1e-12"),
]


@pytest.mark.parametrize(("content", "message"), BAD_JSON)
def test_bad_json_gives_file_line_col_exit_2_and_no_output(tmp_path: Path, content: str,
                                                           message: str) -> None:
    src = tmp_path / "in.json"
    src.write_text(content)
    out = tmp_path / "out.nc"
    code, stdout, stderr = run("convert", str(src), "-o", str(out))
    assert code == 2
    assert stderr == f"{src}:{message}\n"
    assert not out.exists() and os.listdir(tmp_path) == ["in.json"]


BAD_PROFILES = [
    ("period_s: 0.001\n", "{p}: missing key 'max_feed_mm_s'"),
    ("- 1\n- 2\n", "{p}: a machine profile is a mapping of keys to values, not list"),
    ("period_s: [1\n", "{p}:2:1: not valid YAML (expected ',' or ']', but got '<stream end>')"),
    ("{base}\nspeed: 3\n", "{p}:10:1: unknown key 'speed' (known keys: chord_error_mm, decimals, "
     "feed_decimals, jerk_model, max_acc_mm_s2, max_acc_x_mm_s2, max_acc_y_mm_s2, "
     "max_acc_z_mm_s2, max_curve_time_s, max_feed_mm_s, max_jerk_mm_s3, max_jerk_x_mm_s3, "
     "max_jerk_y_mm_s3, max_jerk_z_mm_s3, max_normal_acc_mm_s2, max_normal_jerk_mm_s3, "
     "max_vel_x_mm_s, max_vel_y_mm_s, max_vel_z_mm_s, min_block_time_s, move_periods, "
     "period_s, planner, rest_move_s)"),
    ("{base}\nchord_error_mm: .nan\n", "{p}:10:1: 'chord_error_mm' must be positive and finite, "
     "not nan"),
    ("{base}\nmax_acc_mm_s2: fast\n", "{p}:10:1: 'max_acc_mm_s2' must be a number, not 'fast'"),
    ("{base}\nmax_curve_time_s: 0\n", "{p}:10:1: 'max_curve_time_s' must be positive and "
     "finite, not 0"),
    ("{base}\nmax_curve_time_s: .inf\n", "{p}:10:1: 'max_curve_time_s' must be positive and "
     "finite, not inf"),
    ("{base}\ndecimals: 2.5\n", "{p}:10:1: 'decimals' must be a whole number from 0 to 8, "
     "not 2.5"),
]


@pytest.mark.parametrize(("content", "message"), BAD_PROFILES)
def test_bad_machine_profile_names_file_key_and_value(tmp_path: Path, content: str,
                                                      message: str) -> None:
    base = "\n".join(line for line in (ROOT / "configs" / "paper-table1.yaml").read_text()
                     .splitlines() if line and not line.startswith("#"))
    base_lines = base.splitlines()
    profile = tmp_path / "m.yaml"
    if "{base}" in content:
        key = content.split("\n")[1].split(":")[0]
        base = "\n".join(line for line in base_lines if not line.startswith(key + ":"))
    profile.write_text(content.replace("{base}", base))
    out = tmp_path / "out.nc"
    code, _, stderr = run("convert", str(SAMPLES / "quarter-circle.json"), "-m", str(profile),
                          "-o", str(out))
    assert code == 2
    line_no = len(base.splitlines()) + 1
    assert stderr == message.format(p=profile).replace(":10:", f":{line_no}:") + "\n"
    assert not out.exists()


@pytest.mark.parametrize(("args", "message"), [
    (["--machine", "nosuch"], "unknown machine 'nosuch': give a YAML file or one of default, "
                              "linuxcnc, paper-table1"),
    (["--period-s", "0"], "option --period-s: 'period_s' must be positive and finite, not 0.0"),
    (["--decimals", "12"], "option --decimals: 'decimals' must be a whole number from 0 to 8, "
                           "not 12"),
    (["--max-curve-time-s", "-1"], "option --max-curve-time-s: 'max_curve_time_s' must be "
                                   "positive and finite, not -1.0"),
])
def test_bad_options_exit_2_with_a_message(args, message) -> None:
    code, stdout, stderr = run("convert", str(SAMPLES / "quarter-circle.json"), *args)
    assert (code, stdout, stderr) == (2, "", message + "\n")


def test_missing_input_and_unwritable_output(tmp_path: Path) -> None:
    code, _, stderr = run("convert", str(tmp_path / "nope.nc"))
    assert (code, stderr) == (2, f"{tmp_path / 'nope.nc'}: cannot read input (No such file or "
                                 "directory)\n")
    target = tmp_path / "missing-dir" / "x.nc"
    code, _, stderr = run("convert", str(SAMPLES / "quarter-circle.json"), "-o", str(target))
    assert (code, stderr) == (2, f"{target}: cannot write output: directory {target.parent} "
                                 "does not exist\n")


def test_usage_errors_exit_2() -> None:
    code, _, stderr = run("convert", str(SAMPLES / "quarter-circle.json"),
                          str(SAMPLES / "circle.json"))
    assert code == 2 and "several inputs need -o DIR" in stderr
    code, _, stderr = run("convert", str(SAMPLES / "circle.json"), "--method", "rk9")
    assert code == 2 and "'rk9' is not one of 'taylor1', 'rk4', 'rk2c'" in stderr


def test_zero_length_curve_writes_no_move_and_says_so(tmp_path: Path) -> None:
    src = tmp_path / "dot.json"
    src.write_text('{"degree": 1, "knots": [0,0,1,1], "control_points": [[3,4],[3,4]]}')
    code, stdout, _ = run("convert", str(src))
    assert code == 0
    assert "(nurbsfeed: zero-length curve, no move written)" in stdout
    assert "G1" not in stdout


@pytest.mark.parametrize("profile", ["paper-table1", "default"])  # paper model, path model
def test_jit_and_plain_python_kernels_write_identical_programs(tmp_path: Path,
                                                               profile: str) -> None:
    """One code path: the numba-compiled kernels and the same functions run as plain Python
    produce the same output to the last written digit, and the same trace: positions, arc,
    parameter and speed to 1e-12; the law's acceleration and jerk, which a period's piece
    takes from its ends' positions over T^2 and T^3 (1e6, 1e9 at 1 ms), to 1e-9 of their
    largest (compiled code rounds a multiply-add once, plain Python twice: the path planner's
    linear programs carry that last bit to the 1e-15 of a position)."""
    outputs = []
    for flag in ("0", "1"):
        out, trace = tmp_path / f"q{flag}.nc", tmp_path / f"q{flag}.csv"
        args = ["convert", str(SAMPLES / "quarter-circle.json"), "-m", profile, "-o",
                str(out), "--trace", str(trace), "-q"]
        if flag == "0" and JIT_ENABLED:  # this process runs the compiled kernels already
            assert run(*args)[0] == 0
        else:  # NURBSFEED_NO_JIT is read at import: a process of its own
            env = dict(os.environ, NURBSFEED_NO_JIT=flag)
            subprocess.run([sys.executable, "-m", "nurbsfeed.cli", *args], env=env, check=True)
        outputs.append((out.read_bytes(), np.loadtxt(trace, delimiter=",", skiprows=1)))
    assert outputs[0][0] == outputs[1][0]
    (jit_rows, plain_rows) = outputs[0][1], outputs[1][1]
    exact = [0, 1, 2, 3, 4, 5, 8, 9, 10]  # curve, k, t, u, s, v, x, y, z
    assert np.allclose(jit_rows[:, exact], plain_rows[:, exact], rtol=1e-12, atol=1e-12)
    for column in (6, 7):  # a, j
        scale = float(np.abs(jit_rows[:, column]).max())
        assert np.max(np.abs(jit_rows[:, column] - plain_rows[:, column])) <= 1e-9 * scale


@pytest.mark.skipif(not JIT_ENABLED, reason="numba is not in use")
def test_a_run_from_numbas_cache_writes_what_the_first_run_wrote(tmp_path: Path) -> None:
    """The kernels are cached on disk by numba (`cache=True`): a second conversion, in a new
    process, takes every kernel it runs from the cache (no compile) and writes the very bytes
    the first run wrote (which compiled them, on a fresh clone, or loaded them too). The first
    run is this process's own: its kernels, compiled or loaded, are the cache's as well."""
    probe = ("import sys\n"
             "from nurbsfeed.cli import main\n"
             "try:\n"
             "    main(['convert', %r, '-o', %r, '-q'])\n"
             "except SystemExit as exc:\n"
             "    assert not exc.code, exc.code\n"
             "ran = {f'{name}.{attr}': kernel for name, module in list(sys.modules.items())\n"
             "       if name.startswith('nurbsfeed') for attr, kernel in vars(module).items()\n"
             "       if hasattr(kernel, 'stats') and getattr(kernel, 'signatures', None)}\n"
             "print(len(ran))\n"
             "print(sorted(name for name, kernel in ran.items() if kernel.stats.cache_misses\n"
             "             or not kernel.stats.cache_hits))\n")
    first, second = tmp_path / "first.nc", tmp_path / "second.nc"
    assert run("convert", str(SAMPLES / "fanuc-quadratic.nc"), "-o", str(first), "-q")[0] == 0
    code = probe % (str(SAMPLES / "fanuc-quadratic.nc"), str(second))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    ran, compiled = done.stdout.split("\n")[:2]
    assert int(ran) > 0
    assert compiled == "[]"  # every kernel the second run ran came from the cache
    assert first.read_bytes() == second.read_bytes()


@pytest.mark.skipif(not JIT_ENABLED, reason="numba is not in use")
def test_the_first_run_after_an_install_compiles_in_children_what_later_runs_load(
        tmp_path: Path) -> None:
    """An empty numba cache, as after an install: the console script's first compilation has
    child processes run the warm-up (the butterfly under the same profile, commands.warm_up)
    and fill the cache, and compiles only what the warm-up did not run (the kernel whose miss
    started it, among them). It writes the very bytes that the next run, all from the cache,
    writes, and that this process writes (its kernels compiled here or loaded)."""
    probe = ("import json, sys\n"
             "from numba.core import event\n"
             "here = []\n"
             "class Seen(event.Listener):\n"
             "    def on_start(self, ev):\n"
             "        func = ev.data['dispatcher'].py_func\n"
             "        if func.__module__.startswith('nurbsfeed.'):\n"
             "            here.append(func.__qualname__)\n"
             "    def on_end(self, ev):\n"
             "        pass\n"
             "event.register('numba:compile', Seen())\n"
             "from nurbsfeed.cli import run\n"
             "sys.argv = ['nurbsfeed', *sys.argv[1:]]\n"
             "try:\n"
             "    run()\n"
             "except SystemExit as exc:\n"
             "    assert not exc.code, exc.code\n"
             "print(json.dumps(here))\n")
    outputs = {name: tmp_path / f"{name}.nc" for name in ("first", "second", "here")}
    args = ["convert", str(SAMPLES / "quarter-circle.json"), "-m", "paper-table1", "-q", "-o"]
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    compiled = []
    for name in ("first", "second"):
        done = subprocess.run([sys.executable, "-c", probe, *args, str(outputs[name])],
                              env=env, capture_output=True, text=True, check=True)
        compiled.append(json.loads(done.stdout))
    assert 1 <= len(compiled[0]) <= 3 and compiled[1] == []  # 47 compiled in the process
    assert run(*args, str(outputs["here"]))[0] == 0
    assert outputs["first"].read_bytes() == outputs["second"].read_bytes()
    assert outputs["first"].read_bytes() == outputs["here"].read_bytes()


def test_taylor1_conversions_warn_that_they_can_break_the_limits(tmp_path: Path) -> None:
    out = tmp_path / "t.nc"
    code, _, stderr = run("convert", str(SAMPLES / "quarter-circle.json"), "--method", "taylor1",
                          "-o", str(out), "-q")
    assert code == 0 and out.exists()
    assert stderr.startswith("nurbsfeed: warning: taylor1 is the paper's first-order baseline")
    code, _, stderr = run("convert", str(SAMPLES / "quarter-circle.json"), "-o", str(out), "-q")
    assert stderr == ""


def test_a_taylor1_refusal_names_its_drift_not_a_defect(tmp_path: Path) -> None:
    """The circle under the default profile: taylor1's points, slowed as far as the verification
    goes, still jerk 37 % over the Y axis's limit; the refusal says why and what to use, where
    another method's would ask for a report."""
    out = tmp_path / "t.nc"
    code, _, stderr = run("convert", str(SAMPLES / "circle.json"), "--method", "taylor1",
                          "-o", str(out), "-q")
    assert code == 2 and not out.exists()
    message = stderr.splitlines()[-1]
    assert message.startswith(f"{SAMPLES / 'circle.json'}:1:47: curve 0 \"circle\": refused, ")
    assert message.endswith("(taylor1's points drift off the planned feed, which the limits "
                            "do not allow here: use rk2c)")
    assert run("convert", str(SAMPLES / "circle.json"), "-o", str(out), "-q")[0] == 0


def _under_a_terminal(*args: str) -> tuple[int, str]:
    """Run `nurbsfeed` with stderr on a pseudo-terminal: (exit code, everything it showed)."""
    import pty

    chunks: list[bytes] = []

    def read(fd: int) -> bytes:
        data = os.read(fd, 4096)
        chunks.append(data)
        return data

    status = pty.spawn([sys.executable, "-m", "nurbsfeed.cli", *args], read)
    return os.waitstatus_to_exitcode(status), b"".join(chunks).decode()


def planned_points_and_cycle(source: Path) -> tuple[int, float]:
    """The points and cycle a conversion of source under the default profile writes, from
    the plans of its curves."""
    from nurbsfeed.chains import ChainWindow, chain_items
    from nurbsfeed.machine import load_machine
    from nurbsfeed.pipeline import chain_block, plan_block
    from nurbsfeed.readers import read_program

    machine = load_machine("default")
    # curves that join are planned as one chain (design §3b)
    plans = [plan_block(chain_block(item, machine.limits)[0], machine)
             for item in chain_items(read_program(source), machine)
             if isinstance(item, ChainWindow)]
    return (sum(plan.n_periods + 1 for plan in plans),
            sum(plan.cycle_time_s for plan in plans))


STATUS_LINE = re.compile(r"\r(\d+) of (\d+) files, ([\d,]+) points, (\d+) s elapsed, "
                         r"(~\d+ s left|time left unknown)\x1b\[K")


def test_progress_only_on_a_terminal(tmp_path: Path) -> None:
    """Not a terminal (CliRunner): no progress at all. A pseudo-terminal: one status line,
    rewritten in place, with files done of total, points, elapsed time and time left; it is
    drawn at the first converted curve (then at most every 0.1 s), so two curves show it."""
    big = tmp_path / "big.json"
    big.write_text(BUTTERFLIES.format(",".join([BUTTERFLY_CURVE] * 2)))
    code, _, stderr = run("convert", str(big), "-o", str(tmp_path / "a.nc"))
    assert code == 0 and "\r" not in stderr and "files," not in stderr
    out = tmp_path / "b.nc"
    code, text = _under_a_terminal("convert", str(big), "-o", str(out))
    assert code == 0 and out.exists()
    lines = STATUS_LINE.findall(text)
    points, cycle_s = planned_points_and_cycle(big)
    assert lines[0][:2] == ("0", "1") and lines[-1][:3] == ("1", "1", f"{points:,}")
    assert text.endswith("\r\x1b[K" + f"{big}: 2 curves, {points:,} points, cycle "
                         f"{cycle_s:.3f} s -> {out}\r\n")


def test_progress_of_a_batch_under_jobs(tmp_path: Path) -> None:
    """--jobs 2 on a terminal: the status line counts the files as the workers finish them
    (3 of 3 at the end, with every point), and goes away before the summary."""
    sources = [SAMPLES / name for name in ("butterfly.json", "circle.json", "quarter-circle.json")]
    code, text = _under_a_terminal("convert", *map(str, sources), "-o", str(tmp_path / "out"),
                                   "--jobs", "2")
    assert code == 0
    lines = STATUS_LINE.findall(text)
    assert [line[1] for line in lines] == ["3"] * len(lines)
    assert [int(line[0]) for line in lines] == sorted(int(line[0]) for line in lines)
    points = sum(planned_points_and_cycle(source)[0] for source in sources)
    assert lines[-1][:3] == ("3", "3", f"{points:,}")  # the summary's points
    assert lines[-1][4].startswith("~0 s left")
    assert "\x1b[Kfile " in text and text.rstrip().endswith("3 of 3 files converted")


def test_no_progress_under_quiet_on_a_terminal(tmp_path: Path) -> None:
    code, text = _under_a_terminal("convert", str(SAMPLES / "circle.json"), "-o",
                                   str(tmp_path / "c.nc"), "-q")
    assert code == 0 and text == ""


BUTTERFLY_CURVE = (SAMPLES / "butterfly.json").read_text().split('"curves": [')[1].rsplit("]", 1)[0]
BUTTERFLIES = '{{"units": "mm", "curves": [{}]}}'


def _curve_off_chords_mm(curve, u: np.ndarray, points: np.ndarray, sub: int = 8) -> float:
    """How far the curve between consecutive parameters u_k strays from the chord between the
    points written for them: (N,), (N, 3) -> the largest distance."""
    f = np.arange(1, sub) / sub
    between = curve.point((u[:-1, None] + np.diff(u)[:, None] * f).ravel()).reshape(-1, sub - 1, 3)
    a, ab = points[:-1, None, :], np.diff(points, axis=0)[:, None, :]
    t = np.clip(np.sum((between - a) * ab, axis=2) / np.maximum(np.sum(ab * ab, axis=2), 1e-300),
                0.0, 1.0)
    return float(np.max(np.linalg.norm(a + t[..., None] * ab - between, axis=2)))


def _edge_curves() -> dict[str, dict]:
    rng = np.random.default_rng(12)

    def curve(degree: int, n: int, lo: float = 0.0, width: float = 1.0, offset: float = 0.0,
              weights=None) -> dict:
        interior = np.sort(rng.uniform(0.05, 0.95, n - degree - 1))
        knots = lo + width * np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])
        points = offset + np.cumsum(rng.uniform(2.0, 4.0, (n, 2)) * [1, rng.choice([-1, 1])],
                                    axis=0)
        return {"degree": degree, "knots": knots.tolist(), "control_points": points.tolist(),
                "weights": rng.uniform(0.5, 2.0, n).tolist() if weights is None else weights,
                "feed": 3000}

    span = curve(3, 8)
    span["knots"][5] = span["knots"][4] + 1.01e-12
    span["knots"][4:6] = sorted(span["knots"][4:6])
    return {"degree 9": curve(9, 12),
            "weight ratio 1000, heavy": curve(3, 6, weights=[1, 1, 1000, 1, 1, 1]),
            "weight ratio 1000, light": curve(3, 6, weights=[1, 1e-3, 1e-3, 1, 1, 1]),
            "narrowest knot span": span,
            "coordinates near 1e6": curve(3, 8, offset=1e6 - 100.0),
            "coordinates near -1e6": curve(3, 8, offset=-1e6 + 10.0),
            "knot range 1e-6": curve(3, 8, width=1e-6),
            "knot range 1e6": curve(3, 8, width=1e6),
            "knots [1e6, 1e6 + 1]": curve(3, 8, lo=1e6)}


EDGE_CURVES = _edge_curves()


@pytest.mark.parametrize("name", list(EDGE_CURVES))
def test_conversions_at_the_envelope_edges_write_points_on_the_curve(tmp_path: Path,
                                                                     name: str) -> None:
    """At each edge of the input envelope: exit 0; every written point is the curve's point at
    its trace u (given in the input's own knot range) to the output's rounding; the curve
    between consecutive points stays within the chord tolerance of the move; no move is
    longer than the feed allows in one period."""
    src, out, trace = tmp_path / "edge.json", tmp_path / "edge.nc", tmp_path / "edge.csv"
    src.write_text(json.dumps(EDGE_CURVES[name]))
    code, _, stderr = run("convert", str(src), "-o", str(out), "--trace", str(trace), "-q")
    assert code == 0, stderr
    curve = read_json_curves(src)[1][0][0]
    table = np.loadtxt(trace, delimiter=",", skiprows=1)
    u_input, points = table[:, 3], table[:, 8:11]
    assert u_input[0] == curve.u_origin and np.all(np.diff(u_input) >= 0)
    assert u_input[-1] == pytest.approx(curve.u_origin + curve.u_scale, rel=1e-15)
    u = (u_input - curve.u_origin) / curve.u_scale
    rounding_mm = np.sqrt(3) / 2 * 10.0**-DECIMALS
    assert np.max(np.linalg.norm(curve.point(u) - points, axis=1)) <= 1e-9 * (
        1 + np.max(np.abs(points)))
    written, _, _ = moves(out.read_text(), np.round(points[0], DECIMALS))
    assert np.array_equal(written, np.round(points[1:], DECIMALS)[np.any(
        np.diff(np.round(points, DECIMALS), axis=0) != 0, axis=1)])
    assert _curve_off_chords_mm(curve, u, points) <= 0.001 + rounding_mm  # chord_error_mm
    assert np.max(np.linalg.norm(np.diff(points, axis=0), axis=1)) <= 50.0 * 0.001 * (1 + 1e-6)
