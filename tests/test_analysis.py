"""compare (the paper's Table 2) and check (a converted program against its source).

compare is held against an independent recomputation of the feed fluctuation; check must pass on
correct conversions and name the violation in every tampered one. Conversions are shared at module
scope (the JIT compile and the planning count against the test time).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from nurbsfeed.analysis import CHECKS, check_files, compare_file, curve_blocks
from nurbsfeed.analysis.check import project_points
from nurbsfeed.analysis.check.estimates import derivative_estimate, stencils
from nurbsfeed.analysis.geometry import chord_errors_mm
from nurbsfeed.interpolate.kernels import METHODS
from nurbsfeed.interpolate.stepping import interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_file, plan_block
from tests.conftest import SAMPLES, load_curve

PROFILES = ("paper-table1", "default")
CURVES = ("butterfly", "circle")


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, str], Path]:
    """The butterfly and the circle converted under both profiles (rk2c)."""
    folder = tmp_path_factory.mktemp("converted")
    out = {}
    for profile in PROFILES:
        for name in CURVES:
            target = folder / f"{name}-{profile}.nc"
            convert_file(SAMPLES / f"{name}.json", target, load_machine(profile))
            out[(name, profile)] = target
    return out


@pytest.fixture(scope="module")
def two_curves(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A JSON program with the butterfly and the circle, and its conversion (paper profile)."""
    folder = tmp_path_factory.mktemp("two")
    curves = [json.loads((SAMPLES / f"{n}.json").read_text())["curves"][0] for n in CURVES]
    source = folder / "two.json"
    source.write_text(json.dumps({"units": "mm", "curves": curves}))
    target = folder / "two.nc"
    convert_file(source, target, load_machine("paper-table1"))
    return source, target


def violated(report) -> set[str]:
    return {v.check for v in report.violations}


# ---- compare --------------------------------------------------------------------------------

def _independent_ff(curve, result) -> np.ndarray:
    """FF per period from the vectorised evaluator at the stepped parameters (not the kernel's
    points)."""
    chord = np.linalg.norm(np.diff(curve.point(result.u), axis=0), axis=1)
    keep = result.ds_mm > 0
    return np.abs(chord[keep] - result.ds_mm[keep]) / result.ds_mm[keep]


def test_compare_on_the_butterfly_matches_an_independent_computation_and_the_paper_order():
    machine = load_machine("paper-table1")
    table = compare_file(SAMPLES / "butterfly.json", machine, "auto", repeat=3)
    rows = {r.method: r for r in table.rows}
    assert list(rows) == list(METHODS) and table.n_curves == 1
    plan = plan_block(curve_blocks(SAMPLES / "butterfly.json")[0], machine)
    for method, row in rows.items():
        result = interpolate(plan, method)
        ff = _independent_ff(plan.curve, result)
        # the two evaluators agree to ~1e-14 mm: relative 1e-9 of rk2c's 3e-7 fluctuation
        assert row.max_ff_pct == pytest.approx(100 * ff.max(), rel=1e-3, abs=1e-9)
        assert row.mean_ff_pct == pytest.approx(100 * ff.mean(), rel=1e-3, abs=1e-11)
        assert row.n_points == plan.n_periods + 1 == row.n_steps + 1
        assert 0 < row.us_per_step < 1000
    assert rows["taylor1"].max_ff_pct > rows["rk4"].max_ff_pct > rows["rk2c"].max_ff_pct
    assert (rows["taylor1"].paper_max_ff_pct, rows["rk2c"].paper_us_per_step) == (6.84, 11.5)


def test_compare_aggregates_curves_max_of_max_and_step_weighted_mean(two_curves) -> None:
    source, _ = two_curves
    machine = load_machine("paper-table1")
    table = compare_file(source, machine, "auto", repeat=1)
    assert table.n_curves == 2 and table.as_dict()["aggregate"].startswith("max: largest")
    plans = [plan_block(b, machine) for b in curve_blocks(source)]
    for row in table.rows:
        ffs = [_independent_ff(p.curve, interpolate(p, row.method)) for p in plans]
        assert row.max_ff_pct == pytest.approx(100 * max(f.max() for f in ffs), rel=1e-3)
        weighted = sum(f.sum() for f in ffs) / sum(f.size for f in ffs)
        assert row.mean_ff_pct == pytest.approx(100 * weighted, rel=1e-3)
        assert row.n_points == sum(p.n_periods + 1 for p in plans)


