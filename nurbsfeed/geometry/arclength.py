"""Arc length of a NURBS curve: every quadrature of |C'(u)| (paper Eq. 21, with the norms it
omits) that nurbsfeed uses, each for what its callers need. |C'| comes from the span polynomials
(geometry.kernel), one parameter at a time, or from the caller's vectorised evaluation.

- `simpson_lengths` (compiled): the cumulative arc at the planning grid's nodes (planning.grid).
  Adaptive Simpson, each interval between consecutive nodes on its own, depth-first with an
  explicit stack of the right halves still to do: an interval [a, b] with Simpson value
  S(a, b) is split at its midpoint m, and accepted when |S(a, m) + S(m, b) - S(a, b)| <= 15 tol
  (the classic criterion; tol halves with each split) or at MAX_DEPTH; an accepted interval
  contributes S(a, m) + S(m, b) plus the Richardson term (S(a, m) + S(m, b) - S(a, b)) / 15.
- `arc_length` (compiled): the arc of one piece [a, b] to a tolerance, by adaptive 5-point
  Gauss-Legendre, for the steps beside a zero of C' (interpolate.solved_steps).
- `gauss_lengths` (numpy): the arcs of many pieces at once by a fixed Gauss-Legendre rule, for
  pieces short enough and free of knots (the path model's u(s), planning.path_check; the check's
  arc, analysis.geometry; the reference schedule's cells, analysis.bound.grid).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np

from nurbsfeed.geometry.kernel import find_span, point_d1
from nurbsfeed.jit import jit

MAX_DEPTH = 40  # halvings of a node interval by `simpson_lengths`
# Splits per node interval: MAX_DEPTH alone allows 2^40 of them where |C'| is rounding noise
# (coincident control points), which never ends in practice; a smooth |C'| needs a few dozen.
MAX_SPLITS = 1 << 16
# Gauss-Legendre, 5 points on [-1, 1]: the arc of a piece of the curve (`arc_length`)
GAUSS_X = (-0.906179845938664, -0.5384693101056831, 0.0, 0.5384693101056831, 0.906179845938664)
GAUSS_W = (0.23692688505618928, 0.4786286704993663, 0.5688888888888887, 0.4786286704993663,
           0.23692688505618928)
ARC_MAX_DEPTH = 48  # halvings of a piece by `arc_length`: far below any step's rounding
ARC_MAX_PIECES = 4096  # pieces `arc_length` splits at most
EPS = float(np.finfo(float).eps)


@jit
def simpson_lengths(knots, coef, degree, nodes, speed_at_nodes, speed_at_middles, tol_per_u):
    """Cumulative arc length at the nodes: (M,) -> (M,), s[0] = 0.

    coef: the curve's span polynomials; speed_at_nodes: |C'| at the nodes, and
    speed_at_middles (M,): at the middle of each node's interval to the next, NaN where not
    known; both computed by the caller already (the grid computes them with the curvature). The
    interval [u_i, u_i+1] is integrated to tol_per_u * (u_i+1 - u_i) (length units per unit of
    u). An interval that needs more than MAX_SPLITS splits makes s NaN from its end on: the
    caller refuses the curve there.
    """
    n_ctrl = coef.shape[0]
    cumulative = np.empty(nodes.size)  # (not np.zeros: numba would compile it)
    if nodes.size:
        cumulative[0] = 0.0
    # the stack: intervals [a, b] still to integrate, with |C'| at a, the midpoint and b, their
    # Simpson value, tolerance and depth (one pending interval per level at most)
    stack = np.empty((MAX_DEPTH + 2, 8))
    span = degree
    for i in range(nodes.size - 1):
        a = nodes[i]
        b = nodes[i + 1]
        fa = speed_at_nodes[i]
        fb = speed_at_nodes[i + 1]
        fm = speed_at_middles[i]
        if fm != fm:
            m = 0.5 * (a + b)
            span = find_span(knots, degree, n_ctrl, m, span)
            _, _, _, dx, dy, dz = point_d1(knots, coef, degree, span, m)
            fm = math.sqrt(dx * dx + dy * dy + dz * dz)
        whole = (b - a) / 6.0 * (fa + 4.0 * fm + fb)
        tol = tol_per_u * (b - a)
        depth = 0.0
        top = 0
        total = 0.0
        splits = 0
        while splits <= MAX_SPLITS:
            m = 0.5 * (a + b)
            # |C'| at both quarter points (written once: helpers that take arrays cost a call)
            flm = 0.0
            frm = 0.0
            for quarter in range(2):
                uq = 0.5 * (a + m) if quarter == 0 else 0.5 * (m + b)
                span = find_span(knots, degree, n_ctrl, uq, span)
                _, _, _, dx, dy, dz = point_d1(knots, coef, degree, span, uq)
                if quarter == 0:
                    flm = math.sqrt(dx * dx + dy * dy + dz * dz)
                else:
                    frm = math.sqrt(dx * dx + dy * dy + dz * dz)
            left = (m - a) / 6.0 * (fa + 4.0 * flm + fm)
            right = (b - m) / 6.0 * (fm + 4.0 * frm + fb)
            err = left + right - whole
            if abs(err) <= 15.0 * tol or depth >= MAX_DEPTH:
                total += left + right + err / 15.0
                if top == 0:
                    break
                top -= 1  # the right half left behind at the last split
                a, b, fa, fm, fb, whole, tol, depth = (stack[top, 0], stack[top, 1],
                                                       stack[top, 2], stack[top, 3],
                                                       stack[top, 4], stack[top, 5],
                                                       stack[top, 6], stack[top, 7])
                continue
            # split: integrate the left half now, the right half later
            stack[top, 0] = m
            stack[top, 1] = b
            stack[top, 2] = fm
            stack[top, 3] = frm
            stack[top, 4] = fb
            stack[top, 5] = right
            stack[top, 6] = tol / 2.0
            stack[top, 7] = depth + 1.0
            top += 1
            b = m
            fb = fm
            fm = flm
            whole = left
            tol /= 2.0
            depth += 1.0
            splits += 1
        if splits > MAX_SPLITS:
            cumulative[i + 1:] = math.nan
            return cumulative
        cumulative[i + 1] = cumulative[i] + total
    return cumulative


@jit
def _gauss_arc(knots, coef, degree, n_ctrl, a, b, span):
    """Integral of |C'| over [a, b] by 5-point Gauss-Legendre, and the span last used."""
    half = 0.5 * (b - a)
    mid = 0.5 * (a + b)
    total = 0.0
    for i in range(5):
        x = mid + half * GAUSS_X[i]
        span = find_span(knots, degree, n_ctrl, x, span)
        _, _, _, dx, dy, dz = point_d1(knots, coef, degree, span, x)
        total += GAUSS_W[i] * math.sqrt(dx * dx + dy * dy + dz * dz)
    return half * total, span


