r"""Jerk-limited speed transitions (paper Eq. 17-20, errata in SPEC §2) and segment peak speeds.

A transition changes speed by dv with zero acceleration at both ends:

      a                                   a
      |   ____                            |  /\
      |  /    \         dv > A^2/J        | /  \        dv <= A^2/J
      |_/______\___ t                     |/____\___ t
        T1  T2  T1                         T1  T1
  T1 = A/J, T2 = dv/A - A/J               T1 = sqrt(dv/J)

The profile is point-symmetric about its middle, so its distance is exactly
(v_start + v_end)/2 * duration; this replaces the printed Eq. 20.
Functions accept scalars or arrays (vectorised over segments).
"""

from __future__ import annotations

import numpy as np

SPEED_REL_TOL = 1e-12  # relative precision of the bisection on speeds


def transition_time_s(dv_mm_s, acc_mm_s2: float, jerk_mm_s3: float):
    """Duration of a transition by |dv| (Eq. 17)."""
    dv = np.abs(dv_mm_s)
    return np.where(dv <= acc_mm_s2**2 / jerk_mm_s3, 2.0 * np.sqrt(dv / jerk_mm_s3),
                    dv / acc_mm_s2 + acc_mm_s2 / jerk_mm_s3)


def transition_distance_mm(v0_mm_s, v1_mm_s, acc_mm_s2: float, jerk_mm_s3: float):
    """Distance of the transition v0 -> v1: (v0 + v1)/2 * duration."""
    return 0.5 * (v0_mm_s + v1_mm_s) * transition_time_s(v1_mm_s - v0_mm_s, acc_mm_s2,
                                                         jerk_mm_s3)


def reachable_speed(v0_mm_s: float, length_mm: float, acc_mm_s2: float, jerk_mm_s3: float,
                    cap_mm_s: float) -> float:
    """Highest v <= cap with transition_distance(v0, v) <= length (the scan of Eq. 22).

    Closed form: with x = sqrt(dv), the jerk-only branch is x^3 + 2 v0 x - L sqrt(J) = 0 (one real
    root, Cardano); past dv = A^2/J the quadratic branch
    dv^2/(2A) + dv (v0/A + A/(2J)) + v0 A/J - L = 0. The root is proposed, then verified against
    transition_distance and nudged down by bisection if rounding put it past the length.
    """
    if transition_distance_mm(v0_mm_s, cap_mm_s, acc_mm_s2, jerk_mm_s3) <= length_mm:
        return cap_mm_s
    a, j = acc_mm_s2, jerk_mm_s3
    q = -length_mm * np.sqrt(j)
    p = 2.0 * v0_mm_s
    disc = np.sqrt(q * q / 4.0 + p**3 / 27.0)
    x = np.cbrt(-q / 2.0 + disc) + np.cbrt(-q / 2.0 - disc)
    dv = x * x
    if dv > a * a / j:
        qa = 1.0 / (2.0 * a)
        qb = v0_mm_s / a + a / (2.0 * j)
        qc = v0_mm_s * a / j - length_mm
        dv = 2.0 * -qc / (qb + np.sqrt(qb * qb - 4.0 * qa * qc))
    v = min(v0_mm_s + max(dv, 0.0), cap_mm_s)
    if transition_distance_mm(v0_mm_s, v, a, j) <= length_mm:
        return float(v)
    low, high = v0_mm_s, v
    while high - low > SPEED_REL_TOL * max(high, 1e-300):
        mid = 0.5 * (low + high)
        if transition_distance_mm(v0_mm_s, mid, a, j) <= length_mm:
            low = mid
        else:
            high = mid
    return float(low)


def peak_speeds(v_start: np.ndarray, v_end: np.ndarray, length_mm: np.ndarray,
                cap_mm_s: np.ndarray, acc_mm_s2: float, jerk_mm_s3: float) -> np.ndarray:
    """Per segment the highest v_p in [max(v_s, v_e), cap] whose accel + decel fit the length.

    (K,) arrays -> (K,). Requires transition_distance(v_s, v_e) <= length (the scan ensures it),
    so the lower end of the bracket always fits; bisection keeps the invariant that `low` fits.
    """
    def need(vp: np.ndarray) -> np.ndarray:
        return (transition_distance_mm(v_start, vp, acc_mm_s2, jerk_mm_s3)
                + transition_distance_mm(vp, v_end, acc_mm_s2, jerk_mm_s3))

    low = np.maximum(v_start, v_end)
    high = np.maximum(cap_mm_s, low)
    fits_cap = need(high) <= length_mm
    for _ in range(200):
        open_ = high - low > SPEED_REL_TOL * np.maximum(high, 1e-300)
        if not np.any(open_ & ~fits_cap):
            break
        mid = 0.5 * (low + high)
        ok = need(mid) <= length_mm
        low = np.where(ok, mid, low)
        high = np.where(ok, high, mid)
    return np.where(fits_cap, high, low)


def transition_phases(v0_mm_s: float, v1_mm_s: float, acc_mm_s2: float,
                      jerk_mm_s3: float) -> list[tuple[float, float]]:
    """Constant-jerk phases [(duration_s, jerk_mm_s3)] taking v0 to v1 (Eq. 17-18)."""
    dv = v1_mm_s - v0_mm_s
    if dv == 0.0:
        return []
    sign = 1.0 if dv > 0 else -1.0
    dv = abs(dv)
    j = jerk_mm_s3
    if dv <= acc_mm_s2**2 / j:
        t1 = float(np.sqrt(dv / j))
        return [(t1, sign * j), (t1, -sign * j)]
    t1 = acc_mm_s2 / j
    t2 = dv / acc_mm_s2 - t1
    return [(t1, sign * j), (t2, 0.0), (t1, -sign * j)]
