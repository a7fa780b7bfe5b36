"""A textbook NURBS evaluator that lives only in the tests: the oracle for nurbsfeed.geometry.

Cox-de Boor recursion straight from the definition (paper Eq. 2) with the 0/0 := 0 convention,
derivatives of the basis from
N'_{i,p} = p/(u_{i+p}-u_i) N_{i,p-1} - p/(u_{i+p+1}-u_{i+1}) N_{i+1,p-1},
and the quotient rule for the rational curve. Slow and obviously right.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np


def _ratio(num: float, den: float) -> float:
    return 0.0 if den == 0.0 else num / den


def basis(i: int, p: int, u: float | np.ndarray, knots: np.ndarray) -> float | np.ndarray:
    """N_{i,p}(u); for an array of u, elementwise (the same operations, the same values)."""
    if p == 0:
        last = knots[-1]
        if isinstance(u, np.ndarray):
            return 1.0 * ((knots[i] <= u) & (u < knots[i + 1])
                          | (u == last) & (knots[i] < knots[i + 1] == last))
        if knots[i] <= u < knots[i + 1]:
            return 1.0
        # the right end belongs to the last non-empty span
        if u == last and knots[i] < knots[i + 1] == last:
            return 1.0
        return 0.0
    return (_ratio(u - knots[i], knots[i + p] - knots[i]) * basis(i, p - 1, u, knots)
            + _ratio(knots[i + p + 1] - u, knots[i + p + 1] - knots[i + 1])
            * basis(i + 1, p - 1, u, knots))


def basis_derivative(i: int, p: int, u: float, knots: np.ndarray, order: int) -> float:
    if order == 0:
        return basis(i, p, u, knots)
    if order > p:
        return 0.0
    return p * (_ratio(1.0, knots[i + p] - knots[i]) * basis_derivative(i, p - 1, u, knots,
                                                                          order - 1)
                - _ratio(1.0, knots[i + p + 1] - knots[i + 1])
                * basis_derivative(i + 1, p - 1, u, knots, order - 1))


def evaluate(degree: int, knots, points, weights, u: float):
    """C(u), C'(u), C''(u) as three (3,) arrays."""
    knots = np.asarray(knots, float)
    pts = np.asarray(points, float)
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    w = np.asarray(weights, float)
    a = [np.zeros(3) for _ in range(3)]
    wd = [0.0, 0.0, 0.0]
    for i in range(len(pts)):
        if not knots[i] <= u <= knots[i + degree + 1]:
            continue  # N_i,p and its derivatives vanish outside [u_i, u_i+p+1] (local support)
        for order in range(3):
            n = basis_derivative(i, degree, u, knots, order)
            a[order] = a[order] + n * w[i] * pts[i]
            wd[order] += n * w[i]
    c0 = a[0] / wd[0]
    c1 = (a[1] - wd[1] * c0) / wd[0]
    c2 = (a[2] - 2.0 * wd[1] * c1 - wd[2] * c0) / wd[0]
    return c0, c1, c2


def exact_evaluate(degree: int, knots, points, weights, u: float | Fraction) -> np.ndarray:
    """C, C', C'' at u (derivatives in the input's own u) as a (3, 3) array, computed exactly in
    rational arithmetic from the given doubles and rounded once at the end: Cox-de Boor in
    `fractions.Fraction`, the right end in the last span. The reference at the input envelope's
    edges, where the float evaluator above would itself lose digits."""
    k = [Fraction(float(x)) for x in knots]
    uf = u if isinstance(u, Fraction) else Fraction(float(u))
    n_ctrl = len(points)
    last = k[-1]
    # basis[p][i] = N_{i,p}(u); the half-open convention, the right end closed
    if uf >= last:
        span = max(i for i in range(len(k) - 1) if k[i] < k[i + 1])
    else:
        span = max(i for i in range(len(k) - 1) if k[i] <= uf < k[i + 1])
    table = [[Fraction(1) if i == span else Fraction(0) for i in range(len(k) - 1)]]
    for p in range(1, degree + 1):
        row = []
        for i in range(len(k) - 1 - p):
            value = Fraction(0)
            if k[i + p] != k[i]:
                value += (uf - k[i]) / (k[i + p] - k[i]) * table[p - 1][i]
            if k[i + p + 1] != k[i + 1]:
                value += (k[i + p + 1] - uf) / (k[i + p + 1] - k[i + 1]) * table[p - 1][i + 1]
            row.append(value)
        table.append(row)

    def ders(i: int, p: int, order: int) -> Fraction:
        if order == 0:
            return table[p][i]
        value = Fraction(0)
        if k[i + p] != k[i]:
            value += p * ders(i, p - 1, order - 1) / (k[i + p] - k[i])
        if k[i + p + 1] != k[i + 1]:
            value -= p * ders(i + 1, p - 1, order - 1) / (k[i + p + 1] - k[i + 1])
        return value

    pts = [[Fraction(float(c)) for c in point] for point in points]
    w = [Fraction(float(x)) for x in weights]
    a = [[Fraction(0)] * 3 for _ in range(3)]
    wd = [Fraction(0)] * 3
    for i in range(max(span - degree, 0), min(span + 1, n_ctrl)):
        for order in range(3):
            n = ders(i, degree, order) if order <= degree else Fraction(0)
            wd[order] += n * w[i]
            for c in range(3):
                a[order][c] += n * w[i] * pts[i][c]
    c0 = [a[0][c] / wd[0] for c in range(3)]
    c1 = [(a[1][c] - wd[1] * c0[c]) / wd[0] for c in range(3)]
    c2 = [(a[2][c] - 2 * wd[1] * c1[c] - wd[2] * c0[c]) / wd[0] for c in range(3)]
    return np.array([[float(x) for x in c0], [float(x) for x in c1], [float(x) for x in c2]])


def curvature(c1: np.ndarray, c2: np.ndarray) -> float:
    return float(np.linalg.norm(np.cross(c1, c2)) / np.linalg.norm(c1) ** 3)


def length(degree: int, knots, points, weights, a: float, b: float, n: int = 4000) -> float:
    """Arc length by composite Gauss-Legendre on the naive |C'| (a different rule than ours).

    The panels also break at every knot: |C'| is only piecewise smooth.
    """
    x, wq = np.polynomial.legendre.leggauss(8)
    edges = np.union1d(np.linspace(a, b, n + 1),
                       [k for k in np.asarray(knots, float) if a < k < b])
    total = 0.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        for xi, wi in zip(x, wq):
            u = 0.5 * (lo + hi) + 0.5 * (hi - lo) * xi
            total += 0.5 * (hi - lo) * wi * np.linalg.norm(evaluate(degree, knots, points,
                                                                    weights, u)[1])
    return total


def chord_speed_limit(kappa: float, period_s: float, chord_mm: float, acc: float,
                      jerk: float, feed: float) -> float:
    """Eq. 15 (corrected) written directly in rho, independent of the product's formula."""
    if kappa == 0.0:
        return feed
    rho = 1.0 / kappa
    chord = (2.0 / period_s) * math.sqrt(2.0 * rho * chord_mm - chord_mm**2) if chord_mm < rho \
        else 2.0 * rho / period_s
    return min(feed, chord, math.sqrt(acc * rho), (jerk * rho * rho) ** (1.0 / 3.0))
