"""Arc length by adaptive Simpson quadrature of |C'(u)| (paper Eq. 21, with the norms it omits).

Each interval between consecutive nodes is integrated on its own, depth-first with an explicit
stack of the right halves still to do: an interval [a, b] with Simpson value S(a, b) is split at
its midpoint m, and accepted when |S(a, m) + S(m, b) - S(a, b)| <= 15 tol (the classic
criterion; tol halves with each split) or at MAX_DEPTH; an accepted interval contributes
S(a, m) + S(m, b) plus the Richardson term (S(a, m) + S(m, b) - S(a, b)) / 15.
|C'| comes from the span polynomials (geometry.kernel), one parameter at a time.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry.kernel import find_span, point_d1
from nurbsfeed.jit import jit

MAX_DEPTH = 40
# Splits per node interval: MAX_DEPTH alone allows 2^40 of them where |C'| is rounding noise
# (coincident control points), which never ends in practice; a smooth |C'| needs a few dozen.
MAX_SPLITS = 1 << 16


@jit
def simpson_lengths(knots, coef, degree, nodes, speed_at_nodes, tol_per_u):
    """Cumulative arc length at the nodes: (M,) -> (M,), s[0] = 0.

    coef: the curve's span polynomials; speed_at_nodes: |C'| at the nodes, already known to the
    caller (the grid computes it with the curvature). The interval [u_i, u_i+1] is integrated
    to tol_per_u * (u_i+1 - u_i) (length units per unit of u). An interval that needs more
    than MAX_SPLITS splits makes s NaN from its end on: the caller refuses the curve there.
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