# ---- the pieces of check ------------------------------------------------------------------

def test_projection_recovers_the_parameters_of_points_on_a_self_crossing_curve() -> None:
    machine = load_machine("paper-table1")
    plan = plan_block(curve_blocks(SAMPLES / "butterfly.json")[0], machine)
    result = interpolate(plan)
    u, dist = project_points(plan.curve, result.points, 1e-4, 1e-9, 1e-2)
    assert np.max(dist) < 1e-9
    assert np.max(np.abs(u - result.u)) < 1e-9


def test_projection_distance_of_points_off_the_circle_is_the_radial_offset() -> None:
    circle = load_curve("circle")  # centre (50, 0), R 50, starts at (0, 0) going up
    angle = np.linspace(0.1, 6.0, 40)
    offset = np.random.default_rng(7).uniform(-1e-3, 1e-3, angle.size)
    radius = 50.0 + offset
    pts = np.column_stack([50 - radius * np.cos(angle), radius * np.sin(angle),
                           np.zeros(angle.size)])
    u, dist = project_points(circle, pts, 1e-4, 1e-9, 1e-2)
    assert np.allclose(dist, np.abs(offset), rtol=0, atol=1e-12)
    foot = circle.point(u)
    assert np.allclose(np.arctan2(foot[:, 1], 50 - foot[:, 0]) % (2 * np.pi), angle, atol=1e-12)


def test_chord_error_of_circle_arcs_is_the_sagitta() -> None:
    circle = load_curve("circle")
    u0 = np.array([0.05, 0.3, 0.6, 0.8])
    u1 = u0 + np.array([1e-3, 1e-2, 3e-2, 1e-1])
    a, b = circle.point(u0), circle.point(u1)
    half_angle = np.arcsin(np.linalg.norm(b - a, axis=1) / 100.0)
    sagitta = 50.0 * (1.0 - np.cos(half_angle))
    assert np.allclose(chord_errors_mm(circle, u0, u1, a, b), sagitta, rtol=1e-9, atol=1e-15)


def test_divided_differences_are_exact_on_a_cubic_and_bound_the_noise() -> None:
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.integers(1, 4, 200)) * 1e-3  # uneven, as multi-period moves make it
    c = rng.normal(size=4) * [1.0, 50.0, 400.0, 3000.0]
    s = c[0] + c[1] * t + c[2] * t**2 + c[3] * t**3
    e = np.full(t.size, 1e-4)
    for order, exact in ((2, None), (3, 6 * c[3])):
        idx = stencils(t, order, 4e-3)
        value, noise = derivative_estimate(t, s, e, idx)
        if exact is None:  # a = 2 c2 + 6 c3 t, a B-spline mean over the nodes' span
            lo, hi = 2 * c[2] + 6 * c[3] * t[idx[:, 0]], 2 * c[2] + 6 * c[3] * t[idx[:, -1]]
            assert np.all((value >= np.minimum(lo, hi) - 1e-6) & (value <= np.maximum(lo, hi)
                                                                  + 1e-6))
        else:
            assert np.allclose(value, exact, rtol=1e-6)
        bumped, _ = derivative_estimate(t, s + rng.uniform(-1e-4, 1e-4, t.size), e, idx)
        assert np.all(np.abs(bumped - value) <= noise * (1 + 1e-9))


# ---- check on correct conversions -------------------------------------------------------

