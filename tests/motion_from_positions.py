"""The motion the machine feels, measured from positions one period apart (tests and benches).

tests/motion_check gives speed and acceleration; this adds the jerk vector, split along the
path, and the motion of each axis. Along C(s) at speed v, tangential acceleration a and jerk j
(T, N, B the Frenet frame here, T the period below):

    velocity     = v T
    acceleration = a T + kappa v^2 N
    jerk         = (j - kappa^2 v^3) T + (3 kappa v a + kappa' v^3) N + kappa tau v^3 B

so the jerk the machine feels along the path is the time law's j minus kappa^2 v^3, and across
it (N and B together) more than the proxy v^3 kappa^2 the planner limits. Nothing of the planner
is used: the points P_k are positions at t_k = k T, and

    velocity     (P_k+1 - P_k) / T                          at t_k+1/2
    acceleration (P_k+1 - 2 P_k + P_k-1) / T^2              at t_k
    jerk         (P_k+2 - 3 P_k+1 + 3 P_k - P_k-1) / T^3    at t_k+1/2

each split by the unit chord across the same points (P_k+1 - P_k-1 for acceleration, P_k+1 - P_k
for jerk), the direction of the mean velocity there.

Finite-difference error: each n-th divided difference is the mean of the true n-th derivative
under a positive B-spline weight n periods wide, so it never exceeds the motion's own peak (the
law's jerk steps are averaged, not overshot) and at its centre it is P^(n) + c T^2 P^(n+2) with
c = 1/24, 1/12, 1/8 for n = 1, 2, 3; on uniform circular motion at angular rate w it is exactly
P^(n) sinc(wT/2)^n in norm, within n (wT)^2 / 24 of it. The chord P_k+1 - P_k is T times the
velocity at t_k+1/2 plus T^3 P''' / 24, so the split turns by up to T^2 |P'''| / (24 v) rad and
shifts up to |D| T^2 |P'''| / (24 v) of a difference D between its parts along and across.
Position rounding e adds up to 2^n e / T^n: 0.008 mm/s^3 of jerk per femtometre at T = 1 ms,
which is why positions must be full precision (rounding to a 0.1 um output grid alone could
read as 400,000 mm/s^3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tests.motion_check import Motion, motion


@dataclass(frozen=True)
class PathMotion:
    path: Motion  # speed, |tangential acc|, normal acc (tests/motion_check)
    tangential_jerk_mm_s3: np.ndarray  # (N-3,) signed, along the direction of travel
    normal_jerk_mm_s3: np.ndarray  # (N-3,) norm of the part across the path (N and B)
    jerk_mm_s3: np.ndarray  # (N-3, 3) the jerk vector
    axis_velocity_mm_s: np.ndarray  # (N-1, 3)
    axis_acc_mm_s2: np.ndarray  # (N-2, 3)


def _unit(chord: np.ndarray) -> np.ndarray:
    """(M, 3) -> (M, 3); a zero chord (the tool not moving) gives a zero tangent, and everything
    at that place counts as across the path."""
    norm = np.linalg.norm(chord, axis=1)
    return np.divide(chord, norm[:, None], out=np.zeros_like(chord), where=norm[:, None] > 0)


def path_motion(points: np.ndarray, period_s: float) -> PathMotion:
    """points (N, 3) one period apart, N >= 4 -> the motion from their divided differences."""
    step = np.diff(points, axis=0)
    acc = np.diff(step, axis=0) / period_s**2
    jerk = np.diff(step, n=2, axis=0) / period_s**3
    tangent = _unit(step[1:-1])
    along = np.einsum("ij,ij->i", jerk, tangent)
    across = np.linalg.norm(jerk - along[:, None] * tangent, axis=1)
    return PathMotion(motion(points, period_s), along, across, jerk, step / period_s, acc)
