r"""Jerk-limited speed transitions (paper Eq. 17-20, errata in design §2), the bidirectional scan
(Eq. 22) and segment peak speeds. Scalar functions in numba's subset (see nurbsfeed.jit).

A transition changes speed by dv with zero acceleration at both ends:

      a                                   a
      |   ____                            |  /\
      |  /    \         dv > A^2/J        | /  \        dv <= A^2/J
      |_/______\___ t                     |/____\___ t
        T1  T2  T1                         T1  T1
  T1 = A/J, T2 = dv/A - A/J               T1 = sqrt(dv/J)

The profile is point-symmetric about its middle, so its distance is exactly
(v_start + v_end)/2 * duration; this replaces the printed Eq. 20.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit

SPEED_REL_TOL = 1e-12  # relative precision of the bisections on speeds
MAX_BISECTIONS = 200


@jit
def _cbrt(x: float) -> float:
    return math.copysign(abs(x) ** (1.0 / 3.0), x)


@jit
def transition_time_s(dv_mm_s: float, acc_mm_s2: float, jerk_mm_s3: float) -> float:
    """Duration of a transition by |dv| (Eq. 17)."""
    dv = abs(dv_mm_s)
    if dv <= acc_mm_s2 * acc_mm_s2 / jerk_mm_s3:
        return 2.0 * math.sqrt(dv / jerk_mm_s3)
    return dv / acc_mm_s2 + acc_mm_s2 / jerk_mm_s3


@jit
def transition_distance_mm(v0_mm_s: float, v1_mm_s: float, acc_mm_s2: float,
                           jerk_mm_s3: float) -> float:
    """Distance of the transition v0 -> v1: (v0 + v1)/2 * duration."""
    return 0.5 * (v0_mm_s + v1_mm_s) * transition_time_s(v1_mm_s - v0_mm_s, acc_mm_s2,
                                                         jerk_mm_s3)


@jit
def reachable_speed(v0_mm_s: float, length_mm: float, acc_mm_s2: float, jerk_mm_s3: float,
                    cap_mm_s: float) -> float:
    """Highest v in [v0, cap] with transition_distance(v0, v) <= length (the scan of Eq. 22).

    Closed form: with x = sqrt(dv), the jerk-only branch is x^3 + 2 v0 x - L sqrt(J) = 0 (one real
    root, Cardano); past dv = A^2/J the quadratic branch
    dv^2/(2A) + dv (v0/A + A/(2J)) + v0 A/J - L = 0. The root is proposed, then verified against
    transition_distance and nudged down by bisection if rounding put it past the length.
    """
    if cap_mm_s <= v0_mm_s:
        return cap_mm_s
    a = acc_mm_s2
    j = jerk_mm_s3
    if transition_distance_mm(v0_mm_s, cap_mm_s, a, j) <= length_mm:
        return cap_mm_s
    q = -length_mm * math.sqrt(j)
    p = 2.0 * v0_mm_s
    disc = math.sqrt(q * q / 4.0 + p * p * p / 27.0)
    # Cardano with the second cube root as -p/(3C): cbrt(a) cbrt(b) = -p/3, no cancellation
    c = _cbrt(-q / 2.0 + disc)
    x = c - p / (3.0 * c) if c != 0.0 else 0.0
    dv = x * x
    if dv > a * a / j:
        qa = 1.0 / (2.0 * a)
        qb = v0_mm_s / a + a / (2.0 * j)
        qc = v0_mm_s * a / j - length_mm
        dv = -2.0 * qc / (qb + math.sqrt(qb * qb - 4.0 * qa * qc))
    v = min(v0_mm_s + max(dv, 0.0), cap_mm_s)
    if transition_distance_mm(v0_mm_s, v, a, j) <= length_mm:
        return v
    low = v0_mm_s
    high = v
    for _ in range(MAX_BISECTIONS):
        if high - low <= SPEED_REL_TOL * high:
            break
        mid = 0.5 * (low + high)
        if transition_distance_mm(v0_mm_s, mid, a, j) <= length_mm:
            low = mid
        else:
            high = mid
    return low


@jit
def peak_speed(v_start: float, v_end: float, length_mm: float, cap_mm_s: float,
               acc_mm_s2: float, jerk_mm_s3: float) -> float:
    """The highest v_p in [max(v_s, v_e), cap] whose accel + decel fit the segment length.

    Requires transition_distance(v_s, v_e) <= length (the scan ensures it), so the lower end of
    the bracket always fits; the bisection keeps the invariant that `low` fits.
    """
    low = max(v_start, v_end)
    high = max(cap_mm_s, low)
    if (transition_distance_mm(v_start, high, acc_mm_s2, jerk_mm_s3)
            + transition_distance_mm(high, v_end, acc_mm_s2, jerk_mm_s3)) <= length_mm:
        return high
    for _ in range(MAX_BISECTIONS):
        if high - low <= SPEED_REL_TOL * high:
            break
        mid = 0.5 * (low + high)
        if (transition_distance_mm(v_start, mid, acc_mm_s2, jerk_mm_s3)
                + transition_distance_mm(mid, v_end, acc_mm_s2, jerk_mm_s3)) <= length_mm:
            low = mid
        else:
            high = mid
    return low


@jit
def scan_speeds(nominal: np.ndarray, length_mm: np.ndarray, cap_mm_s: np.ndarray,
                acc_mm_s2: float, jerk_mm_s3: float) -> np.ndarray:
    """Eq. 22: (K,), (K-1,), (K-1,) -> (K,) key speeds.

    Backward pass from the end: each key speed is lowered until the next key is reachable by
    deceleration within the segment. Forward pass from the start: the next key is lowered until
    it is reachable by acceleration. Both passes also respect the caps of the adjacent segments.
    """
    k = nominal.size
    v = nominal.copy()
    for i in range(k - 1):
        v[i] = min(v[i], cap_mm_s[i])
        v[i + 1] = min(v[i + 1], cap_mm_s[i])
    for i in range(k - 2, -1, -1):
        v[i] = min(v[i], reachable_speed(v[i + 1], length_mm[i], acc_mm_s2, jerk_mm_s3, v[i]))
    for i in range(k - 1):
        v[i + 1] = min(v[i + 1], reachable_speed(v[i], length_mm[i], acc_mm_s2, jerk_mm_s3,
                                                 v[i + 1]))
    return v


@jit
def segment_profiles(v_key: np.ndarray, length_mm: np.ndarray, cap_mm_s: np.ndarray,
                     acc_mm_s2: float, jerk_mm_s3: float):
    """Per segment: peak speed, accel distance and decel distance: three (K-1,) arrays."""
    n = length_mm.size
    peak = np.empty(n)
    d_up = np.empty(n)
    d_down = np.empty(n)
    for i in range(n):
        vp = peak_speed(v_key[i], v_key[i + 1], length_mm[i], cap_mm_s[i], acc_mm_s2,
                        jerk_mm_s3)
        peak[i] = vp
        d_up[i] = transition_distance_mm(v_key[i], vp, acc_mm_s2, jerk_mm_s3)
        d_down[i] = transition_distance_mm(vp, v_key[i + 1], acc_mm_s2, jerk_mm_s3)
    return peak, d_up, d_down


@jit
def transition_phases(v0_mm_s: float, v1_mm_s: float, acc_mm_s2: float, jerk_mm_s3: float,
                      durations: np.ndarray, jerks: np.ndarray) -> int:
    """Constant-jerk phases taking v0 to v1 (Eq. 17-18), written to durations/jerks (>= 3);
    returns how many (0, 2 or 3)."""
    dv = v1_mm_s - v0_mm_s
    if dv == 0.0:
        return 0
    sign = 1.0 if dv > 0 else -1.0
    dv = abs(dv)
    j = jerk_mm_s3
    if dv <= acc_mm_s2 * acc_mm_s2 / j:
        t1 = math.sqrt(dv / j)
        durations[0] = t1
        jerks[0] = sign * j
        durations[1] = t1
        jerks[1] = -sign * j
        return 2
    t1 = acc_mm_s2 / j
    durations[0] = t1
    jerks[0] = sign * j
    durations[1] = dv / acc_mm_s2 - t1
    jerks[1] = 0.0
    durations[2] = t1
    jerks[2] = -sign * j
    return 3