@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("name", CURVES)
def test_check_passes_on_correct_conversions(converted, name: str, profile: str) -> None:
    report = check_files(SAMPLES / f"{name}.json", converted[(name, profile)],
                         load_machine(profile))
    assert report.ok, "\n".join(map(str, report.violations))
    measured = {m.name: m for m in report.measures}
    assert set(measured) == set(CHECKS)
    model_checks = (("tangential-jerk", "normal-jerk") if report.jerk_model == "paper" else
                    ("tangential-jerk-xyz", "normal-jerk-xyz",
                     *(f"{kind}-{axis}" for kind in ("axis-vel", "axis-acc", "axis-jerk")
                       for axis in "xyz")))
    assert report.jerk_model == ("path" if profile == "default" else "paper")
    for check in ("path-deviation", "chord-error", "coverage", "segment-time", "feed",
                  "tangential-acc", "normal-acc", "acc-xyz", "tangential-acc-xyz",
                  "normal-acc-xyz", *model_checks):
        assert measured[check].n_checked > 0.99 * report.n_moves and measured[check].ratio <= 1
    assert measured["feed"].worst > 0.5 * measured["feed"].limit  # real speeds, not zeros


def test_check_passes_on_a_fanuc_program_with_three_curves(tmp_path: Path) -> None:
    source = SAMPLES / "fanuc-multi-curve.nc"
    target = tmp_path / "multi.nc"
    convert_file(source, target, load_machine("default"))
    report = check_files(source, target, load_machine("default"))
    assert report.ok, "\n".join(map(str, report.violations))
    assert report.n_curves == 3 and report.n_pass_through > 20


def test_feed_limit_both_sides_of_the_allowance(converted) -> None:
    """The paper conversion cruises at 100 mm/s: it passes at 100 and fails at 99 mm/s."""
    target = converted[("butterfly", "paper-table1")]
    source = SAMPLES / "butterfly.json"
    assert check_files(source, target, load_machine("paper-table1")).ok
    report = check_files(source, target, load_machine("paper-table1",
                                                      {"max_feed_mm_s": 99.0}))
    assert violated(report) == {"feed", "coverage"}  # the chord, and the arc it spans
    feed = next(v for v in report.violations if v.check == "feed")
    assert re.fullmatch(r"feed 99\.\d+ mm/s > 99 mm/s \+ 0\.173 mm/s rounding noise",
                        feed.message)


# ---- check on tampered conversions ------------------------------------------------------

def _tampered(path: Path, tmp_path: Path, edit) -> Path:
    lines = path.read_text().splitlines(keepends=True)
    edit(lines)
    out = tmp_path / "tampered.nc"
    out.write_text("".join(lines))
    return out


def _move_with_feed(lines: list[str], start: int = 3000) -> int:
    return next(k for k in range(start, len(lines)) if " F" in lines[k] and "X" in lines[k])


def _scale_feed(lines: list[str], k: int, factor: float) -> None:
    lines[k] = re.sub(r"F([0-9.]+)", lambda m: f"F{float(m[1]) * factor:.3f}", lines[k])


def _move_x(lines: list[str], k: int, delta: float) -> None:
    lines[k] = re.sub(r"X([0-9.]+)", lambda m: f"X{float(m[1]) + delta:.4f}", lines[k])


TAMPERING = {
    "moved point": (lambda ls: _move_x(ls, _move_with_feed(ls), 0.01), "path-deviation"),
    "wrong F": (lambda ls: _scale_feed(ls, _move_with_feed(ls), 1.1), "segment-time"),
    "missing move line": (lambda ls: ls.pop(3000), "skipped-periods"),
    "missing pass-through line": (lambda ls: ls.pop(), "pass-through"),
    "changed pass-through line": (lambda ls: ls.__setitem__(2, ls[2].replace("G0 ", "G00 ")),
                                  "pass-through"),
    "missing last move": (lambda ls: ls.pop(-2), "end-point"),
    "F0": (lambda ls: _scale_feed(ls, _move_with_feed(ls), 0.0), "zero-feed"),
    "number without decimal point": (lambda ls: ls.__setitem__(
        _move_with_feed(ls), re.sub(r"F([0-9]+)\.[0-9]*", r"F\1", ls[_move_with_feed(ls)])),
        "decimal-point"),
    "repeated move": (lambda ls: ls.insert(3000, ls[3000]), "zero-length"),
}


