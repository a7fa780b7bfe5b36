"""Curvature peaks the planning grid or the limit rounds missed (fuzzer finds): the normal limits
must hold at every interpolation point, not only at the grid's nodes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbsfeed.cli import main
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.nurbs import curvature_from_derivatives
from nurbsfeed.interpolate import interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.planning.planner import plan_curve
from tests.limits_check import measure

DATA = Path(__file__).parent / "data" / "peaks"
LIMIT_REL = 1e-6

# tests/data/peaks/peak-before-end.nc: kappa 37.3 inside the last sample interval (kappa 2.5 at
# the sample before, 20.3 at the end); the plan ran v^3 kappa^2 to 1.72 J_n there
BEFORE_END = NurbsCurve.build(
    3, [0, 0, 0, 0, 0.6, 0.9, 0.9, 1, 1, 1, 1],
    [[1, 2, 0], [3.946, 0, 0], [0.341, 0.341, 0], [0, 0.01, 0], [1.29, 4.869, 0],
     [4.032, 3.386, 0], [4.01, 3.679, 0]],
    [1, 1.1, 1, 1.193, 1, 1, 1])
# tests/data/peaks/peak-before-knot.ngc (G18: Z, X): kappa 21.7 just before the knot 0.25,
# where kappa jumps from 16.8 down to 7.5; the sample before it has 16.4. 1.69 J_n.
BEFORE_KNOT = NurbsCurve.build(
    2, [0, 0, 0, 0.25, 0.5, 0.75, 1, 1, 1],
    [[3, 3, 0], [0.772, 3, 4.289], [1.335, 3, 4.393], [0, 3, 0.391], [4.955, 3, 0.972],
     [0, 3, 0]],
    [1, 1.571, 1.812, 1.177, 0.528, 1])


def kappa_at(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    _, c1, c2 = curve.derivatives(u)
    return curvature_from_derivatives(c1, c2)


@pytest.mark.parametrize("curve", [BEFORE_END, BEFORE_KNOT], ids=["end", "knot"])
def test_no_grid_interval_hides_a_curvature_above_both_its_nodes(curve: NurbsCurve) -> None:
    """The planner bounds the limit between two nodes by the lower of their limits: kappa
    between them must not exceed the higher of theirs (dense sampling, 64 per interval)."""
    grid = plan_curve(curve, load_machine("default").limits).grid
    frac = np.linspace(0.0, 1.0, 66)[1:-1]
    inside = grid.u[:-1, None] + np.diff(grid.u)[:, None] * frac[None, :]
    highest = kappa_at(curve, inside.ravel()).reshape(inside.shape).max(axis=1)
    ends = np.maximum(grid.kappa_1_mm[:-1], grid.kappa_1_mm[1:])
    assert np.all(highest <= ends * (1 + 1e-3)), np.max(highest / ends)


@pytest.mark.parametrize(("curve", "where"), [(BEFORE_END, (0.9972, 0.9975)),
                                              (BEFORE_KNOT, (0.2403, 0.2408))],
                         ids=["end", "knot"])
def test_the_hidden_maximum_is_a_peak_node(curve: NurbsCurve, where) -> None:
    grid = plan_curve(curve, load_machine("default").limits).grid
    peaks = grid.u[grid.peak_index]
    (found,) = peaks[(peaks > where[0]) & (peaks < where[1])]
    around = kappa_at(curve, found + np.array([-1e-6, 0.0, 1e-6]))
    assert around[1] >= around.max() * (1 - 1e-12)


@pytest.mark.parametrize("curve", [BEFORE_END, BEFORE_KNOT], ids=["end", "knot"])
def test_normal_limits_hold_at_every_interpolation_point(curve: NurbsCurve) -> None:
    """Under the default profile (v_m 200 mm/s)."""
    lim = load_machine("default").limits
    m = measure(curve, interpolate(plan_curve(curve, lim)), lim)
    assert m.normal_jerk <= lim.normal_jerk_mm_s3 * (1 + LIMIT_REL), m
    assert m.normal_acc <= lim.normal_acc_mm_s2 * (1 + LIMIT_REL), m
    assert m.v_over_limit <= 1 + LIMIT_REL, m


@pytest.mark.parametrize("name", ["peak-before-end.nc", "peak-before-knot.ngc"])
def test_check_passes_on_the_conversion(tmp_path: Path, name: str) -> None:
    """The programs as the fuzzer's finds had them (one curve each): `check` measured normal
    jerk 1.68 and 1.66 times J_n on their conversions."""
    out = tmp_path / "out.nc"
    runner = CliRunner()
    converted = runner.invoke(main, ["convert", str(DATA / name), "-o", str(out)])
    assert converted.exit_code == 0, converted.stderr
    checked = runner.invoke(main, ["check", str(DATA / name), str(out)])
    assert checked.exit_code == 0, checked.output
    assert "result: OK: 0 violation(s)" in checked.output


# A quarter circle of radius 10 (rational quadratic): kappa 0.1 everywhere, so the limit is
# sqrt(A_n / kappa) = 31.62 mm/s under the linuxcnc profile at every point, and no node shows
# more than any other. Its shoulder segments one grid interval long once peaked at 32.08 and
# 33.16 mm/s between their two nodes: v^2 kappa 9 % over A_n where no node looked.
QUARTER = NurbsCurve.build(2, [0, 0, 0, 1, 1, 1], [[10, 0, 0], [10, 10, 0], [0, 10, 0]],
                           [1, 2**-0.5, 1])


def test_a_peak_between_two_nodes_keeps_the_limit_at_every_point() -> None:
    """Measured at every interpolation point (tests/limits_check, the curve's own curvature),
    and on the law itself, sampled at 0.1 ms (the circle's limit is one number)."""
    lim = load_machine("linuxcnc").limits
    plan = plan_curve(QUARTER, lim)
    m = measure(QUARTER, interpolate(plan, "rk2c"), lim)
    assert m.normal_acc <= lim.normal_acc_mm_s2 * (1 + LIMIT_REL), m
    assert plan.piece_scale.size == 1  # rest to rest: the law runs at v / piece_scale
    v = plan.law.sample(np.arange(0.0, plan.law.duration_s, 1e-4))[1] / plan.piece_scale[0]
    assert v.max() <= np.sqrt(lim.normal_acc_mm_s2 / 0.1) * (1 + LIMIT_REL), v.max()
