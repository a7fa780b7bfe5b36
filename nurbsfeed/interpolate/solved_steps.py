"""The steps the stepping loop (interpolate.kernels) hands back: solved on the chord and arc
equations by bracketing and Illinois regula falsi instead of by a Taylor-based update.

Where |C'(u)| vanishes (repeated control points, design §3a) a step solves the chord equation
|C(u + du) - C(u)| = ds directly instead of dividing by |C'|; rk2c and rk4 also do so when |C'|
changes by more than a quarter within the step, which only happens right next to such a point,
or when the tangent turns by more than 60 degrees within it (a hairpin whose |C'| dips and rises
alike on both legs). There the curve can turn back within one step and the chord equation has
roots on both legs of the turn: `leg_step` first solves the arc, integral(|C'|, u, u + du) =
ds (`_arc_step`, adaptive Gauss-Legendre), then the chord root from there on, unless the chord
reaches ds only where the arc exceeds LEG_ARC_MAX ds (the far leg): then the arc root stands.

Across a knot where rk2c's chord stays off its target, the chord equation is solved from du = 0
(`chord_step`). The arc of a piece of the curve is geometry.arclength's (`arc_length`).
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry.arclength import arc_length
from nurbsfeed.geometry.kernel import find_span, point_d1
from nurbsfeed.jit import jit

# A step whose bracket grows past the curve's whole parameter range finds no arc or chord of
# its length: what is left of the curve is shorter than the step, as where the last control
# points coincide and a run's targets outrun the arc (an overshooting sigma, taylor1's drift).
# The step ends there, on the curve's still end (the landing then takes a lower sigma), instead
# of doubling on to an infinite u (a NaN point, refused by the motion guard).
CHORD_ITERATIONS = 200
EPS = float(np.finfo(float).eps)


ARC_REL_TOL = 1e-12  # of the target: what `_arc_step` resolves the arc of a step to
# `leg_step`: a chord root whose arc exceeds its target this much (relative) lies past a
# turn-back (rk2c's own arc exceeds its chord by 4.6 % where the tangent turns 60 degrees)
LEG_ARC_MAX = 1.1


@jit
def _illinois(x, g, lo, hi, g_lo, g_hi, side):
    """One step of Illinois regula falsi: the bracket [lo, hi] (g_lo < 0 <= g_hi) after the
    candidate x with value g, and the side it replaced (-1: lo, 1: hi, 0: none yet). Replacing
    the same side twice halves the other end's value, so that the bracket shrinks from both
    ends. (side is a float: numba would compile this once more for the literal integer 0.)"""
    if g < 0.0:
        if side == -1.0:
            g_hi *= 0.5
        return x, hi, g, g_hi, -1.0
    if side == 1.0:
        g_lo *= 0.5
    return lo, x, g_lo, g, 1.0


@jit
def _arc_step(knots, coef, degree, n_ctrl, u, ds, guess, span):
    """The du > 0 whose arc from u is ds (integral of |C'| over [u, u + du]), by bracketing and
    Illinois regula falsi; the arc to each new candidate is added to the arc to the bracket's
    low end, so that the pieces integrated shrink with the bracket."""
    tol = ARC_REL_TOL * ds
    lo = 0.0
    arc_lo = 0.0
    hi = guess
    arc_hi = arc_length(knots, coef, degree, n_ctrl, u, u + hi, tol, span)
    u_range = knots[knots.size - 1] - knots[0]
    for _ in range(CHORD_ITERATIONS):
        if arc_hi >= ds:
            break
        if hi > u_range:  # the curve left is shorter than the step: see CHORD_ITERATIONS
            return hi
        lo = hi
        arc_lo = arc_hi
        hi *= 2.0
        arc_hi = arc_lo + arc_length(knots, coef, degree, n_ctrl, u + lo, u + hi, tol, span)
    g_lo = arc_lo - ds
    g_hi = arc_hi - ds
    side = 0.0
    for _ in range(CHORD_ITERATIONS):
        if hi - lo <= 1e-16 * (abs(u) + hi) or g_hi == g_lo or -g_lo <= tol or g_hi <= tol:
            break
        x = (lo * g_hi - hi * g_lo) / (g_hi - g_lo)
        if x <= lo or x >= hi:
            x = 0.5 * (lo + hi)
        arc_x = arc_lo + arc_length(knots, coef, degree, n_ctrl, u + lo, u + x, tol, span)
        g = arc_x - ds
        if g < 0.0:
            arc_lo = arc_x
        lo, hi, g_lo, g_hi, side = _illinois(x, g, lo, hi, g_lo, g_hi, side)
    return lo if -g_lo < g_hi else hi


@jit
def leg_step(knots, coef, degree, n_ctrl, u, px, py, pz, ds, guess, span):
    """The step beside a point where C' (nearly) vanishes: the du > 0 whose chord from
    P = C(u) is ds on the leg the arc ds reaches, or, past a turn-back, whose arc is ds.

    The chord equation alone has roots on both legs of a turn-back, and bracketing from du = 0
    can land on the far one (ahead of the law by more than the step). The arc root comes first
    (arc = ds, chord <= ds, `_arc_step`); the chord root is sought from it on, as rk2c's other
    steps make chords equal their targets: stepping arcs here and chords beside would jump by
    the arc minus the chord (a 5 % jerk at a tight corner). If the chord reaches ds only where
    the arc exceeds LEG_ARC_MAX ds, it does so on the far leg of a turn-back: the arc root
    stands."""
    du_arc = _arc_step(knots, coef, degree, n_ctrl, u, ds, guess, span)
    span = find_span(knots, degree, n_ctrl, u + du_arc, span)
    cx, cy, cz, _, _, _ = point_d1(knots, coef, degree, span, u + du_arc)
    chord = math.sqrt((cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2)
    if chord >= ds:
        return du_arc
    # bracket the chord root beyond the arc root, by widths doubling from the chord's shortfall
    width = du_arc * (ds - chord) / ds + 4.0 * EPS * (abs(u) + du_arc)
    arc = ds
    lo = du_arc
    u_range = knots[knots.size - 1] - knots[0]
    for _ in range(CHORD_ITERATIONS):
        if lo > u_range:  # the curve left is shorter than the step: see CHORD_ITERATIONS
            return du_arc
        hi = lo + width
        span = find_span(knots, degree, n_ctrl, u + hi, span)
        cx, cy, cz, _, _, _ = point_d1(knots, coef, degree, span, u + hi)
        arc += arc_length(knots, coef, degree, n_ctrl, u + lo, u + hi, ARC_REL_TOL * ds, span)
        if arc > LEG_ARC_MAX * ds:
            return du_arc
        if math.sqrt((cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2) >= ds:
            return chord_step(knots, coef, degree, n_ctrl, u, px, py, pz, ds, lo, hi, span)
        lo = hi
        width *= 2.0
    return du_arc


@jit
def chord_step(knots, coef, degree, n_ctrl, u, px, py, pz, ds, lo, guess, span):
    """The du > lo with |C(u + du) - P| = ds (the chord at lo short of ds), by bracketing from
    guess and Illinois regula falsi."""
    lo0 = lo
    span = find_span(knots, degree, n_ctrl, u + lo, span)
    cx, cy, cz, _, _, _ = point_d1(knots, coef, degree, span, u + lo)
    g_lo = math.sqrt((cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2) - ds if lo > 0.0 else -ds
    hi = guess
    g_hi = -ds
    u_range = knots[knots.size - 1] - knots[0]
    for _ in range(CHORD_ITERATIONS):
        span = find_span(knots, degree, n_ctrl, u + hi, span)
        cx, cy, cz, _, _, _ = point_d1(knots, coef, degree, span, u + hi)
        g_hi = math.sqrt((cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2) - ds
        if g_hi >= 0.0:
            break
        if hi - lo0 > u_range:  # the curve left is shorter than the step: see CHORD_ITERATIONS
            return hi
        lo = hi
        g_lo = g_hi
        hi = lo0 + 2.0 * (hi - lo0)
    side = 0.0
    for _ in range(CHORD_ITERATIONS):
        if hi - lo <= 1e-16 * (abs(u) + hi) or g_hi == g_lo:
            break
        x = (lo * g_hi - hi * g_lo) / (g_hi - g_lo)
        span = find_span(knots, degree, n_ctrl, u + x, span)
        cx, cy, cz, _, _, _ = point_d1(knots, coef, degree, span, u + x)
        g = math.sqrt((cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2) - ds
        if g == 0.0:
            return x
        lo, hi, g_lo, g_hi, side = _illinois(x, g, lo, hi, g_lo, g_hi, side)
    return lo if -g_lo < g_hi else hi