@pytest.mark.parametrize("case", list(TAMPERING))
def test_check_names_the_violation_of_a_tampered_output(converted, tmp_path: Path,
                                                         case: str) -> None:
    edit, expected = TAMPERING[case]
    target = _tampered(converted[("butterfly", "paper-table1")], tmp_path, edit)
    report = check_files(SAMPLES / "butterfly.json", target, load_machine("paper-table1"))
    assert not report.ok and expected in violated(report), "\n".join(map(str, report.violations))


def test_segment_time_tolerance_both_sides(converted, tmp_path: Path) -> None:
    """0.5 % of a period: an F off by 0.4 % passes, by 0.6 % fails."""
    source, path = SAMPLES / "butterfly.json", converted[("butterfly", "paper-table1")]
    machine = load_machine("paper-table1")
    ok = _tampered(path, tmp_path, lambda ls: _scale_feed(ls, _move_with_feed(ls), 1.004))
    assert check_files(source, ok, machine).ok
    bad = _tampered(path, tmp_path, lambda ls: _scale_feed(ls, _move_with_feed(ls), 1.006))
    report = check_files(source, bad, machine)
    assert violated(report) == {"segment-time"}
    assert "off a whole number of periods at its F (allowed 0.5 %)" in report.violations[0].message


def test_negative_zero_is_named(converted, tmp_path: Path) -> None:
    """The circle starts at x = 0: its first moves write X0. for the start column."""
    path = converted[("circle", "paper-table1")]
    lines = path.read_text().splitlines(keepends=True)
    k = next(i for i, line in enumerate(lines) if re.match(r"(G1 )?X0\. ", line))
    lines[k] = lines[k].replace("X0. ", "X-0.000 ", 1)
    target = tmp_path / "neg.nc"
    target.write_text("".join(lines))
    report = check_files(SAMPLES / "circle.json", target, load_machine("paper-table1"))
    assert violated(report) == {"negative-zero"}


def test_a_dropped_curve_is_named(two_curves, tmp_path: Path) -> None:
    source, path = two_curves
    lines = path.read_text().splitlines(keepends=True)
    first = next(i for i, line in enumerate(lines) if line.startswith("(nurbsfeed: curve 1 "))
    end = next(i for i in range(first + 1, len(lines)) if lines[i].strip() == "M2")
    target = tmp_path / "dropped.nc"
    target.write_text("".join(lines[:first] + lines[end:]))
    report = check_files(source, target, load_machine("paper-table1"))
    assert violated(report) == {"curve-missing"}
    assert "curve 1 (circle" in report.violations[0].message
    assert report.violations[0].where == f"{target}:{first + 1}"


FANUC_G91 = """%
O2000 (A QUADRATIC G06.2 CURVE{mode})
G17 G21 G90 G94
G0 X0. Y0.
G1 Z-1. F600.
{g91}G06.2 P3 K0. X0. Y0. R1. F3000.
K0. X20. Y30.
K0. X40. Y-10.
K0.5 X60. Y20.
K1.
K1.
K1.
F500.
G90
M30
%
"""


@pytest.mark.parametrize("incremental", [False, True])
def test_modal_lines_around_the_moves(tmp_path: Path, incremental: bool) -> None:
    """A bare F line after the curve looks like a move and is not taken for one; under G91 the
    moves need their G90 ... G91 bracket."""
    source = tmp_path / "g91.nc"
    source.write_text(FANUC_G91.format(mode=" IN G91" if incremental else "",
                                       g91="G91\n" if incremental else ""))
    target = tmp_path / "g91-out.nc"
    machine = load_machine("default")
    convert_file(source, target, machine)
    report = check_files(source, target, machine)
    assert report.ok, "\n".join(map(str, report.violations))
    if incremental:
        lines = target.read_text().splitlines(keepends=True)
        lines.remove("G90\n")  # the first G90: the bracket's opening line
        target.write_text("".join(lines))
        assert violated(check_files(source, target, machine)) == {"g90-g91"}
