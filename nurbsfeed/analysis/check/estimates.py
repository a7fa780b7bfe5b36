"""Derivatives of a sampled motion by divided differences, with their rounding-noise bounds.

k! f[t_0..t_k] is a B-spline weighted mean of the k-th derivative over [t_0, t_k] (Peano kernel,
Hermite-Genocchi), for vectors as for scalars: its size never exceeds the largest true one. An
error of at most e_q on each sample changes it by at most k! sum_q |w_q| e_q (w_q the difference's
weights), and that bound falls as the baseline h (the spacing of the nodes) grows, as 1/h^k.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry import NurbsCurve

NOISE_SHARE = 0.1
TURN_SAMPLES = 9  # tangents sampled over a stencil to bound how far the path turns in it


def stencils(t_s: np.ndarray, order: int, baseline_s: float) -> np.ndarray:
    """Node indices (S, order+1): from each point, the first points at or after t + q h."""
    starts = np.arange(t_s.size)
    cols = [starts] + [np.searchsorted(t_s, t_s + q * baseline_s * (1.0 - 1e-9), side="left")
                       for q in range(1, order + 1)]
    idx = np.stack(cols, axis=1)
    ok = (idx[:, -1] < t_s.size) & np.all(np.diff(idx, axis=1) > 0, axis=1)
    return idx[ok]


def divided_difference_weights(t_s: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Weights (S, k+1) of k! f[t_0..t_k] at the stencils idx (S, k+1)."""
    k = idx.shape[1] - 1
    t = t_s[idx]
    gap = t[:, :, None] - t[:, None, :]
    diag = np.arange(k + 1)
    gap[:, diag, diag] = 1.0
    return math.factorial(k) / np.prod(gap, axis=2)


def derivative_estimate(t_s: np.ndarray, s_mm: np.ndarray, e_mm: np.ndarray,
                        idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """k! f[t_0..t_k] of a scalar at the stencils idx (S, k+1), and its noise bound k! sum |w| e."""
    w = divided_difference_weights(t_s, idx)
    return np.sum(w * s_mm[idx], axis=1), np.sum(np.abs(w) * e_mm[idx], axis=1)


def acceleration_xyz(t_s: np.ndarray, p_mm: np.ndarray, r_mm: float,
                     idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """2 f[t_0, t_1, t_2] of positions p (N, 3) at the stencils idx (S, 3): (S, 3), and its noise
    bound 2 r sum |w| (S,) for points each at most r (a length) from the true ones."""
    w = divided_difference_weights(t_s, idx)
    return np.einsum("sq,sqc->sc", w, p_mm[idx]), r_mm * np.sum(np.abs(w), axis=1)


def baseline_s(period_s: float, order: int, noise_mm: float, limit: float) -> float:
    """Smallest multiple of T whose evenly spaced k-th difference noise (4 e / h^2 for k = 2,
    8 e / h^3 for k = 3) stays under NOISE_SHARE of the limit."""
    gain = {2: 4.0, 3: 8.0}[order]
    h = (gain * noise_mm / (NOISE_SHARE * limit)) ** (1.0 / order)
    return period_s * max(1, math.ceil(h / period_s - 1e-9))


def unit_tangents(curve: NurbsCurve, u: np.ndarray) -> np.ndarray:
    """C'(u)/|C'(u)|: (N,) -> (N, 3); NaN where C'(u) = 0 (no tangent of its own there)."""
    _, c1, _ = curve.derivatives(np.asarray(u, dtype=float).ravel())
    norm = np.linalg.norm(c1, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(norm[:, None] > 0.0, c1 / norm[:, None], np.nan).reshape(
            np.shape(u) + (3,))


def turning_rad(curve: NurbsCurve, u_lo: np.ndarray, u_mid: np.ndarray,
                u_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far the tangent turns away from its direction at u_mid over [u_lo, u_hi]: (S,) each.

    Returns the unit tangent at u_mid (S, 3) and the angle (S,): the largest angle between it
    and TURN_SAMPLES sampled tangents, plus the largest angle between neighbouring samples (a
    margin for the turning between them), at most pi. pi where the tangent at u_mid is undefined.
    """
    frac = np.linspace(0.0, 1.0, TURN_SAMPLES)
    lo, hi = np.minimum(u_lo, u_hi), np.maximum(u_lo, u_hi)
    tan = unit_tangents(curve, lo[:, None] + (hi - lo)[:, None] * frac[None, :])
    mid = unit_tangents(curve, u_mid)

    def angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0))

    with np.errstate(invalid="ignore"):
        away = angle(tan, mid[:, None, :])
        steps = angle(tan[:, 1:], tan[:, :-1])
    away = np.where(np.isnan(away), 0.0, away)
    steps = np.where(np.isnan(steps), 0.0, steps)
    theta = np.minimum(np.pi, away.max(axis=1) + steps.max(axis=1))
    return mid, np.where(np.isnan(mid[:, 0]), np.pi, theta)
