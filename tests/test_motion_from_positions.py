"""tests/motion_from_positions against motions whose derivatives are known in closed form.

Each case samples positions at t_k = k T and checks the measured quantities against the
continuous ones within the finite-difference error the module states (n (wT)^2 / 24 for the
n-th difference at angular rate w), and where the discrete values are themselves known exactly
(a sinusoid's differences scale by sinc(wT/2)^n, a cubic's third difference is exact) against
those to rounding.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import Polynomial

from tests.motion_from_positions import path_motion

PERIOD_S = 0.001
EPS = np.finfo(float).eps


def rounding(n: int, size_mm: float) -> float:
    """The most an n-th difference over T^n can gain from positions of size `size_mm` rounded
    to float: 2^n roundings of half an ulp each, and as much again for the rounding of what
    the positions were computed from (phases, cosines) and of the differences."""
    return 4.0 * 2.0**n * EPS * size_mm / PERIOD_S**n


def sinc_half(theta: float) -> float:
    """sin(theta/2) / (theta/2): the ratio of a sinusoid's first difference to its derivative."""
    return float(np.sin(theta / 2) / (theta / 2))


def circle(radius_mm: float, phase_rad: np.ndarray) -> np.ndarray:
    return radius_mm * np.column_stack([np.cos(phase_rad), np.sin(phase_rad),
                                        np.zeros_like(phase_rad)])


@pytest.mark.parametrize("radius_mm, speed_mm_s", [(5.0, 100.0), (0.5, 20.0), (40.0, 200.0)])
def test_uniform_circle_jerk_is_minus_kappa2_v3_along_the_path(radius_mm, speed_mm_s):
    omega = speed_mm_s / radius_mm
    theta = omega * PERIOD_S
    m = path_motion(circle(radius_mm, omega * PERIOD_S * np.arange(300)), PERIOD_S)
    v2_kappa = speed_mm_s**2 / radius_mm
    kappa2_v3 = speed_mm_s**3 / radius_mm**2
    # exactly the sinusoid's differences ...
    np.testing.assert_allclose(m.path.speed_mm_s, speed_mm_s * sinc_half(theta), rtol=0,
                               atol=rounding(1, radius_mm))
    np.testing.assert_allclose(m.path.normal_acc_mm_s2, v2_kappa * sinc_half(theta)**2, rtol=0,
                               atol=rounding(2, radius_mm))
    np.testing.assert_allclose(m.tangential_jerk_mm_s3, -kappa2_v3 * sinc_half(theta)**3,
                               rtol=0, atol=rounding(3, radius_mm))
    assert np.abs(m.path.tangential_acc_mm_s2).max() < rounding(2, radius_mm)
    assert m.normal_jerk_mm_s3.max() < rounding(3, radius_mm)
    # ... which fall short of the continuous ones by n theta^2 / 24, neither more nor much less
    for n, measured, exact in ((1, m.path.speed_mm_s, speed_mm_s),
                               (2, m.path.normal_acc_mm_s2, v2_kappa),
                               (3, -m.tangential_jerk_mm_s3, kappa2_v3)):
        shortfall = 1.0 - measured / exact
        bound = n * theta**2 / 24
        slack = rounding(n, radius_mm) / exact
        assert np.all(shortfall <= bound + slack), (n, shortfall)
        assert np.all(shortfall >= 0.99 * bound - slack), (n, shortfall)


def test_straight_line_with_cubic_law_has_jerk_6_c3_along_the_line():
    direction = np.array([2.0, -1.0, 0.5]) / np.linalg.norm([2.0, -1.0, 0.5])
    c1, c2, c3 = 50.0, 100.0, 1000.0  # s = c1 t + c2 t^2 + c3 t^3, v > 0 throughout
    t = PERIOD_S * np.arange(100)
    s = c1 * t + c2 * t**2 + c3 * t**3
    points = 1.5 + s[:, None] * direction[None, :]
    size_mm = np.abs(points).max()
    m = path_motion(points, PERIOD_S)
    mid = t[1:] - PERIOD_S / 2
    # a cubic's second and third differences are exact; the first is s'(mid) + c3 T^2 / 4
    np.testing.assert_allclose(m.tangential_jerk_mm_s3, 6 * c3, rtol=0,
                               atol=rounding(3, size_mm))
    np.testing.assert_allclose(m.jerk_mm_s3, np.tile(6 * c3 * direction, (t.size - 3, 1)),
                               rtol=0, atol=rounding(3, size_mm))
    assert m.normal_jerk_mm_s3.max() < rounding(3, size_mm)
    np.testing.assert_allclose(m.path.tangential_acc_mm_s2, 2 * c2 + 6 * c3 * t[1:-1], rtol=0,
                               atol=rounding(2, size_mm))
    assert m.path.normal_acc_mm_s2.max() < rounding(2, size_mm)
    speed = c1 + 2 * c2 * mid + 3 * c3 * mid**2
    np.testing.assert_allclose(m.path.speed_mm_s, speed + c3 * PERIOD_S**2 / 4, rtol=0,
                               atol=rounding(1, size_mm))
    assert np.all(m.path.speed_mm_s - speed > c3 * PERIOD_S**2 / 8)  # the stated error is there
    np.testing.assert_allclose(m.axis_velocity_mm_s,
                               m.path.speed_mm_s[:, None] * direction[None, :], rtol=0,
                               atol=rounding(1, size_mm))
    np.testing.assert_allclose(m.axis_acc_mm_s2,
                               (2 * c2 + 6 * c3 * t[1:-1])[:, None] * direction[None, :],
                               rtol=0, atol=rounding(2, size_mm))


