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

KAPPA_STEP_REL = 0.1  # refine where kappa changes by more than 10 % between nodes
REFINE_ROUNDS = 6  # ... down to 1/64 of the base spacing
ZOOM_SAMPLES = 11
ZOOM_ROUNDS = 12  # the bracket (two grid steps) shrinks by 5^12 ~ 2e8
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
    return _kappa_and_speed(curve, u)[0]


def _kappa_and_speed(curve: NurbsCurve, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    _, c1, c2 = curve.derivatives(u)
    return curvature_from_derivatives(c1, c2), np.sqrt(np.einsum("ij,ij->i", c1, c1))



def _refine_peaks(curve: NurbsCurve, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """The maximum of kappa in each bracket [low_i, high_i], all brackets at once.

    Zoom sampling: ZOOM_SAMPLES points per bracket, keep the best and its neighbours as the next
    bracket, ZOOM_ROUNDS times (the bracket shrinks by ZOOM_SAMPLES/2 per round). Unlike a
    parabolic or Newton step it needs no smoothness, so a maximum on a knot (a kink in kappa)
    is found as well as a smooth one.
    """
    frac = np.linspace(0.0, 1.0, ZOOM_SAMPLES)
    best = 0.5 * (low + high)
    for _ in range(ZOOM_ROUNDS):
        u = low[:, None] + (high - low)[:, None] * frac[None, :]
        k = np.nan_to_num(_kappa(curve, u.ravel()), nan=-1.0).reshape(u.shape)
        i = np.argmax(k, axis=1)
        rows = np.arange(u.shape[0])
        best = u[rows, i]
        low = u[rows, np.maximum(i - 1, 0)]
        high = u[rows, np.minimum(i + 1, ZOOM_SAMPLES - 1)]
    return best


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


def _refine_where_kappa_jumps(curve: NurbsCurve, u: np.ndarray, kappa: np.ndarray,
                              speed: np.ndarray, kappa_floor: float):
    """Halve every interval across which kappa (above kappa_floor) changes by more than
    KAPPA_STEP_REL, up to REFINE_ROUNDS times. The planner bounds the limit between two nodes by
    the lower of their limits; near a sharp curvature peak that bound is only tight when the
    nodes are close, so the grid is made dense exactly there."""
    for _ in range(REFINE_ROUNDS):
        high = np.maximum(kappa[:-1], kappa[1:])
        split = (high > kappa_floor) & (np.abs(np.diff(kappa)) > KAPPA_STEP_REL * high)
        if not np.any(split):
            break
        mid = 0.5 * (u[:-1][split] + u[1:][split])
        k_mid, s_mid = _kappa_and_speed(curve, mid)
        order = np.argsort(np.concatenate([u, mid]), kind="stable")
        u = np.concatenate([u, mid])[order]
        kappa = np.concatenate([kappa, _fill_singular(k_mid)])[order]
        speed = np.concatenate([speed, s_mid])[order]
    return u, kappa, speed


def build_grid(curve: NurbsCurve, spacing_mm: float, extra_u: np.ndarray = np.empty(0),
               kappa_floor: float = np.inf) -> Grid:
    """Sample, find and refine curvature maxima, integrate arc length: the planning grid.

    extra_u: parameters that must be nodes (where the programmed feed changes); kappa_floor:
    below it the limit does not depend on curvature (kappa_0), so no refinement is needed.
    """
    breaks = curve.span_breaks
    counts = _span_node_counts(curve, breaks, spacing_mm)
    pieces = [np.linspace(breaks[i], breaks[i + 1], counts[i], endpoint=False)
              for i in range(len(breaks) - 1)]
    u = np.concatenate(pieces + [breaks[-1:]])
    kappa, speed = _kappa_and_speed(curve, u)
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

    extra = np.concatenate([peak_u, corner_u, extra_u])
    u_all, first = np.unique(np.concatenate([u, extra]), return_index=True)
    # kappa and |C'| of the sample nodes are known; only the added nodes are evaluated
    kappa_extra, speed_extra = _kappa_and_speed(curve, extra)
    kappa_all = _fill_singular(np.concatenate([kappa, kappa_extra])[first])
    speed_all = np.concatenate([speed, speed_extra])[first]
    u_all, kappa_all, speed_all = _refine_where_kappa_jumps(curve, u_all, kappa_all, speed_all,
                                                            kappa_floor)
    corner_index = np.searchsorted(u_all, corner_u)
    kappa_all[corner_index] = np.inf
    peak_index = np.searchsorted(u_all, peak_u)

    lengths = simpson_lengths(curve.speed, u_all, speed_all,
                              ARC_REL_TOL * np.diff(u_all) * _mean_speed(speed))
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


def _mean_speed(speed: np.ndarray) -> float:
    return float(np.mean(speed)) + 1e-300


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