@jit
def arc_length(knots, coef, degree, n_ctrl, a, b, tol, span):
    """The arc length of C over [a, b] (a <= b) to about tol, by adaptive Gauss-Legendre: a
    piece is halved until its halves add up to it within its share of tol and to no less than
    its chord. |C'| has a kink where C' = 0 and a narrow dip where it nearly vanishes, which a
    fixed rule misses; where the curve rests over most of [a, b] (coincident control points)
    every node of the rule can fall on the rest, and only the chord shows the piece moved."""
    if b <= a:  # a piece narrower than u's rounding
        return 0.0
    stack_a = np.empty(ARC_MAX_DEPTH + 2)
    stack_b = np.empty(ARC_MAX_DEPTH + 2)
    stack_q = np.empty(ARC_MAX_DEPTH + 2)
    whole, span = _gauss_arc(knots, coef, degree, n_ctrl, a, b, span)
    # positions carry rounding of EPS times their coordinates, and so does any arc from them:
    # no piece is split for less (a step of 10 nm asks 1e-20 mm of tol)
    span = find_span(knots, degree, n_ctrl, a, span)
    ax, ay, az, _, _, _ = point_d1(knots, coef, degree, span, a)
    floor = 8.0 * EPS * (abs(ax) + abs(ay) + abs(az))
    stack_a[0] = a
    stack_b[0] = b
    stack_q[0] = whole
    top = 1
    total = 0.0
    width = b - a
    pieces = 0
    while top > 0:
        top -= 1
        lo = stack_a[top]
        hi = stack_b[top]
        q = stack_q[top]
        mid = 0.5 * (lo + hi)
        left, span = _gauss_arc(knots, coef, degree, n_ctrl, lo, mid, span)
        right, span = _gauss_arc(knots, coef, degree, n_ctrl, mid, hi, span)
        span = find_span(knots, degree, n_ctrl, lo, span)
        ax, ay, az, _, _, _ = point_d1(knots, coef, degree, span, lo)
        span = find_span(knots, degree, n_ctrl, hi, span)
        bx, by, bz, _, _, _ = point_d1(knots, coef, degree, span, hi)
        chord = math.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2)
        # beside the tolerance, a floor of rounding (tol may lie below it) and a cap on the
        # pieces: the work stays bounded however tight tol is
        pieces += 1
        slack = max(tol * (hi - lo) / width, 8.0 * EPS * abs(left + right), floor)
        if ((abs(left + right - q) <= slack and left + right >= chord - slack)
                or top >= ARC_MAX_DEPTH or pieces >= ARC_MAX_PIECES or mid <= lo or mid >= hi):
            total += left + right
            continue
        # the right half first on the stack's top: the pieces are summed from a to b
        stack_a[top] = mid
        stack_b[top] = hi
        stack_q[top] = right
        stack_a[top + 1] = lo
        stack_b[top + 1] = mid
        stack_q[top + 1] = left
        top += 2
    return total


@functools.cache
def _gauss_rule(points: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [-1, 1], (points,) each, read-only."""
    x, w = np.polynomial.legendre.leggauss(points)
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


def gauss_lengths(speed: Callable[[np.ndarray], np.ndarray], u0: np.ndarray, u1: np.ndarray,
                  points: int) -> np.ndarray:
    """The arc from u0 to u1 (M,) each, by `points`-point Gauss-Legendre: (M,).

    speed: |C'| at the quadrature nodes, (M * points,) -> (M * points,), piece by piece. Exact
    to rounding on pieces that hold no knot (where |C'| may jump: the callers cut their pieces
    at the knots, or evaluate each on its own span) and are short for the curve's bends.
    """
    x, w = _gauss_rule(points)
    half = 0.5 * (u1 - u0)
    mid = 0.5 * (u0 + u1)
    at = (mid[:, None] + half[:, None] * x[None, :]).ravel()
    return half * (speed(at).reshape(half.size, x.size) @ w)
