"""The planning grid's node data and the path model's compiled kernels against the vectorised
numpy they stand for, to the last bit: the references here are that numpy, written out (the
path model's entry points, path_limit, least_cycle_s, axis_capped, arc_parameters and the
cells' geometry rows, compute every value as it does, operation for operation, in one pass per
node or point)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from nurbsfeed.analysis.common import curve_blocks
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine, machine_from_mapping
from nurbsfeed.planning.basis import G_CAP, G_D, G_K, G_KAPPA, G_KS, G_SIZE, G_T
from nurbsfeed.planning.cells import point_geometry
from nurbsfeed.planning.grid import ZERO_SPEED_REL, Grid, build_grid
from nurbsfeed.planning.limits import Limits, curvature_threshold, speed_limit
from nurbsfeed.planning.path_check import arc_parameters, axis_capped, least_cycle_s, path_limit
from nurbsfeed.planning.path_model import Frames, frames, kappa_n_jumps
from nurbsfeed.planning.plan import grid_spacing
from tests.bench.dense_curves import dense_curves
from tests.test_degenerate import EXAMPLES, degenerate_curves
from tests.test_path_model import PATH_PROFILE

SAMPLES = Path(__file__).resolve().parents[1] / "samples"


def _limits() -> list[Limits]:
    return [load_machine("default").limits, load_machine("linuxcnc").limits,
            machine_from_mapping(PATH_PROFILE, "test").limits]


def _curves() -> list[NurbsCurve]:
    samples = [b.curve for f in sorted(SAMPLES.iterdir()) for b in curve_blocks(f)]
    return samples + dense_curves(quick=True)


def _grid(curve: NurbsCurve, lim: Limits) -> Grid:
    return build_grid(curve, grid_spacing(curve, lim), np.empty(0), curvature_threshold(lim))


def _cbrt_limit(budget: float, per_v3: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.where(per_v3 > 0.0, np.cbrt(budget / np.where(per_v3 > 0.0, per_v3, 1.0)),
                        np.inf)


def _static_limit(f: Frames, lim: Limits) -> np.ndarray:
    v = _cbrt_limit(lim.jerk_mm_s3, f.kappa**2)
    v = np.minimum(v, _cbrt_limit(lim.normal_jerk_mm_s3, np.hypot(f.dkappa_ds,
                                                                  f.kappa * f.torsion)))
    jerk_dir = (-(f.kappa**2)[:, None] * f.tangent + f.dkappa_ds[:, None] * f.normal
                + (f.kappa * f.torsion)[:, None] * f.binormal)
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(f.tangent[:, x])
            v = np.minimum(v, np.where(tx > 0.0, lim.axis_vel_mm_s[x] / np.where(tx > 0.0, tx, 1.0),
                                       np.inf))
            kn = f.kappa * np.abs(f.normal[:, x])
            v = np.minimum(v, np.where(kn > 0.0, np.sqrt(lim.axis_acc_mm_s2[x]
                                                         / np.where(kn > 0.0, kn, 1.0)), np.inf))
            v = np.minimum(v, _cbrt_limit(lim.axis_jerk_mm_s3[x], np.abs(jerk_dir[:, x])))
    return v


def _jump_speeds(jump: np.ndarray, lim: Limits) -> np.ndarray:
    t = lim.period_s
    size = np.sqrt(np.einsum("...i,...i->...", jump, jump))
    with np.errstate(divide="ignore"):
        v = np.where(size > 0.0, np.sqrt(lim.normal_jerk_mm_s3 * t
                                         / np.where(size > 0.0, size, 1.0)), np.inf)
        for x in range(3):
            d = np.abs(jump[:, x])
            v = np.minimum(v, np.where(d > 0.0, np.sqrt(lim.axis_jerk_mm_s3[x] * t
                                                        / np.where(d > 0.0, d, 1.0)), np.inf))
    return v


def _binding_minima(limit: np.ndarray, raw_limit: np.ndarray) -> np.ndarray:
    w = 3
    floor = np.where(limit > 0.0, limit, np.inf)
    windows_min = np.lib.stride_tricks.sliding_window_view(np.pad(floor, w, mode="edge"),
                                                           2 * w + 1)
    windows_max = np.lib.stride_tricks.sliding_window_view(np.pad(limit, w, mode="edge"),
                                                           2 * w + 1)
    rise = 2.0 * limit
    binding = (limit < raw_limit) & (limit > 0.0) & np.isfinite(limit)
    minimum = ((windows_min[:, :w].min(axis=1) > limit)
               & (windows_min[:, w + 1:].min(axis=1) >= limit)
               & (windows_max[:, :w].max(axis=1) >= rise)
               & (windows_max[:, w + 1:].max(axis=1) >= rise))
    step = (windows_max[:, w - 1] >= rise) | (windows_max[:, w + 1] >= rise)
    keys = binding & (minimum | step)
    keys[[0, -1]] = False
    return np.flatnonzero(keys)


def _path_limit(curve: NurbsCurve, grid: Grid, lim: Limits, raw_limit: np.ndarray):
    static = _static_limit(frames(curve, grid.u), lim)
    speed = curve.speed(grid.u)
    zero = speed <= ZERO_SPEED_REL * speed.mean()
    if zero.any() and not zero.all():
        index = np.arange(static.size)
        before = np.maximum.accumulate(np.where(zero, -1, index))
        after = np.minimum.accumulate(np.where(zero, static.size, index)[::-1])[::-1]
        padded = np.concatenate([static, [np.inf, np.inf]])
        static = np.where(zero, np.minimum(padded[before], padded[after]), static)
    limit = np.minimum(raw_limit, static)
    breaks = curve.span_breaks[1:-1]
    nodes = np.searchsorted(grid.u, breaks)
    inside = nodes < grid.u.size
    nodes, breaks = nodes[inside], breaks[inside]
    on_node = grid.u[nodes] == breaks
    nodes, breaks = nodes[on_node], breaks[on_node]
    at_jump = _jump_speeds(kappa_n_jumps(curve, breaks, ZERO_SPEED_REL * float(speed.mean())),
                           lim)
    lower = at_jump < limit[nodes]
    limit[nodes[lower]] = at_jump[lower]
    return limit, np.union1d(nodes[lower], _binding_minima(limit, raw_limit))


def _geometry_rows(curve: NurbsCurve, lim: Limits, u: np.ndarray, feed_mm_s: np.ndarray,
                   at_knot: np.ndarray) -> np.ndarray:
    f = frames(curve, u)
    out = np.zeros((u.size, G_SIZE))
    k = f.kappa
    out[:, G_KAPPA] = k
    out[:, G_T:G_T + 3] = f.tangent
    out[:, G_K:G_K + 3] = k[:, None] * f.normal
    out[:, G_KS:G_KS + 3] = (-(k**2)[:, None] * f.tangent + f.dkappa_ds[:, None] * f.normal
                            + (k * f.torsion)[:, None] * f.binormal)
    knot = at_knot >= 0
    if knot.any():
        out[knot, G_D:G_D + 3] = kappa_n_jumps(curve, curve.span_breaks[at_knot[knot]])
    cap = np.minimum(speed_limit(k, lim, feed_mm_s), lim.feed_mm_s)
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(f.tangent[:, x])
            cap = np.minimum(cap, np.where(tx > 0.0, lim.axis_vel_mm_s[x]
                                           / np.where(tx > 0.0, tx, 1.0), np.inf))
    out[:, G_CAP] = cap**2
    return out


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def _check_curve(curve: NurbsCurve, lim: Limits) -> None:
    grid = _grid(curve, lim)
    # the grid's C, C' and |C'| are the curve's own evaluation at its nodes
    assert _same(grid.points_mm, curve.point(grid.u))
    assert _same(grid.d1_mm, curve.derivatives(grid.u)[1])
    assert _same(grid.speed_mm, curve.speed(grid.u))
    fcap = np.full(grid.u.size, 0.7 * lim.feed_mm_s)
    raw = speed_limit(grid.kappa_1_mm, lim, fcap)
    limit, keys = path_limit(curve, grid, lim, raw)
    ref_limit, ref_keys = _path_limit(curve, grid, lim, raw)
    assert _same(limit, ref_limit) and _same(keys, ref_keys.astype(np.int64))
    travel = np.abs(np.diff(curve.point(grid.u), axis=0))
    axis_s = np.max(travel / np.asarray(lim.axis_vel_mm_s), axis=1)
    cap = np.minimum(np.maximum(fcap[:-1], fcap[1:]), lim.feed_mm_s)
    assert least_cycle_s(curve, grid, lim, fcap) == float(
        np.sum(np.maximum(np.diff(grid.s_mm) / cap, axis_s)))
    tangent = frames(curve, grid.u).tangent
    capped = np.minimum(raw, lim.feed_mm_s)
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(tangent[:, x])
            capped = np.minimum(capped, np.where(tx > 0.0, lim.axis_vel_mm_s[x]
                                                 / np.where(tx > 0.0, tx, 1.0), np.inf))
    assert _same(axis_capped(curve, grid, lim, raw), capped)
    # rows at the nodes (the knots among them from both sides) and between them
    middles = arc_parameters(curve, grid, 0.5 * (grid.s_mm[1:] + grid.s_mm[:-1]))
    u = np.concatenate((grid.u, middles))
    inner = curve.span_breaks[1:-1]
    at_knot = np.full(u.size, -1)
    on_knot = np.isin(grid.u, inner)
    at_knot[:grid.u.size][on_knot] = np.searchsorted(curve.span_breaks, grid.u[on_knot])
    feed = np.full(u.size, 0.7 * lim.feed_mm_s)
    assert _same(point_geometry(curve, lim, u, feed, at_knot),
                 _geometry_rows(curve, lim, u, feed, at_knot))


@pytest.mark.parametrize("lim", _limits(), ids=["default", "linuxcnc", "path-axes"])
def test_the_kernels_give_the_vectorised_values_on_the_samples_and_dense_curves(
        lim: Limits) -> None:
    for curve in _curves():
        _check_curve(curve, lim)


@settings(max_examples=EXAMPLES // 3, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(degenerate_curves())
def test_the_kernels_give_the_vectorised_values_on_degenerate_curves(curve: NurbsCurve) -> None:
    """Repeated control points (zeros of C', where the limit takes its neighbours'), corners,
    degree 2 (kappa N jumps at the knots)."""
    _check_curve(curve, machine_from_mapping(PATH_PROFILE, "test").limits)


def test_arc_parameters_interpolate_as_np_interp_outside_and_at_the_nodes_too() -> None:
    """Where |C'| is even across every interval, u(s) is np.interp's, to the bit: before the
    first node, after the last, on nodes, between them, in any order."""
    curve = _curves()[0]
    grid = _grid(curve, load_machine("default").limits)
    assert np.all(grid.speed_mm[1:] <= 1.5 * grid.speed_mm[:-1])
    assert np.all(grid.speed_mm[:-1] <= 1.5 * grid.speed_mm[1:])
    rng = np.random.default_rng(3)
    s = np.concatenate((rng.uniform(-1.0, grid.length_mm + 1.0, 500), grid.s_mm,
                        [-math.inf, math.inf, 0.0, grid.length_mm]))
    for order in (np.arange(s.size), rng.permutation(s.size), np.argsort(s)):
        assert _same(arc_parameters(curve, grid, s[order]), np.interp(s[order], grid.s_mm, grid.u))
