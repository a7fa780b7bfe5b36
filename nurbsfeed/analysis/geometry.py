"""Measurements on the true curve shared by `check` and `plot`: chord errors, arc length,
curvature."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.arclength import gauss_lengths
from nurbsfeed.geometry.nurbs import curvature_from_derivatives

CHORD_SAMPLES = 9
CHORD_REFINE_ITERATIONS = 40
GOLDEN = 0.5 * (math.sqrt(5.0) - 1.0)


def _distance_to_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of points p from segments [a, b]: (..., 3) each -> (...,)."""
    ab = b - a
    len2 = np.sum(ab * ab, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(len2 > 0.0, np.sum((p - a) * ab, axis=-1) / len2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p - a - t[..., None] * ab, axis=-1)


def chord_errors_mm(curve: NurbsCurve, u0: np.ndarray, u1: np.ndarray, a: np.ndarray,
                    b: np.ndarray) -> np.ndarray:
    """Farthest distance of the arc C([u0_i, u1_i]) from the segment [a_i, b_i]: (N,) -> (N,).

    a, b: (N, 3). CHORD_SAMPLES inner samples locate the farthest point, then a golden-section
    search refines it between the samples beside it (the distance is unimodal on one step).
    """
    if u0.size == 0:
        return np.zeros(0)
    frac = np.linspace(0.0, 1.0, CHORD_SAMPLES + 2)
    du = u1 - u0
    pts = curve.point((u0[:, None] + du[:, None] * frac[None, :]).ravel())
    dist = _distance_to_segments(pts.reshape(u0.size, frac.size, 3), a[:, None, :],
                                 b[:, None, :])
    best = np.argmax(dist, axis=1)
    worst = dist[np.arange(u0.size), best]
    lo = frac[np.maximum(best - 1, 0)]
    hi = frac[np.minimum(best + 1, frac.size - 1)]

    def at(f: np.ndarray) -> np.ndarray:
        return _distance_to_segments(curve.point(u0 + du * f), a, b)

    x1, x2 = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
    f1, f2 = at(x1), at(x2)
    for _ in range(CHORD_REFINE_ITERATIONS):
        left = f1 >= f2
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        new = np.where(left, hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo))
        f_new = at(new)
        x1, x2, f1, f2 = (np.where(left, new, x2), np.where(left, x1, new),
                          np.where(left, f_new, f2), np.where(left, f1, f_new))
    return np.maximum(worst, np.maximum(f1, f2))


GAUSS_POINTS = 5  # of each piece between the sorted parameters and the knots


def arc_length_mm(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    """Arc length from u_min to each u: (N,) -> (N,), u in any order.

    5-point Gauss-Legendre on the intervals between the sorted parameters and the knots (so that
    no interval holds a knot, where |C'| may jump): exact to rounding on steps this short.
    """
    nodes = np.unique(np.concatenate([np.asarray(u, dtype=float), curve.span_breaks]))
    lengths = gauss_lengths(curve.speed, nodes[:-1], nodes[1:], GAUSS_POINTS)
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    return cumulative[np.searchsorted(nodes, u)] - cumulative[np.searchsorted(nodes,
                                                                              curve.u_min)]


def curve_length_mm(curve: NurbsCurve) -> float:
    """The whole curve's arc length."""
    return float(arc_length_mm(curve, np.array([curve.u_max]))[0])


def curvature_1_mm(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    """kappa at u: (N,) -> (N,); 0 where C'(u) = 0 (a repeated control point)."""
    _, c1, c2 = curve.derivatives(u)
    return np.nan_to_num(curvature_from_derivatives(c1, c2), nan=0.0)
