"""Independent measurement of an interpolation against its limits (used by several tests).

Curvature comes from the vectorised evaluator (itself checked against the textbook oracle);
the speed limit from tests/naive_nurbs.chord_speed_limit, written in rho as the paper does;
chord error from sampling the true curve between consecutive parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.nurbs import curvature_from_derivatives
from nurbsfeed.interpolate.stepping import Interpolation
from nurbsfeed.planning.limits import Limits
from tests.naive_nurbs import chord_speed_limit

CHORD_SAMPLES = 9


@dataclass
class Measured:
    v_over_limit: float  # max v / pointwise limit
    normal_acc: float
    normal_jerk: float
    tangential_acc: float
    tangential_jerk: float
    chord_mm: float
    speed: float


def measure(curve: NurbsCurve, result: Interpolation, lim: Limits) -> Measured:
    _, c1, c2 = curve.derivatives(result.u)
    kappa = np.nan_to_num(curvature_from_derivatives(c1, c2), nan=0.0)
    v = result.v_mm_s
    limit = np.array([chord_speed_limit(k, lim.period_s, lim.chord_mm, lim.normal_acc_mm_s2,
                                        lim.normal_jerk_mm_s3, lim.feed_mm_s) for k in kappa])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(v > 0, v / limit, 0.0)
    # chord error: the farthest curve point between u_k and u_k+1 from the chord
    frac = np.linspace(0.0, 1.0, CHORD_SAMPLES + 2)[1:-1]
    u0, u1 = result.u[:-1], result.u[1:]
    inner = curve.point((u0[:, None] + (u1 - u0)[:, None] * frac[None, :]).ravel())
    inner = inner.reshape(len(u0), CHORD_SAMPLES, 3)
    a, b = result.points[:-1], result.points[1:]
    ab = b - a
    length = np.linalg.norm(ab, axis=1)
    safe = np.where(length > 0, length, 1.0)
    dist = np.linalg.norm(np.cross(inner - a[:, None, :], ab[:, None, :]), axis=2) / safe[:, None]
    return Measured(float(np.max(ratio)), float(np.max(v**2 * kappa)),
                    float(np.max(v**3 * kappa**2)), float(np.max(np.abs(result.a_mm_s2))),
                    float(np.max(np.abs(result.j_mm_s3))), float(np.max(dist)), float(v.max()))


def assert_within(curve: NurbsCurve, result: Interpolation, lim: Limits,
                  rel: float = 1e-6) -> Measured:
    m = measure(curve, result, lim)
    assert m.v_over_limit <= 1 + rel, m
    assert m.speed <= lim.feed_mm_s * (1 + rel), m
    assert m.normal_acc <= lim.normal_acc_mm_s2 * (1 + rel), m
    assert m.normal_jerk <= lim.normal_jerk_mm_s3 * (1 + rel), m
    assert m.tangential_acc <= lim.acc_mm_s2 * (1 + rel), m
    assert m.tangential_jerk <= lim.jerk_mm_s3 * (1 + rel), m
    assert m.chord_mm <= lim.chord_mm * (1 + rel), m
    return m
