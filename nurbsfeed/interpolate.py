"""The real-time stage (design §3): from the time law's per-period targets to curve parameters.

All three methods consume the same targets ds_k = s(t_{k+1}) - s(t_k), t_k = k T:
  taylor1  u+ = u + ds / |C'(u)|
  rk4      classical RK4 on du/ds = 1/|C'(u)| over the step ds (4 derivative evaluations)
  rk2c     the paper's method (Eq. 3-13): K1 = 1/|C'(u)|, K2 = 1/|C'(u + ds K1)|,
           u~ = u + ds (K1 + K2)/2, then the correction du that makes the chord |C(u~ + du) - C(u)|
           equal ds to first order: c1 du^2 + c2 du + c3 = 0 with c1 = |C'(u~)|^2,
           c2 = 2 C'(u~).(C(u~) - C(u)), c3 = |C(u~) - C(u)|^2 - ds^2. The root near zero,
           (-c2 + sqrt(disc)) / (2 c1), is computed as -2 c3 / (c2 + sqrt(disc)) (same root, no
           cancellation); du = 0 when disc < 0 (the paper's rule).
Where |C'(u)| vanishes (repeated control points, design §3a) a step solves the chord equation
|C(u + du) - C(u)| = ds directly instead of dividing by |C'|; rk2c and rk4 also do so when |C'|
changes by more than a quarter within the step, which only happens right next to such a point,
or when the tangent turns by more than 60 degrees within it (a hairpin whose |C'| dips and rises
alike on both legs). There the curve can turn back within one step and the chord equation has
roots on both legs of the turn: `_leg_step` first solves the arc, integral(|C'|, u, u + du) =
ds (`_arc_step`, adaptive Gauss-Legendre), then the chord root from there on, unless the chord
reaches ds only where the arc exceeds LEG_ARC_MAX ds (the far leg): then the arc root stands.

End landing: rk2c makes every chord equal to its target, so its arc position runs ahead of the
time law (by the arc minus the chord of every step, ~1 um over a curve) and the last step would
overshoot the end. The last point is the curve end itself, and the targets are lowered (never
raised: no limit is raised either) so that the last chord, from the last stepped point to the
end, equals its own target:
1. All targets are scaled by one factor sigma <= 1: for rk2c 1 - (the drift predicted from the
   curvature along the way, see `_sample_stretch`) / length + LANDING_MARGIN_REL, so that the
   first run overshoots by a little; for rk4 and taylor1, sigma = 1.
2. The overshoot is taken out by a slowdown bump in the stretch's last cruise (or hold) of the
   law, where a = j = 0: the law's v becomes v - e v_c sin^2(pi x / D) over its last
   BUMP_PERIODS periods (x from the bump's start, D its length; e ~ 1e-6 and at most
   BUMP_MAX_SLOWDOWN, so that the bump's own a and j, e v_c pi / D and e v_c 2 pi^2 / D^2, stay
   far below the limits). e is found by a secant search that steps again only from the bump
   on, a few percent of the stretch: one full run and a short one instead of two full runs.
3. Without such a cruise (or if the first run falls short), sigma itself is found by a secant
   search over full runs (d residual / d sigma ~ -length), never above 1.
Both searches stop when the last chord matches its target to LANDING_REL_TOL, or to the rounding
floor of the stepping where that is coarser (but at most LANDING_REL_MAX), or where rounding
stops them improving (then the best run stands). A run whose point n - 1 lies on or past the end
is never kept (the machine would pass the end and come back, or u would step back at a rest):
it ranks below every run before the end, and should the searches end on one, sigma is lowered
until the point lies before the end (an internal error if it never does).
Where the plan rests inside the curve (a corner), each stretch between rests is stepped and
landed on its own, so a point falls exactly on the corner.

Memory is bounded whatever the curve's duration (`Stepping`, `_Stretch`): a stretch is sampled
and stepped CHUNK_PERIODS periods at a time. The landing needs of a run only its last point (and
u where the bump starts), so a stretch longer than a chunk samples its targets from the law again
for every run, at t_k from the integer k (never by summing periods), and once sigma and the bump
are decided steps a last time, handing its points on chunk by chunk. A run carries only u from
one chunk to the next, and the sums over the targets are taken in order, so the points are the
same to the last bit however the stretch is chunked. A stretch within one chunk (the common
case) is sampled once and its last run is what is handed on.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nurbsfeed.choices import METHOD_NAMES
from nurbsfeed.geometry.kernel import find_span, point_d1
from nurbsfeed.jit import jit
from nurbsfeed.planning.plan import Plan
from nurbsfeed.planning.timelaw import TimeLaw, evaluate

METHODS = {name: code for code, name in enumerate(METHOD_NAMES)}  # name -> kernel code
# what `_step_run` stopped for: the end, or a step it hands back to `_chord_step` or `_leg_step`
STEP_DONE, STEP_CHORD, STEP_LEG = 0, 1, 2
CHUNK_PERIODS = 65536  # periods of a stretch sampled, stepped or held in memory at a time
SLOW_SPEED_REL = 1e-3  # |C'| below this fraction of the mean |C'| is treated as "zero"
# rk2c / rk4: when |C'| changes by more than this fraction across one step, the step is next to
# a point where C' = 0 and the Taylor-based update is not valid there: solve the chord instead.
STEP_SPEED_CHANGE_MAX = 0.25
# rk2c / rk4: when the tangent turns by more than 60 degrees across one step (cos below this),
# the step rounds a hairpin whose |C'| dips and rises again alike on its two legs (unseen by the
# speed change): the chord there is far shorter than the arc, and the chord correction lands on
# the far leg. Solve the arc instead.
STEP_TURN_COS_MIN = 0.5
LANDING_REL_TOL = 1e-6  # of the last target: the last chord matches it to 1e-4 % ...
LANDING_REL_MAX = 5e-6  # ... or, where rounding does not resolve that, to half rk2c's 1e-5
LANDING_MAX_RUNS = 8
LANDING_MARGIN_REL = 1e-8  # the first run's sigma lies this far (relative) above the estimate
BUMP_PERIODS = 32
BUMP_MAX_SLOWDOWN = 1e-4
CHORD_ITERATIONS = 200
# A step whose bracket grows past the curve's whole parameter range finds no arc or chord of
# its length: what is left of the curve is shorter than the step, as where the last control
# points coincide and a run's targets outrun the arc (an overshooting sigma, taylor1's drift).
# The step ends there, on the curve's still end (the landing then takes a lower sigma), instead
# of doubling on to an infinite u (a NaN point, refused by the motion guard).
# rk2c: a step across a knot whose chord is still this far (relative) from its target after two
# corrections is solved exactly (a knot where |C'| jumps: a rational curve of degree 1)
KNOT_CHORD_REL = 1e-9
# rk2c: a step whose chord correction moves u by more than this share of the step (u~'s chord
# was off its target by about as much) is checked, and solved exactly if still off, as across a
# knot. On the samples u~'s chord is off by 0.21 % at most (the butterfly's tightest turns; the
# correction takes that to 5e-8); a dip of |C'| to 4 % of its mean inside one step of a straight
# leg, between the points rk2c samples, left it 14 % off, and the correction 0.8 % (a feed 0.6 %
# over the cap). Checked after the one correction, not by a second one inside its loop: that
# cost 10 % of the kernel's time on the butterfly.
STEP_CORRECTION_MAX = 5e-3
EPS = float(np.finfo(float).eps)


# Gauss-Legendre, 5 points on [-1, 1]: the arc of a piece of the curve (`_arc`)
GAUSS_X = (-0.906179845938664, -0.5384693101056831, 0.0, 0.5384693101056831, 0.906179845938664)
GAUSS_W = (0.23692688505618928, 0.4786286704993663, 0.5688888888888887, 0.4786286704993663,
           0.23692688505618928)
ARC_REL_TOL = 1e-12  # of the target: what `_arc_step` resolves the arc of a step to
ARC_MAX_DEPTH = 48  # halvings of a piece by `_arc`: far below any step's rounding
ARC_MAX_PIECES = 4096  # pieces `_arc` splits at most
# `_leg_step`: a chord root whose arc exceeds its target this much (relative) lies past a
# turn-back (rk2c's own arc exceeds its chord by 4.6 % where the tangent turns 60 degrees)
LEG_ARC_MAX = 1.1


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
def _arc(knots, coef, degree, n_ctrl, a, b, tol, span):
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
    arc_hi = _arc(knots, coef, degree, n_ctrl, u, u + hi, tol, span)
    u_range = knots[knots.size - 1] - knots[0]
    for _ in range(CHORD_ITERATIONS):
        if arc_hi >= ds:
            break
        if hi > u_range:  # the curve left is shorter than the step: see CHORD_ITERATIONS
            return hi
        lo = hi
        arc_lo = arc_hi
        hi *= 2.0
        arc_hi = arc_lo + _arc(knots, coef, degree, n_ctrl, u + lo, u + hi, tol, span)
    g_lo = arc_lo - ds
    g_hi = arc_hi - ds
    side = 0.0
    for _ in range(CHORD_ITERATIONS):
        if hi - lo <= 1e-16 * (abs(u) + hi) or g_hi == g_lo or -g_lo <= tol or g_hi <= tol:
            break
        x = (lo * g_hi - hi * g_lo) / (g_hi - g_lo)
        if x <= lo or x >= hi:
            x = 0.5 * (lo + hi)
        arc_x = arc_lo + _arc(knots, coef, degree, n_ctrl, u + lo, u + x, tol, span)
        g = arc_x - ds
        if g < 0.0:
            arc_lo = arc_x
        lo, hi, g_lo, g_hi, side = _illinois(x, g, lo, hi, g_lo, g_hi, side)
    return lo if -g_lo < g_hi else hi


@jit
def _leg_step(knots, coef, degree, n_ctrl, u, px, py, pz, ds, guess, span):
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
        arc += _arc(knots, coef, degree, n_ctrl, u + lo, u + hi, ARC_REL_TOL * ds, span)
        if arc > LEG_ARC_MAX * ds:
            return du_arc
        if math.sqrt((cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2) >= ds:
            return _chord_step(knots, coef, degree, n_ctrl, u, px, py, pz, ds, lo, hi, span)
        lo = hi
        width *= 2.0
    return du_arc


@jit
def _chord_step(knots, coef, degree, n_ctrl, u, px, py, pz, ds, lo, guess, span):
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


def step_spans(method, knots, coef, degree, n_spans, u0, ds, sigma, slow_speed, u_out, p_out):
    """Step from u0 through the targets sigma * ds (N,): u_out (N+1,), p_out (N+1, 3) = C(u_k).

    coef: the curve's span polynomials (geometry.kernel.span_polynomials). Spans past index
    n_spans - 1 are not used: beyond the end of the stretch the last span's polynomial
    extrapolates, so the landing search sees a smooth continuation even at a corner.

    The stepping loop is compiled (`_step_run`); the steps it cannot take itself (a chord
    solved exactly across a knot, `_chord_step`; a step beside a point where C' vanishes,
    `_leg_step`) it hands back, and they are taken here. Those kernels, and the arc-length
    search they use, compile the first time a curve needs them: many conversions never do,
    and compiling them with the loop would cost ~2 s of every first run.
    """
    k, u, span = 0, u0, degree
    while True:
        k, stop, guess, span = _step_run(method, knots, coef, degree, n_spans, k, u, span, ds,
                                         sigma, slow_speed, u_out, p_out)
        if stop == STEP_DONE:
            return
        u, h = u_out[k], sigma * ds[k]
        px, py, pz = p_out[k]
        if stop == STEP_CHORD:
            u = u + _chord_step(knots, coef, degree, n_spans, u, px, py, pz, h, 0.0, guess, span)
        else:
            u = u + _leg_step(knots, coef, degree, n_spans, u, px, py, pz, h, guess, span)
        k += 1


@jit
def _step_run(method, knots, coef, degree, n_spans, k0, u0, span0, ds, sigma, slow_speed, u_out,
              p_out):
    """`step_spans`' loop from point k0 at u0 (span0: where to look for its span first) to the
    end: returns (N, STEP_DONE, 0, span), or, where the step from a point k needs a kernel it
    does not call, (k, STEP_CHORD or STEP_LEG, that kernel's guess of du, the span of u_k)."""
    n_ctrl = n_spans
    u_range = knots[knots.size - 1] - knots[0]
    u = u0
    span = span0
    for k in range(k0, ds.size + 1):
        span = find_span(knots, degree, n_ctrl, u, span)
        px, py, pz, dx, dy, dz = point_d1(knots, coef, degree, span, u)
        u_out[k] = u
        p_out[k, 0] = px
        p_out[k, 1] = py
        p_out[k, 2] = pz
        if k == ds.size:
            break
        h = sigma * ds[k]
        speed = math.sqrt(dx * dx + dy * dy + dz * dz)
        if h <= 0.0:
            continue
        slow = speed < slow_speed
        if not slow:
            k1 = 1.0 / speed
            if method == 0:
                u = u + h * k1
                continue
            if method == 1:
                s2 = find_span(knots, degree, n_ctrl, u + 0.5 * h * k1, span)
                _, _, _, tx, ty, tz = point_d1(knots, coef, degree, s2, u + 0.5 * h * k1)
                sp2 = math.sqrt(tx * tx + ty * ty + tz * tz)
                s3 = find_span(knots, degree, n_ctrl, u + 0.5 * h / sp2, s2)
                _, _, _, tx, ty, tz = point_d1(knots, coef, degree, s3, u + 0.5 * h / sp2)
                sp3 = math.sqrt(tx * tx + ty * ty + tz * tz)
                s4 = find_span(knots, degree, n_ctrl, u + h / sp3, s3)
                _, _, _, tx, ty, tz = point_d1(knots, coef, degree, s4, u + h / sp3)
                sp4 = math.sqrt(tx * tx + ty * ty + tz * tz)
                slow = (sp2 < slow_speed or sp3 < slow_speed or sp4 < slow_speed
                        or abs(1.0 - speed / sp4) > STEP_SPEED_CHANGE_MAX
                        or dx * tx + dy * ty + dz * tz < STEP_TURN_COS_MIN * speed * sp4)
                if not slow:
                    u = u + h * (k1 + 2.0 / sp2 + 2.0 / sp3 + 1.0 / sp4) / 6.0
                    continue
            else:
                s2 = find_span(knots, degree, n_ctrl, u + h * k1, span)
                _, _, _, tx, ty, tz = point_d1(knots, coef, degree, s2, u + h * k1)
                sp2 = math.sqrt(tx * tx + ty * ty + tz * tz)
                slow = (sp2 < slow_speed or abs(1.0 - speed / sp2) > STEP_SPEED_CHANGE_MAX
                        or dx * tx + dy * ty + dz * tz < STEP_TURN_COS_MIN * speed * sp2)
                if not slow:
                    ut = u + 0.5 * h * (k1 + 1.0 / sp2)
                    s3 = find_span(knots, degree, n_ctrl, ut, s2)
                    # Across a knot C'' (or, at a knot of multiplicity `degree`, C' itself)
                    # jumps and one correction from u~ can leave the chord off by 0.4 % (a 10 %
                    # acceleration spike, from positions): correct again from the corrected u
                    # there (Newton on the chord), only at those steps, and if the chord is
                    # still off, solve it exactly. Likewise where the correction was large
                    # (STEP_CORRECTION_MAX: |C'| dips within the step, unseen at the points
                    # sampled).
                    crossed = s2 != span or s3 != span
                    du = 0.0
                    for _ in range(2 if crossed else 1):
                        qx, qy, qz, tx, ty, tz = point_d1(knots, coef, degree, s3, ut)
                        ex = qx - px
                        ey = qy - py
                        ez = qz - pz
                        c1 = tx * tx + ty * ty + tz * tz
                        c2 = 2.0 * (tx * ex + ty * ey + tz * ez)
                        c3 = ex * ex + ey * ey + ez * ez - h * h
                        disc = c2 * c2 - 4.0 * c1 * c3
                        du = 0.0
                        if disc >= 0.0:
                            den = c2 + math.sqrt(disc)
                            if den > 0.0:
                                du = -2.0 * c3 / den
                        ut = ut + du
                        s3 = find_span(knots, degree, n_ctrl, ut, s3)
                    if crossed or s3 != span or abs(du) > STEP_CORRECTION_MAX * (ut - u):
                        qx, qy, qz, _, _, _ = point_d1(knots, coef, degree, s3, ut)
                        chord = math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
                        if abs(chord - h) > KNOT_CHORD_REL * h:
                            return (k, STEP_CHORD,
                                    min(ut - u, u_range) if ut > u else h / speed, span)
                    u = ut
                    continue
        # Beside a point where C' (nearly) vanishes the curve can turn back within one step,
        # and the chord equation has roots on both legs of the turn: a chord step from du = 0
        # landed on the far leg (0.07 um of arc ahead of the law in one period, a 2x-4x jerk
        # from positions, a landing residual jumping with sigma). `_leg_step` keeps to the
        # leg the arc reaches.
        guess = h / slow_speed if speed < slow_speed else h / speed
        return k, STEP_LEG, min(guess, u_range), span
    return ds.size, STEP_DONE, 0.0, span


def _plan_time(t_a: float, t_b: float, n: int, k: int) -> float:
    """Plan time of period k of a stretch of n periods from t_a to t_b: t_a + k (t_b - t_a) / n,
    t_b exactly at k = n. From the integer k, never by summing periods."""
    if k == n:
        return t_b
    return t_a + k * ((t_b - t_a) / n)


def _plan_times(t_a: float, t_b: float, n: int, lo: int, hi: int) -> np.ndarray:
    """`_plan_time` of periods lo .. hi - 1: (hi - lo,), the same arithmetic in numpy."""
    t = t_a + np.arange(lo, hi) * ((t_b - t_a) / n)
    if lo <= n < hi:
        t[n - lo] = t_b
    return t


def _first_period_at(t_a: float, t_b: float, n: int, x: float) -> int:
    """np.searchsorted over a stretch's plan times (n+1,), which are never stored: the first
    period k with t_k >= x, by bisection."""
    lo = 0
    hi = n + 1
    while lo < hi:
        mid = (lo + hi) // 2
        if _plan_time(t_a, t_b, n, mid) < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@jit
def _sample_targets(t0, s0, v0, a0, jk, t_plan, ds, grid_s, grid_kappa, with_drift, node, drift,
                    total, carry):
    """The targets ds_k = s(t_k+1) - s(t_k) between the plan times t_plan (M+1,) of consecutive
    periods (`_plan_times`) into ds (M,), and the running sums over a stretch sampled chunk by
    chunk in order: returns them (node, drift, total, carry) updated.

    ds_k is taken piece by piece (the pieces' starts s0 differ, then the arcs within them), so
    that a tiny step far along the curve keeps its relative precision. total + carry is the
    targets' sum, compensated (Neumaier) and added in order, so that it does not depend on how
    the stretch is chunked. If with_drift, drift accumulates 24 times how far rk2c's arc position
    will run ahead of the targets: sum(min(kappa ds, 2)^2 ds), the arc minus the chord of a
    circular arc of curvature kappa per step, with kappa at the middle of each step interpolated
    linearly on the grid (grid_s, grid_kappa (G,); node: the grid interval reached so far);
    beside a corner (kappa infinite) from its finite side.
    """
    m = ds.size
    piece = np.empty(m + 1, dtype=np.int64)
    local = np.empty(m + 1)
    v = np.empty(m + 1)
    a = np.empty(m + 1)
    j = np.empty(m + 1)
    evaluate(t0, s0, v0, a0, jk, t_plan, piece, local, v, a, j)
    for k in range(m):
        ds[k] = (s0[piece[k + 1]] - s0[piece[k]]) + (local[k + 1] - local[k])
        added = total + ds[k]
        if abs(total) >= abs(ds[k]):
            carry += (total - added) + ds[k]
        else:
            carry += (ds[k] - added) + total
        total = added
    if with_drift:
        last = grid_s.size - 1
        for k in range(m):
            s = s0[piece[k]] + local[k] + 0.5 * ds[k]
            while node + 1 < last and grid_s[node + 1] <= s:
                node += 1
            if s <= grid_s[0]:
                kappa = grid_kappa[0]
            elif s >= grid_s[last]:
                kappa = grid_kappa[last]
            else:
                k_lo = grid_kappa[node]
                k_hi = grid_kappa[node + 1]
                if math.isinf(k_lo) or math.isinf(k_hi):  # beside a corner: the finite side
                    kappa = k_hi if math.isinf(k_lo) else k_lo
                else:
                    w = (s - grid_s[node]) / (grid_s[node + 1] - grid_s[node])
                    kappa = k_lo + w * (k_hi - k_lo)
            if math.isinf(kappa):
                continue
            turn = min(kappa * ds[k], 2.0)
            drift += turn * turn * ds[k]
    return node, drift, total, carry


@dataclass(frozen=True)
class _Bump:
    """The landing bump over periods k0 .. k0 + periods of a stretch (see the module docstring):
    the law's speed v_c there is lowered by e v_c w(t), w = sin^2(pi x / D), x = t - t_start,
    in plan time. times: the plan times of its points k0 .. k0 + periods, (periods + 1,)."""

    k0: int
    periods: int
    times: np.ndarray
    v_mm_s: float  # v_c

    @property
    def t_start(self) -> float:
        return float(self.times[0])

    @property
    def duration(self) -> float:  # D
        return float(self.times[-1] - self.times[0])

    def removed(self, t_s: np.ndarray) -> np.ndarray:
        """Arc taken out by plan time t (per unit of e): v_c integral of w, (M,) -> (M,)."""
        x = np.minimum(np.maximum(t_s - self.t_start, 0.0), self.duration)
        d = self.duration
        return self.v_mm_s * (0.5 * x - d / (4.0 * math.pi) * np.sin(2.0 * math.pi * x / d))

    @cached_property
    def taken(self) -> np.ndarray:
        """(periods,) arc taken out of each of its periods' targets, per unit of e."""
        return np.diff(self.removed(self.times))

    @cached_property
    def shape(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """v_c w, v_c w' and v_c w'' at its points k0 + 1 .. k0 + periods, (periods,) each."""
        t_s = self.times[1:]
        phase = 2.0 * math.pi * (t_s - self.t_start) / self.duration
        w = 0.5 * (1.0 - np.cos(phase))
        w1 = math.pi / self.duration * np.sin(phase)
        w2 = 2.0 * (math.pi / self.duration) ** 2 * np.cos(phase)
        return self.v_mm_s * w, self.v_mm_s * w1, self.v_mm_s * w2

    def lower(self, ds: np.ndarray, lo: int, e: float) -> np.ndarray:
        """The targets ds (M,) of periods lo .. lo + M - 1 with the bump of depth e taken out."""
        first, stop = max(lo, self.k0), min(lo + ds.size, self.k0 + self.periods)
        if e == 0.0 or first >= stop:
            return ds
        ds = ds.copy()
        ds[first - lo:stop - lo] -= e * self.taken[first - self.k0:stop - self.k0]
        return ds


@dataclass(frozen=True, eq=False)
class _StretchLaw:
    """The law over one stretch between rests as it was stepped: points k0 .. k0 + n of the
    curve, at plan times t_a .. t_b (`_plan_time`); the stretch's time scale, its sigma, its
    landing bump and that bump's depth. v, a and j are worked out from it when asked for."""

    k0: int
    n: int
    law: TimeLaw
    t_a: float
    t_b: float
    scale: float
    sigma: float
    bump: _Bump | None
    slowdown: float

    def kinematics(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """v, a, j at its points lo .. hi - 1 (hi - lo,), scaled like the targets stepped (sigma,
        and the stretch's scale), with the landing bump's own."""
        _, _, v, a, j = self.law.sample(_plan_times(self.t_a, self.t_b, self.n, lo, hi))
        bump = self.bump
        if bump is not None:
            first, stop = max(lo, bump.k0 + 1), min(hi, bump.k0 + 1 + bump.periods)
            if first < stop:
                vw, aw, jw = bump.shape
                inside = slice(first - bump.k0 - 1, stop - bump.k0 - 1)
                here = slice(first - lo, stop - lo)
                v[here] -= self.slowdown * vw[inside]
                a[here] -= self.slowdown * aw[inside]
                j[here] -= self.slowdown * jw[inside]
        return self.sigma * v / self.scale, self.sigma * a / self.scale**2, \
            self.sigma * j / self.scale**3


@dataclass(frozen=True, eq=False)
class PointChunk:
    """Points k0 .. k0 + M - 1 of a curve as they were stepped: u (M,), points (M, 3), and the
    target stepped into each point ds (M,) (0 into the curve's first point). They lie in one
    stretch, from its point `local` on (stretch None: the curve's first point, alone)."""

    k0: int
    u: np.ndarray
    points: np.ndarray
    ds_mm: np.ndarray
    stretch: _StretchLaw | None
    local: int
    start_jerk_mm_s3: float  # j at the curve's first point (at rest there: v = a = 0)

    def kinematics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """v, a, j of the law at the points, (M,) each."""
        if self.stretch is None:
            zero = np.zeros(self.u.size)
            return zero, zero, np.full(self.u.size, self.start_jerk_mm_s3)
        return self.stretch.kinematics(self.local, self.local + self.u.size)


@dataclass(frozen=True, eq=False)
class Interpolation:
    """One curve's interpolation points. (N+1,) arrays except points (N+1, 3) and ds (N,)."""

    method: str
    period_s: float
    u: np.ndarray
    points: np.ndarray  # C(u_k), full precision; first and last exactly the curve ends
    ds_mm: np.ndarray  # the targets actually stepped, (N,)
    landing_runs: float  # kernel runs over all stretches, a run from a bump on in its share
    stretches: tuple[_StretchLaw, ...]  # what v, a, j are computed from when asked for
    start_jerk_mm_s3: float  # j at the first point (at rest there: v = a = 0)

    @property
    def n_points(self) -> int:
        return self.u.size

    @property
    def sigma(self) -> np.ndarray:
        """(P,) target scale of each stretch between rests."""
        return np.array([st.sigma for st in self.stretches])

    @property
    def slowdown(self) -> np.ndarray:
        """(P,) relative depth e of each stretch's landing bump (0: none)."""
        return np.array([st.slowdown for st in self.stretches])

    # Time, arc, speed, acceleration and jerk at the points are for traces and analysis; a
    # conversion writes points only, so they are computed on first use.
    @cached_property
    def t_s(self) -> np.ndarray:
        return np.arange(self.n_points, dtype=float) * self.period_s

    @cached_property
    def s_mm(self) -> np.ndarray:
        """The sum of the targets actually stepped."""
        s = np.empty(self.n_points)
        s[0] = 0.0
        np.cumsum(self.ds_mm, out=s[1:])
        return s

    @property
    def v_mm_s(self) -> np.ndarray:
        return self._kinematics[0]

    @property
    def a_mm_s2(self) -> np.ndarray:
        return self._kinematics[1]

    @property
    def j_mm_s3(self) -> np.ndarray:
        return self._kinematics[2]

    @cached_property
    def _kinematics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """v, a, j of the law at the points (`_StretchLaw.kinematics`); at rest at every
        stretch start."""
        v_all = np.zeros(self.n_points)
        a_all = np.zeros(self.n_points)
        j_all = np.zeros(self.n_points)
        for st in self.stretches:
            span = slice(st.k0 + 1, st.k0 + st.n + 1)
            v_all[span], a_all[span], j_all[span] = st.kinematics(1, st.n + 1)
        j_all[0] = self.start_jerk_mm_s3
        for arr in (v_all, a_all, j_all):
            arr.setflags(write=False)
        return v_all, a_all, j_all

    def feed_fluctuation(self) -> np.ndarray:
        """design §3 / Table 2: | |P_{k+1} - P_k| - ds_k | / ds_k for every full period: (N,)."""
        chord = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ff = np.abs(chord - self.ds_mm) / self.ds_mm
        return ff[self.ds_mm > 0]


def _last_flat_periods(law: TimeLaw, t_a: float, t_b: float, n: int,
                       periods: int) -> tuple[int, float]:
    """The first period k0 of the last `periods` periods of the stretch (n periods, plan times
    t_a .. t_b) that lie in one piece of the law that cruises or holds (a = j = 0, v > 0), all
    before the stretch's last period; the piece's speed. (-1, 0) if there are none."""
    t0, a0, jk, v0 = law.t0_s, law.a0_mm_s2, law.jerk_mm_s3, law.v0_mm_s
    end = np.append(t0[1:], law.duration_s)
    before = int(np.searchsorted(t0, t_b, side="left"))  # the pieces that start before t_b
    # Only a flat piece at least periods - 1 periods long can hold `periods` periods (the plan
    # times' rounding is far below a period): the count below decides for those few.
    candidates = np.flatnonzero((jk[:before] == 0.0) & (a0[:before] == 0.0) & (v0[:before] > 0.0)
                                & (end[:before] - t0[:before] >= (periods - 1) * (t_b - t_a) / n))
    for i in candidates[::-1].tolist():
        if end[i] <= t_a:  # (and so every piece before it)
            break
        # the periods k with t_k >= t0 and t_k+1 <= end, the last one before n - 1
        first = _first_period_at(t_a, t_b, n, t0[i])
        after = _first_period_at(t_a, t_b, n, end[i])  # then the first with t_k > end (plan
        if after <= n and _plan_time(t_a, t_b, n, after) == end[i]:  # times strictly increase)
            after += 1
        stop = min(after - 1, n - 1)
        if stop - first >= periods:
            return stop - periods, float(v0[i])
    return -1, 0.0


def _within(sigma: float, bracket: list[float]) -> float:
    """sigma if it lies inside the landing's bracket (below, above) of the root, else the
    bracket's middle (its upper end at most 1)."""
    below, above = bracket
    if below < sigma < above:
        return sigma
    return 0.5 * (below + min(above, 1.0))


@dataclass(frozen=True)
class Landing:
    """How one stretch landed: sigma, the bump and its depth, the kernel runs it took (a run
    from the bump on in its share). Stepping the stretch once with these (`Stepping`'s
    `landed`) gives the landed points again without the search."""

    sigma: float
    bump: _Bump | None
    slowdown: float
    runs: float


class _Stretch:
    """One stretch between rests (plan piece p), stepped chunk by chunk: at most CHUNK_PERIODS
    periods are sampled, stepped or held at a time, whatever the stretch's duration.

    A stretch of at most CHUNK_PERIODS periods stays in memory ("resident"): its targets are
    sampled once and its last run is what is written. A longer one keeps of a run only its last
    point (all the landing needs) and the point where its bump starts; its targets are sampled
    again from the law for every run (from the integer period index, so identically), and once
    the landing is decided a last run hands its points out chunk by chunk. Both give the same
    points to the last bit: a run's state between chunks is u alone.
    """

    def __init__(self, plan: Plan, p: int, code: int, slow: float, chunk: int) -> None:
        curve, law = plan.curve, plan.law
        self.plan = plan
        self.code = code
        self.slow = slow
        self.chunk = chunk
        self.n = int(plan.piece_periods[p])
        key_a, key_b = int(plan.piece_key[p]), int(plan.piece_key[p + 1])
        self.t_a, self.t_b = float(law.key_t_s[key_a]), float(law.key_t_s[key_b])
        self.u_start, self.u_end = float(plan.key_u[key_a]), float(plan.key_u[key_b])
        # the last stretch that moves ends at the curve's end (a rest of zero length after it,
        # where the control points coincide, is no motion)
        last = not bool(np.any(plan.piece_periods[p + 1:] > 0))
        self.end_point = np.asarray(curve.points[-1] if last else curve.point(self.u_end),
                                    dtype=float)
        self.n_spans = int(np.searchsorted(curve.knots, self.u_end, side="left"))
        self.resident = self.n <= chunk
        size = self.n + 1 if self.resident else chunk + 2  # + 2: a chunk's start and the end
        self.u = np.empty(size)
        self.pts = np.empty((size, 3))
        self.u_bump = self.u_start  # u at the bump's first point, from the last full run
        self.past_end = False  # whether the last run's point n - 1 lies on or past the end
        # one pass over the targets: their sum, the last one, rk2c's drift (and, if resident,
        # the targets themselves)
        node, drift, total, carry = 0, 0.0, 0.0, 0.0
        self.ds = np.empty(self.n if self.resident else min(self.n, chunk))
        for lo in range(0, self.n, chunk):
            ds = self.ds[:min(chunk, self.n - lo)] if not self.resident else self.ds
            node, drift, total, carry = self._sample(lo, ds, code == METHODS["rk2c"], node, drift,
                                                     total, carry)
            self.last_ds = float(ds[-1])
        self.total = total + carry
        self.drift = drift / 24.0
        if not self.resident:
            self.ds = np.empty(0)
        k0, v_c = _last_flat_periods(law, self.t_a, self.t_b, self.n, BUMP_PERIODS)
        self.bump = None if k0 < 0 else _Bump(
            k0, BUMP_PERIODS, _plan_times(self.t_a, self.t_b, self.n, k0, k0 + BUMP_PERIODS + 1),
            v_c)

    def _sample(self, lo: int, ds: np.ndarray, with_drift: bool, node: int, drift: float,
                total: float, carry: float) -> tuple[int, float, float, float]:
        """`_sample_targets` of periods lo .. lo + M - 1 into ds (M,)."""
        plan = self.plan
        return _sample_targets(*plan.law.pieces, _plan_times(self.t_a, self.t_b, self.n, lo,
                                                             lo + ds.size + 1),
                               ds, plan.grid.s_mm, plan.grid.kappa_1_mm, with_drift, node, drift,
                               total, carry)

    def targets(self, lo: int, hi: int, e: float) -> np.ndarray:
        """The targets of periods lo .. hi - 1 (hi - lo,), with the bump of depth e taken out."""
        if self.resident:
            ds = self.ds[lo:hi]
        else:
            ds = np.empty(hi - lo)
            self._sample(lo, ds, False, 0, 0.0, 0.0, 0.0)
        return ds if self.bump is None else self.bump.lower(ds, lo, e)

    def _step(self, u0: float, ds: np.ndarray, sigma: float, u_out: np.ndarray,
              p_out: np.ndarray) -> None:
        curve = self.plan.curve
        step_spans(self.code, curve.knots, curve.span_polynomials, curve.degree, self.n_spans,
                   u0, ds, sigma, self.slow, u_out, p_out)

    def run(self, sigma: float, e: float = 0.0, from_bump: bool = False) -> float:
        """Step with targets sigma * ds (the bump of depth e taken out) to the last point before
        the end, from the start or from the bump's first point (u_bump of the last full run);
        return the landing residual |end - P_n-1| - (last target), signed by the side of the end
        the point lies on."""
        k = self.bump.k0 if from_bump and self.bump is not None else 0
        u = self.u_bump if k else self.u_start
        last = self.n - 1  # steps 0 .. n - 2 reach point n - 1
        while True:
            hi = min(k + self.chunk, last)
            base = k if self.resident else 0
            m = hi - k
            self._step(u, self.targets(k, hi, e), sigma, self.u[base:base + m + 1],
                       self.pts[base:base + m + 1])
            if not from_bump and self.bump is not None and k <= self.bump.k0 <= hi:
                self.u_bump = float(self.u[base + self.bump.k0 - k])
            u = float(self.u[base + m])
            if hi == last:
                break
            k = hi
        # a point on or past the end would make the machine go past it and back (or, at a rest
        # inside the curve, step u back for the next stretch): the landing never keeps such a run
        self.past_end = u >= self.u_end
        last_point = self.pts[base + m]  # the run's last stepped point (n - 1)
        gap = math.sqrt(sum((float(self.end_point[i]) - float(last_point[i])) ** 2
                            for i in range(3)))
        return (gap if u <= self.u_end else -gap) - sigma * self.last_ds

    def replay(self, landing: Landing) -> None:
        """Step as `land` ended, with its sigma and bump depth, from the start: the same points
        to the last bit (a run's state is u alone, and the bump lowers only the targets from
        its first period on, so a run from the start and one from the bump agree). A longer
        stretch steps in `points` anyway."""
        if self.resident:
            self.run(landing.sigma, landing.slowdown)

    def land(self, sigma: float) -> Landing:
        """Land exactly on the end (see the module docstring): first with targets sigma * ds,
        then with a bump or another sigma.

        The kernel makes the first n - 1 steps; the last point is the end itself, and the
        residual |end - P_n-1| - (last target) is driven to zero. It is continuous and monotone
        in sigma and e even where C' vanishes at the end (the curve folds back there when
        extrapolated).
        """
        n, total, last_ds = self.n, self.total, self.last_ds
        # Each step rounds the point to ~eps (length + coordinates), and those errors add up like
        # a random walk: the landing resolves only to about sqrt(N) of them (measured: up to 1x
        # on curves 1 m from the origin); ask no more, but never accept less than
        # LANDING_REL_MAX.
        noise = EPS * (total + max(abs(float(x)) for x in self.end_point)) * math.sqrt(n)
        tol = max(LANDING_REL_TOL * last_ds, min(noise, LANDING_REL_MAX * last_ds))
        r = self.run(sigma)
        runs = 1.0
        if abs(r) > tol and r < 0.0 and self.bump is not None:
            landed = self._land_bump(self.bump, sigma, r, self.past_end, tol)
            if landed is not None:
                slowdown, bump_runs = landed
                return Landing(sigma, self.bump, slowdown, runs + bump_runs)
            r = self.run(sigma)  # the bump could not land: back to the plain run
            runs += 1.0
        # d(residual)/d(sigma) ~ -total: Newton, then secant steps, never above 1 (that would
        # raise the speed). A resident stretch keeps the best run after the first aside, so
        # that a last run that made things worse (rounding) costs a copy back. The sigmas run
        # bracket the root (below it: r > 0 before the end; above: r < 0 or past the end), and
        # a step out of the bracket bisects it instead: where the steps run out of curve
        # (control points coincide at the end) r is flat above the root, and a secant through
        # two such runs once proposed sigma = -0.008, a stretch that never moved.
        sigma_prev, r_prev = sigma, r
        bracket = [0.0, 1.0 if self.past_end or r < 0.0 else math.inf]
        best = (self.past_end, abs(r), sigma)  # a run past the end ranks below any other
        kept = None
        sigma = _within(min(sigma + r / total, 1.0), bracket)
        while abs(r_prev) > tol or best[0]:
            r = self.run(sigma)
            runs += 1.0
            if self.past_end or r < 0.0:
                bracket[1] = min(bracket[1], sigma)
            else:
                bracket[0] = max(bracket[0], sigma)
            improved = (self.past_end, abs(r)) < best[:2]
            if improved:
                best = (self.past_end, abs(r), sigma)
            # stop at the tolerance, or where the residual stops improving: below ~1e-11 mm it
            # is rounding (and branch switches inside the kernel), not a function of sigma
            if ((abs(r) <= tol and not self.past_end) or runs >= LANDING_MAX_RUNS
                    or r == r_prev or not improved):
                break
            if self.resident:
                kept = (sigma, self.u[:n].copy(), self.pts[:n].copy())
            sigma, sigma_prev, r_prev = (
                _within(min(sigma - r * (sigma - sigma_prev) / (r - r_prev), 1.0), bracket),
                sigma, r)
        if sigma != best[2]:  # the last run was not the best one: back to the best
            sigma = best[2]
            if kept is not None and kept[0] == sigma:
                self.u[:n], self.pts[:n] = kept[1], kept[2]
                self.past_end = best[0]
            else:
                self.run(sigma)
                runs += 1.0
        # The residual is monotone in sigma, so the search above ends before the end; should it
        # not (a kernel branch switching with sigma), lower sigma (a little slower) until the
        # point lies before the end: by twice the overshoot's arc, then twice that again.
        cut = 2.0 * best[1] / total
        for _ in range(LANDING_MAX_RUNS):
            if not self.past_end:
                break
            sigma *= 1.0 - min(max(cut, 16.0 * EPS), 0.5)
            self.run(sigma)
            runs += 1.0
            cut *= 2.0
        if self.past_end:
            # a bug, not bad input: the command line reports it as an internal error
            raise RuntimeError(f"the landing leaves point {n - 1} of a stretch on or past its "
                               f"end u = {self.u_end!r}")
        return Landing(sigma, None, 0.0, runs)

    def _land_bump(self, bump: _Bump, sigma: float, r_full: float, past_full: bool,
                   tol: float) -> tuple[float, float] | None:
        """Step 2 of the landing: the depth e of the bump that takes out the overshoot r_full < 0
        of the full run, by a secant search over runs from the bump's first point on (the best
        run where rounding stops it short of the tolerance). Returns e and the runs (as a share
        of the full run), or None if e would exceed BUMP_MAX_SLOWDOWN or no bump does better
        than none or leaves the point past the end (past_full: the full run's does)."""
        share = (self.n - 1 - bump.k0) / (self.n - 1)
        # r rises by sigma * (arc taken out): exactly sigma * v_c D / 2 per unit of e
        e_prev, r_prev = 0.0, r_full
        e = -r_full / (sigma * float(bump.taken.sum()))
        best = (past_full, abs(r_full), 0.0)  # a run past the end ranks below any other
        runs = 0.0
        for _ in range(LANDING_MAX_RUNS):
            if not 0.0 < e <= BUMP_MAX_SLOWDOWN:
                return None
            r = self.run(sigma, e, from_bump=True)
            runs += share
            if (self.past_end, abs(r)) < best[:2]:
                best = (self.past_end, abs(r), e)
            # stop at the tolerance, or where the residual stops improving (rounding)
            if (abs(r) <= tol and not self.past_end) or r == r_prev or abs(r) >= abs(r_prev):
                break
            e, e_prev, r_prev = e - r * (e - e_prev) / (r - r_prev), e, r
        if best[2] == 0.0 or best[0]:  # no bump did better than none, or none lands before the end
            return None
        if e != best[2]:
            e = best[2]
            self.run(sigma, e, from_bump=True)
            runs += share
        return e, runs

    def points(self, landing: Landing, end_u: float) -> Iterator[tuple[int, np.ndarray,
                                                                        np.ndarray, np.ndarray]]:
        """The landed stretch's points 1 .. n, in chunks (first index, u (M,), points (M, 3),
        targets into them (M,)): the last run's points, the end point (at end_u) last. A
        resident stretch hands out its last run; a longer one steps once more, chunk by chunk."""
        n, sigma, e = self.n, landing.sigma, landing.slowdown
        if self.resident:
            self.u[n] = end_u
            self.pts[n] = self.end_point
            yield 1, self.u[1:], self.pts[1:], sigma * self.targets(0, n, e)
            return
        k, u = 0, self.u_start
        while True:
            hi = min(k + self.chunk, n - 1)
            final = hi == n - 1
            m = hi - k
            ds = self.targets(k, hi + final, e)
            u_out = np.empty(m + 1 + final)
            p_out = np.empty((m + 1 + final, 3))
            self._step(u, ds[:m], sigma, u_out[:m + 1], p_out[:m + 1])
            if final:
                u_out[-1] = end_u
                p_out[-1] = self.end_point
            yield k + 1, u_out[1:], p_out[1:], sigma * ds
            if final:
                return
            u = float(u_out[m])
            k = hi


class Stepping:
    """One curve's interpolation, produced chunk by chunk (`chunks`): memory is bounded by
    CHUNK_PERIODS whatever the curve's duration. The landing figures (runs, the stretches' laws,
    `landed`) are complete once the chunks are exhausted.

    `landings`: how the stretches landed when this plan was stepped with this method before
    (a Stepping's `landed`): each stretch is stepped once with its landing instead of searching
    for it again, the same points to the last bit (`_Stretch.replay`), and `runs` counts the
    runs the search took then."""

    def __init__(self, plan: Plan, method: str = "rk2c",
                 landings: tuple[Landing, ...] | None = None) -> None:
        self.plan = plan
        self.method = method
        self.given = landings
        self.runs = 0.0
        self.stretches: list[_StretchLaw] = []
        self.landings: list[Landing] = []
        self.done = False  # the chunks are exhausted
        self.start_jerk_mm_s3 = 0.0

    @property
    def landed(self) -> tuple[Landing, ...] | None:
        """How every stretch landed, in order, once the chunks are exhausted (None before)."""
        return tuple(self.landings) if self.done else None

    def chunks(self) -> Iterator[PointChunk]:
        """The curve's points in order: its first point alone, then every stretch between rests
        (stepped and landed as a whole first: its points are only known once it has landed)."""
        plan = self.plan
        curve, law = plan.curve, plan.law
        code = METHODS[self.method]
        mean_speed = plan.length_mm / (curve.u_max - curve.u_min)
        slow = SLOW_SPEED_REL * mean_speed
        moving = [p for p in range(len(plan.piece_periods)) if plan.piece_periods[p] > 0]
        # at rest at the start (and at every stretch start): v = a = 0, the jerk of the first
        # piece
        first_j = float(law.jerk_mm_s3[0]) if law.jerk_mm_s3.size else 0.0
        first_scale = float(plan.piece_scale[0]) if plan.piece_scale.size else 1.0
        start_u = float(plan.key_u[plan.piece_key[moving[0]]]) if moving else curve.u_min
        k0 = 0  # index of the stretch's first point
        for i, p in enumerate(moving):
            stretch = _Stretch(plan, p, code, slow, CHUNK_PERIODS)
            if self.given is not None:
                landing = self.given[i]
                stretch.replay(landing)
            else:
                sigma = 1.0
                if code == METHODS["rk2c"] and stretch.total > 0.0:
                    sigma = min(1.0, 1.0 - stretch.drift / stretch.total + LANDING_MARGIN_REL)
                landing = stretch.land(sigma)
            self.landings.append(landing)
            self.runs += landing.runs
            st = _StretchLaw(k0, stretch.n, law, stretch.t_a, stretch.t_b,
                             float(plan.piece_scale[p]), landing.sigma, landing.bump,
                             landing.slowdown)
            self.stretches.append(st)
            if i == 0:
                self.start_jerk_mm_s3 = landing.sigma * first_j / first_scale**3
                yield self._first_point(start_u)
            # a stretch's last point is where the next one starts stepping from
            end_u = (float(plan.key_u[plan.piece_key[moving[i + 1]]]) if i + 1 < len(moving)
                     else stretch.u_end)
            for local, u, pts, ds in stretch.points(landing, end_u):
                yield PointChunk(k0 + local, u, pts, ds, st, local, self.start_jerk_mm_s3)
            k0 += stretch.n
        if not moving:
            self.start_jerk_mm_s3 = first_j / first_scale**3
            yield self._first_point(start_u)
        self.done = True

    def _first_point(self, u: float) -> PointChunk:
        return PointChunk(0, np.array([u]), np.array(self.plan.curve.points[:1], dtype=float),
                          np.zeros(1), None, 0, self.start_jerk_mm_s3)


def interpolate(plan: Plan, method: str = "rk2c") -> Interpolation:
    """Step along the planned curve with `method`, into whole-curve arrays (for the analyses;
    a conversion streams `Stepping.chunks` instead); see the module docstring."""
    stepping = Stepping(plan, method)
    chunks = list(stepping.chunks())
    u = np.concatenate([c.u for c in chunks])
    points = np.concatenate([c.points for c in chunks])
    ds = np.concatenate([c.ds_mm for c in chunks])[1:]
    return Interpolation(method, plan.limits.period_s, u, points, ds, stepping.runs,
                         tuple(stepping.stretches), stepping.start_jerk_mm_s3)
