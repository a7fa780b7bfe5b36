"""The stepping kernels: one loop over a stretch's targets, ds_k = s(t_{k+1}) - s(t_k), t_k = k T,
from u_k to u_k+1 (called by interpolate.landing, which chooses the targets' scale).

All three methods consume the same targets:
  taylor1  u+ = u + ds / |C'(u)|
  rk4      classical RK4 on du/ds = 1/|C'(u)| over the step ds (4 derivative evaluations)
  rk2c     the paper's method (Eq. 3-13): K1 = 1/|C'(u)|, K2 = 1/|C'(u + ds K1)|,
           u~ = u + ds (K1 + K2)/2, then the correction du that makes the chord |C(u~ + du) - C(u)|
           equal ds to first order: c1 du^2 + c2 du + c3 = 0 with c1 = |C'(u~)|^2,
           c2 = 2 C'(u~).(C(u~) - C(u)), c3 = |C(u~) - C(u)|^2 - ds^2. The root near zero,
           (-c2 + sqrt(disc)) / (2 c1), is computed as -2 c3 / (c2 + sqrt(disc)) (same root, no
           cancellation); du = 0 when disc < 0 (the paper's rule).
Where |C'(u)| vanishes (repeated control points, design §3a), where |C'| changes by more than a
quarter within a step (right next to such a point), or where the tangent turns by more than 60
degrees within it (a hairpin), the loop hands the step back to `step_spans`, which solves it in
interpolate.solved_steps (`leg_step`); likewise a chord rk2c leaves off its target across a knot
(`chord_step`).
"""

from __future__ import annotations

import math

from nurbsfeed.choices import METHOD_NAMES
from nurbsfeed.geometry import kernel
from nurbsfeed.interpolate.solved_steps import chord_step, leg_step
from nurbsfeed.jit import compiles_large, inline, jit

# `_step_run` evaluates the curve up to six times a step: compiled into the loop, not called
find_span = inline(kernel.find_span)
point_d1 = inline(kernel.point_d1)

METHODS = {name: code for code, name in enumerate(METHOD_NAMES)}  # name -> kernel code
# what `_step_run` stopped for: the end, or a step it hands back to `chord_step` or `leg_step`
STEP_DONE, STEP_CHORD, STEP_LEG = 0, 1, 2
SLOW_SPEED_REL = 1e-3  # |C'| below this fraction of the mean |C'| is treated as "zero"
# rk2c / rk4: when |C'| changes by more than this fraction across one step, the step is next to
# a point where C' = 0 and the Taylor-based update is not valid there: solve the chord instead.
STEP_SPEED_CHANGE_MAX = 0.25
# rk2c / rk4: when the tangent turns by more than 60 degrees across one step (cos below this),
# the step rounds a hairpin whose |C'| dips and rises again alike on its two legs (unseen by the
# speed change): the chord there is far shorter than the arc, and the chord correction lands on
# the far leg. Solve the arc instead.
STEP_TURN_COS_MIN = 0.5
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


def step_spans(method, knots, coef, degree, n_spans, u0, ds, sigma, slow_speed, u_out, p_out):
    """Step from u0 through the targets sigma * ds (N,): u_out (N+1,), p_out (N+1, 3) = C(u_k).

    coef: the curve's span polynomials (geometry.kernel.span_polynomials). Spans past index
    n_spans - 1 are not used: beyond the end of the stretch the last span's polynomial
    extrapolates, so the landing search sees a smooth continuation even at a corner.

    The stepping loop is compiled (`_step_run`); the steps it cannot take itself (a chord
    solved exactly across a knot, `chord_step`; a step beside a point where C' vanishes,
    `leg_step`) it hands back, and they are taken here. Those kernels, and the arc-length
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
            u = u + chord_step(knots, coef, degree, n_spans, u, px, py, pz, h, 0.0, guess, span)
        else:
            u = u + leg_step(knots, coef, degree, n_spans, u, px, py, pz, h, guess, span)
        k += 1


@compiles_large(40.0)  # its inlined evaluations: 29-34 MB more at the peak of its compilation
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
        # from positions, a landing residual jumping with sigma). `leg_step` keeps to the
        # leg the arc reaches.
        guess = h / slow_speed if speed < slow_speed else h / speed
        return k, STEP_LEG, min(guess, u_range), span
    return ds.size, STEP_DONE, 0.0, span
