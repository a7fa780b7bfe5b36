"""The dense grid a curve is planned on: parameters, arc length, curvature, pointwise limits.

The grid has nodes at every knot and enough nodes inside each span that consecutive nodes are
at most `spacing_mm` apart; refined curvature maxima are nodes too. The planner checks its speed
profile at these nodes ("limits everywhere"), so the spacing is tied to the step length v_m T.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.arclength import simpson_lengths
from nurbsfeed.geometry.nurbs import NurbsCurve, curvature_from_derivatives

GOLDEN = 0.5 * (np.sqrt(5.0) - 1.0)
PEAK_ITERATIONS = 60  # golden-section steps: the bracket shrinks by 0.618^60 ~ 3e-13
ARC_REL_TOL = 1e-10  # arc length tolerance relative to the span's length
MIN_NODES_PER_SPAN = 8


@dataclass(frozen=True, eq=False)
class Grid:
    """Nodes along one curve; every array is (M,) and read-only."""

    u: np.ndarray
    s_mm: np.ndarray  # cumulative arc length, s[0] = 0
    kappa_1_mm: np.ndarray  # curvature; at a point where C' = 0, the limit from inside
    peak_index: np.ndarray  # (P,) nodes that are local curvature maxima (refined)
    corner_index: np.ndarray  # (Q,) nodes where the tangent jumps (C0 knots): speed 0

    @property
    def length_mm(self) -> float:
        return float(self.s_mm[-1])


def _span_node_counts(curve: NurbsCurve, breaks: np.ndarray, spacing_mm: float) -> np.ndarray:
    """Nodes per span so that node spacing <= spacing_mm (from a 16-point chord estimate)."""
    probe = np.linspace(0.0, 1.0, 17)
    u = breaks[:-1, None] + (breaks[1:] - breaks[:-1])[:, None] * probe[None, :]
    pts = curve.point(u.ravel()).reshape(u.shape + (3,))
    chord = np.linalg.norm(np.diff(pts, axis=1), axis=-1).sum(axis=1)
    return np.maximum(MIN_NODES_PER_SPAN, np.ceil(1.05 * chord / spacing_mm)).astype(int)


def _kappa(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    _, c1, c2 = curve.derivatives(u)
    return curvature_from_derivatives(c1, c2)


def _refine_peaks(curve: NurbsCurve, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Golden-section search for the maximum of kappa in each [low_i, high_i], all at once."""
    x1 = high - GOLDEN * (high - low)
    x2 = low + GOLDEN * (high - low)
    f1, f2 = _kappa(curve, x1), _kappa(curve, x2)
    for _ in range(PEAK_ITERATIONS):
        left = np.nan_to_num(f1, nan=-1.0) >= np.nan_to_num(f2, nan=-1.0)
        high = np.where(left, x2, high)
        low = np.where(left, low, x1)
        new_x = np.where(left, high - GOLDEN * (high - low), low + GOLDEN * (high - low))
        f_new = _kappa(curve, new_x)
        x2, f2, x1, f1 = (np.where(left, x1, new_x), np.where(left, f1, f_new),
                          np.where(left, new_x, x2), np.where(left, f_new, f2))
    return 0.5 * (low + high)


def _corners(curve: NurbsCurve, breaks: np.ndarray) -> np.ndarray:
    """Interior knots of multiplicity >= degree where the unit tangent jumps (a sharp corner)."""
    interior = breaks[1:-1]
    if interior.size == 0:
        return interior
    mult = np.array([np.count_nonzero(curve.knots == k) for k in interior])
    cand = interior[mult >= curve.degree]
    if cand.size == 0:
        return cand
    eps = 1e-9 * (curve.u_max - curve.u_min)
    d_left = curve.derivatives(cand - eps)[1]
    d_right = curve.derivatives(cand + eps)[1]
    unit = lambda d: d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)
    cos = np.sum(unit(d_left) * unit(d_right), axis=-1)
    return cand[cos < 1.0 - 1e-8]


def build_grid(curve: NurbsCurve, spacing_mm: float,
               extra_u: np.ndarray = np.empty(0)) -> Grid:
    """Sample, find and refine curvature maxima, integrate arc length: the planning grid.

    extra_u: parameters that must be nodes (where the programmed feed changes).
    """
    breaks = curve.span_breaks
    counts = _span_node_counts(curve, breaks, spacing_mm)
    pieces = [np.linspace(breaks[i], breaks[i + 1], counts[i], endpoint=False)
              for i in range(len(breaks) - 1)]
    u = np.concatenate(pieces + [breaks[-1:]])
    kappa = _kappa(curve, u)
    kappa = _fill_singular(kappa)

    # Local maxima on the samples (a plateau counts once, at its first node), then refined
    # inside the bracket of their neighbours. Knots stay maxima where kappa has a kink.
    inner = np.arange(1, u.size - 1)
    is_max = (kappa[inner] > kappa[inner - 1]) & (kappa[inner] >= kappa[inner + 1])
    idx = _prominent(kappa, inner[is_max])
    refined = _refine_peaks(curve, u[idx - 1], u[idx + 1])
    refined_kappa = _kappa(curve, refined)
    better = np.nan_to_num(refined_kappa, nan=-1.0) > kappa[idx]
    peak_u = np.where(better, refined, u[idx])
    corner_u = _corners(curve, breaks)

    u_all = np.unique(np.concatenate([u, peak_u, corner_u, extra_u]))
    kappa_all = _fill_singular(_kappa(curve, u_all))
    corner_index = np.searchsorted(u_all, corner_u)
    kappa_all[corner_index] = np.inf
    peak_index = np.searchsorted(u_all, peak_u)

    lengths = simpson_lengths(curve.speed, u_all[:-1], u_all[1:],
                              ARC_REL_TOL * np.maximum(np.abs(np.diff(u_all)), 0.0)
                              * _mean_speed(curve))
    s = np.concatenate([[0.0], np.cumsum(lengths)])
    for a in (u_all, s, kappa_all, peak_index, corner_index):
        a.setflags(write=False)
    return Grid(u_all, s, kappa_all, peak_index, corner_index)


PEAK_PROMINENCE_REL = 1e-7


def _prominent(kappa: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Maxima that stand out from the valleys on both sides by a relative 1e-7, so that the
    rounding noise of a constant-curvature arc (1e-15) does not make every node a peak."""
    if idx.size == 0:
        return idx
    bounds = np.concatenate([[0], idx, [kappa.size - 1]])
    valley = np.minimum.reduceat(kappa, bounds[:-1])[: idx.size + 1]
    # valley[k] is the lowest kappa between peak k-1 and peak k (inclusive of the left end)
    left, right = valley[:-1], valley[1:]
    lowest_side = np.maximum(left, right)
    return idx[kappa[idx] > lowest_side * (1.0 + PEAK_PROMINENCE_REL)]


def _mean_speed(curve: NurbsCurve) -> float:
    u = np.linspace(curve.u_min, curve.u_max, 65)
    return float(np.mean(curve.speed(u))) + 1e-300


def _fill_singular(kappa: np.ndarray) -> np.ndarray:
    """Where C' = 0 (repeated control points) kappa is NaN: use the neighbouring node's value,
    the limit of kappa from inside the curve (SPEC §3a)."""
    bad = ~np.isfinite(kappa)
    if not np.any(bad):
        return kappa
    good = np.flatnonzero(~bad)
    if good.size == 0:
        return np.zeros_like(kappa)
    nearest = good[np.clip(np.searchsorted(good, np.flatnonzero(bad)), 0, good.size - 1)]
    out = kappa.copy()
    out[bad] = kappa[nearest]
    return out