def circle_derivative(radius_mm: float, phase_rad: Polynomial, n: int,
                      t_s: np.ndarray) -> np.ndarray:
    """The n-th time derivative of R exp(i phase(t)) (a point on a circle, x + iy), from
    d/dt (q exp(i phase)) = (q' + i phase' q) exp(i phase): (M,) -> (M,) complex."""
    factor = Polynomial([1.0 + 0j])
    for _ in range(n):
        factor = factor.deriv() + 1j * phase_rad.deriv() * factor
    return radius_mm * factor(t_s) * np.exp(1j * phase_rad(t_s))


def split_error(p3: np.ndarray, p5: np.ndarray, speed_mm_s: np.ndarray) -> float:
    """The module's bound on a jerk component: T^2 |P^(5)| / 8 for the difference, and the
    chord's turn T^2 |P'''| / (24 v) times |P'''| for the split."""
    return float(PERIOD_S**2 * (np.abs(p5).max() / 8
                                + np.abs(p3).max()**2 / (24 * speed_mm_s.min())))


def test_helix_jerk_across_the_path_is_kappa_tau_v3():
    radius_mm, pitch_mm, omega = 4.0, 3.0, 25.0  # z rises pitch_mm per turn
    rise_mm = pitch_mm / (2 * np.pi)  # z = rise_mm * phase
    kappa = radius_mm / (radius_mm**2 + rise_mm**2)
    tau = rise_mm / (radius_mm**2 + rise_mm**2)
    speed = omega * np.hypot(radius_mm, rise_mm)
    t = PERIOD_S * np.arange(400)
    points = circle(radius_mm, omega * t)
    points[:, 2] = rise_mm * omega * t
    size_mm = np.abs(points).max()
    m = path_motion(points, PERIOD_S)
    phase = Polynomial([0.0, omega])
    error = split_error(circle_derivative(radius_mm, phase, 3, t),
                        circle_derivative(radius_mm, phase, 5, t), np.array([speed]))
    # uniform speed: no 3 kappa v a term, kappa' = 0: only -kappa^2 v^3 T and kappa tau v^3 B
    np.testing.assert_allclose(m.normal_jerk_mm_s3, kappa * tau * speed**3, rtol=0, atol=error)
    np.testing.assert_allclose(m.tangential_jerk_mm_s3, -kappa**2 * speed**3, rtol=0, atol=error)
    np.testing.assert_allclose(m.path.normal_acc_mm_s2, kappa * speed**2,
                               rtol=2 * (omega * PERIOD_S)**2 / 24)
    np.testing.assert_allclose(m.axis_velocity_mm_s[:, 2], rise_mm * omega, rtol=0,
                               atol=rounding(1, size_mm))
    assert np.abs(m.jerk_mm_s3[:, 2]).max() < rounding(3, size_mm)
    # the torsion term is what the proxy v^3 kappa^2 misses: here it is not small
    assert kappa * tau * speed**3 > 10 * error


def test_accelerating_on_a_circle_adds_3_kappa_v_a_across_the_path():
    radius_mm = 5.0
    v0, a0, j0 = 20.0, 400.0, 3000.0  # s = v0 t + a0 t^2 / 2 + j0 t^3 / 6
    t = PERIOD_S * np.arange(150)
    phase = Polynomial([0.0, v0, a0 / 2, j0 / 6]) / radius_mm
    m = path_motion(circle(radius_mm, phase(t)), PERIOD_S)
    mid = t[1:-2] + PERIOD_S / 2
    v, a = v0 + a0 * mid + j0 * mid**2 / 2, a0 + j0 * mid
    kappa = 1.0 / radius_mm
    p5 = circle_derivative(radius_mm, phase, 5, t)
    error = split_error(circle_derivative(radius_mm, phase, 3, t), p5, v)
    np.testing.assert_allclose(m.normal_jerk_mm_s3, 3 * kappa * v * a, rtol=0, atol=error)
    np.testing.assert_allclose(m.tangential_jerk_mm_s3, j0 - kappa**2 * v**3, rtol=0, atol=error)
    # the vector itself against its closed form at the centres, within T^2 |P^(5)| / 8
    exact = circle_derivative(radius_mm, phase, 3, mid)
    np.testing.assert_allclose(m.jerk_mm_s3[:, 0] + 1j * m.jerk_mm_s3[:, 1], exact, rtol=0,
                               atol=PERIOD_S**2 / 8 * np.abs(p5).max())


def test_zero_chord_counts_the_jerk_as_across_the_path():
    """At a point where the tool stands for a period the direction of travel is unknown."""
    s = np.array([0.0, 0.0, 0.0, 1e-6, 4e-6])
    m = path_motion(np.column_stack([s, np.zeros_like(s), np.zeros_like(s)]), PERIOD_S)
    assert m.tangential_jerk_mm_s3[0] == 0.0
    assert m.normal_jerk_mm_s3[0] == pytest.approx(1e-6 / PERIOD_S**3)
    assert m.tangential_jerk_mm_s3[1] == pytest.approx(1e-6 / PERIOD_S**3)
