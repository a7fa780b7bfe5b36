"""The pointwise speed limit of a curve point (paper Eq. 15, corrected) and the curvature threshold
(Eq. 16).

Names: kappa_1_mm curvature, v_mm_s speed, in mm and seconds.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from nurbsfeed.jit import jit


@dataclass(frozen=True)
class Limits:
    """The kinematic limits of a machine (`machine.Machine.limits`, from the profile's keys
    max_feed_mm_s ...), in mm and seconds. A curve with a programmed feed is planned under
    `dataclasses.replace(limits, feed_mm_s=min(limits.feed_mm_s, programmed))`."""

    period_s: float
    feed_mm_s: float  # v_m: min(machine max feed, programmed feed)
    chord_mm: float  # delta
    acc_mm_s2: float  # A_t
    jerk_mm_s3: float  # J_t
    normal_acc_mm_s2: float  # A_n
    normal_jerk_mm_s3: float  # J_n
    # "paper": the normal jerk is the proxy v^3 kappa^2 of Eq. 15 and the tangential jerk the
    # law's j; "path": the jerk vector the machine feels, and the per-axis limits (design §2b)
    jerk_model: str = "paper"
    axis_vel_mm_s: tuple[float, float, float] = (math.inf, math.inf, math.inf)  # X, Y, Z
    axis_acc_mm_s2: tuple[float, float, float] = (math.inf, math.inf, math.inf)
    axis_jerk_mm_s3: tuple[float, float, float] = (math.inf, math.inf, math.inf)
    # "scurve": the paper's key points and S-curves; "optimal": planning.path_plan's
    # controllable sets (path model)
    planner: str = "scurve"


def curvature_threshold(lim: Limits) -> float:
    """kappa_0 (Eq. 16): above it the pointwise limit of Eq. 15 is below v_m.

    min(8 delta / (v_m^2 T^2 + 4 delta^2), A_n / v_m^2, sqrt(J_n / v_m^3)).
    """
    v, t, d = lim.feed_mm_s, lim.period_s, lim.chord_mm
    return float(min(8.0 * d / (v * v * t * t + 4.0 * d * d), lim.normal_acc_mm_s2 / v**2,
                     np.sqrt(lim.normal_jerk_mm_s3 / v**3)))


# a profile's limits as one array (`limit_values`), in this order, for the compiled kernels
(L_PERIOD, L_FEED, L_CHORD, L_ACC, L_JERK, L_NORMAL_ACC, L_NORMAL_JERK, L_AXIS_VEL, L_AXIS_ACC,
 L_AXIS_JERK) = (0, 1, 2, 3, 4, 5, 6, 7, 10, 13)  # the axes' X, Y, Z from each L_AXIS_...


@functools.lru_cache(maxsize=64)
def limit_values(lim: Limits) -> np.ndarray:
    """lim's numbers (16,), read-only, in the order of the L_ indices: what the kernels read,
    one array instead of a dozen arguments (a curve's limits are equal Limits objects each
    time, so this is made once per profile and feed)."""
    out = np.array([lim.period_s, lim.feed_mm_s, lim.chord_mm, lim.acc_mm_s2, lim.jerk_mm_s3,
                    lim.normal_acc_mm_s2, lim.normal_jerk_mm_s3, *lim.axis_vel_mm_s,
                    *lim.axis_acc_mm_s2, *lim.axis_jerk_mm_s3], dtype=float)
    out.setflags(write=False)
    return out


@jit
def least(r, x):
    """The smaller of r and x, NaN if either is (as np.minimum)."""
    return x if (x < r or x != x) else r


@jit
def most(r, x):
    """The larger of r and x, NaN if either is (as np.maximum)."""
    return x if (x > r or x != x) else r


@jit
def chord_acc_limit(k, period_s, chord_mm, normal_acc_mm_s2):
    """The chord and normal acceleration terms of `speed_limit` at one kappa k, as it computes
    them: inf where k is not above 0."""
    if not k > 0.0:
        return math.inf
    if k * chord_mm < 1.0:
        chord = (2.0 / period_s) * math.sqrt(chord_mm * (2.0 - k * chord_mm) / k)
    else:
        chord = 2.0 / (k * period_s)
    return least(chord, math.sqrt(normal_acc_mm_s2 / k))


def speed_limit(kappa_1_mm: np.ndarray, lim: Limits, feed_mm_s: np.ndarray | float) -> np.ndarray:
    """Pointwise limit v(kappa) (Eq. 15 with the sign of Eq. 14 corrected): (N,) -> (N,).

    min(v_m, (2/T) sqrt(2 rho delta - delta^2), sqrt(A_n rho), cbrt(J_n rho^2)) with rho = 1/kappa
    (the last under the paper's jerk model only).
    The chord term saturates at 2 rho / T once delta >= rho (the chord is then a diameter).
    Written in kappa so that kappa = 0 gives the feed cap without dividing by zero. (The
    compiled `chord_acc_limit` computes its first terms alike, operation for operation.)
    """
    k = np.asarray(kappa_1_mm, dtype=float)
    t, d = lim.period_s, lim.chord_mm
    with np.errstate(divide="ignore", invalid="ignore"):
        chord = np.where(k * d < 1.0, (2.0 / t) * np.sqrt(d * (2.0 - k * d) / k), 2.0 / (k * t))
        acc = np.sqrt(lim.normal_acc_mm_s2 / k)
        v = np.minimum(chord, acc)
        if lim.jerk_model == "paper":  # the path model's jerk limits: planning.path_model
            v = np.minimum(v, np.cbrt(lim.normal_jerk_mm_s3 / (k * k)))
    v = np.where(k > 0.0, v, np.inf)
    return np.minimum(v, np.minimum(lim.feed_mm_s, feed_mm_s))
