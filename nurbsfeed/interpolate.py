"""The real-time stage (SPEC §3): from the time law's per-period targets to curve parameters.

All three methods consume the same targets ds_k = s(t_{k+1}) - s(t_k), t_k = k T:
  taylor1  u+ = u + ds / |C'(u)|
  rk4      classical RK4 on du/ds = 1/|C'(u)| over the step ds (4 derivative evaluations)
  rk2c     the paper's method (Eq. 3-13): K1 = 1/|C'(u)|, K2 = 1/|C'(u + ds K1)|,
           u~ = u + ds (K1 + K2)/2, then the correction du that makes the chord |C(u~ + du) - C(u)|
           equal ds to first order: c1 du^2 + c2 du + c3 = 0 with c1 = |C'(u~)|^2,
           c2 = 2 C'(u~).(C(u~) - C(u)), c3 = |C(u~) - C(u)|^2 - ds^2. The root near zero,
           (-c2 + sqrt(disc)) / (2 c1), is computed as -2 c3 / (c2 + sqrt(disc)) (same root, no
           cancellation); du = 0 when disc < 0 (the paper's rule).
Where |C'(u)| vanishes (repeated control points, SPEC §3a) a step solves the chord equation
|C(u + du) - C(u)| = ds directly instead of dividing by |C'|; rk2c and rk4 also do so when |C'|
changes by more than a quarter within the step, which only happens right next to such a point.

End landing: rk2c makes every chord equal to its target, so its arc position runs ahead of the
time law and the last step would overshoot the end. All targets are scaled by one factor
sigma <= 1, found by a secant search so that the last chord, from the last stepped point to the
curve end, equals its own target; sigma only lowers speed, acceleration and jerk. The last point
is the curve end exactly.
Where the plan rests inside the curve (a corner), each stretch between rests is stepped and
landed on its own, so a point falls exactly on the corner.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.kernel import eval_d1, find_span
from nurbsfeed.jit import jit
from nurbsfeed.planning.planner import Plan

METHODS = {"taylor1": 0, "rk4": 1, "rk2c": 2}
SLOW_SPEED_REL = 1e-3  # |C'| below this fraction of the mean |C'| is treated as "zero"
# rk2c / rk4: when |C'| changes by more than this fraction across one step, the step is next to
# a point where C' = 0 and the Taylor-based update is not valid there: solve the chord instead.
STEP_SPEED_CHANGE_MAX = 0.25
LANDING_REL_TOL = 1e-6  # of the last target: the last chord matches it to 1e-4 %
LANDING_ULPS = 16
LANDING_MAX_RUNS = 8
CHORD_ITERATIONS = 200


@jit
def _chord_step(knots, cw, degree, n_ctrl, u, px, py, pz, ds, guess, span,
                basis, dbasis, left, right, p_tmp, d_tmp):
    """The du > 0 with |C(u + du) - P| = ds, by bracketing and Illinois regula falsi."""
    lo = 0.0
    g_lo = -ds
    hi = guess
    g_hi = -ds
    for _ in range(CHORD_ITERATIONS):
        span = find_span(knots, degree, n_ctrl, u + hi, span)
        eval_d1(knots, cw, degree, u + hi, span, basis, dbasis, left, right, p_tmp, d_tmp)
        g_hi = math.sqrt((p_tmp[0] - px) ** 2 + (p_tmp[1] - py) ** 2
                         + (p_tmp[2] - pz) ** 2) - ds
        if g_hi >= 0.0:
            break
        lo = hi
        g_lo = g_hi
        hi *= 2.0
    side = 0
    for _ in range(CHORD_ITERATIONS):
        if hi - lo <= 1e-16 * (abs(u) + hi) or g_hi == g_lo:
            break
        x = (lo * g_hi - hi * g_lo) / (g_hi - g_lo)
        span = find_span(knots, degree, n_ctrl, u + x, span)
        eval_d1(knots, cw, degree, u + x, span, basis, dbasis, left, right, p_tmp, d_tmp)
        g = math.sqrt((p_tmp[0] - px) ** 2 + (p_tmp[1] - py) ** 2 + (p_tmp[2] - pz) ** 2) - ds
        if g == 0.0:
            return x
        if g < 0.0:
            lo = x
            g_lo = g
            if side == -1:
                g_hi *= 0.5
            side = -1
        else:
            hi = x
            g_hi = g
            if side == 1:
                g_lo *= 0.5
            side = 1
    return lo if -g_lo < g_hi else hi


@jit
def step_curve(method, knots, cw, degree, n_spans, u0, ds, sigma, slow_speed, u_out, p_out):
    """Step from u0 through the targets sigma * ds (N,): u_out (N+1,), p_out (N+1, 3) = C(u_k).

    Spans past index n_spans - 1 are not used: beyond the end of the stretch the last span's
    polynomial extrapolates, so the landing search sees a smooth continuation even at a corner.
    """
    n_ctrl = n_spans
    basis = np.empty(degree + 1)
    dbasis = np.empty(degree + 1)
    left = np.empty(degree + 1)
    right = np.empty(degree + 1)
    p = np.empty(3)
    d = np.empty(3)
    pt = np.empty(3)
    dt = np.empty(3)
    u_range = knots[knots.size - 1] - knots[0]
    u = u0
    span = find_span(knots, degree, n_ctrl, u, degree)
    for k in range(ds.size + 1):
        span = find_span(knots, degree, n_ctrl, u, span)
        eval_d1(knots, cw, degree, u, span, basis, dbasis, left, right, p, d)
        u_out[k] = u
        p_out[k, 0] = p[0]
        p_out[k, 1] = p[1]
        p_out[k, 2] = p[2]
        if k == ds.size:
            break
        h = sigma * ds[k]
        speed = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
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
                eval_d1(knots, cw, degree, u + 0.5 * h * k1, s2, basis, dbasis, left, right, pt, dt)
                sp2 = math.sqrt(dt[0] * dt[0] + dt[1] * dt[1] + dt[2] * dt[2])
                s3 = find_span(knots, degree, n_ctrl, u + 0.5 * h / sp2, s2)
                eval_d1(knots, cw, degree, u + 0.5 * h / sp2, s3, basis, dbasis, left, right, pt, dt)
                sp3 = math.sqrt(dt[0] * dt[0] + dt[1] * dt[1] + dt[2] * dt[2])
                s4 = find_span(knots, degree, n_ctrl, u + h / sp3, s3)
                eval_d1(knots, cw, degree, u + h / sp3, s4, basis, dbasis, left, right, pt, dt)
                sp4 = math.sqrt(dt[0] * dt[0] + dt[1] * dt[1] + dt[2] * dt[2])
                slow = (sp2 < slow_speed or sp3 < slow_speed or sp4 < slow_speed
                        or abs(1.0 - speed / sp4) > STEP_SPEED_CHANGE_MAX)
                if not slow:
                    u = u + h * (k1 + 2.0 / sp2 + 2.0 / sp3 + 1.0 / sp4) / 6.0
                    continue
            else:
                s2 = find_span(knots, degree, n_ctrl, u + h * k1, span)
                eval_d1(knots, cw, degree, u + h * k1, s2, basis, dbasis, left, right, pt, dt)
                sp2 = math.sqrt(dt[0] * dt[0] + dt[1] * dt[1] + dt[2] * dt[2])
                slow = sp2 < slow_speed or abs(1.0 - speed / sp2) > STEP_SPEED_CHANGE_MAX
                if not slow:
                    ut = u + 0.5 * h * (k1 + 1.0 / sp2)
                    s3 = find_span(knots, degree, n_ctrl, ut, s2)
                    eval_d1(knots, cw, degree, ut, s3, basis, dbasis, left, right, pt, dt)
                    ex = pt[0] - p[0]
                    ey = pt[1] - p[1]
                    ez = pt[2] - p[2]
                    c1 = dt[0] * dt[0] + dt[1] * dt[1] + dt[2] * dt[2]
                    c2 = 2.0 * (dt[0] * ex + dt[1] * ey + dt[2] * ez)
                    c3 = ex * ex + ey * ey + ez * ez - h * h
                    disc = c2 * c2 - 4.0 * c1 * c3
                    du = 0.0
                    if disc >= 0.0:
                        den = c2 + math.sqrt(disc)
                        if den > 0.0:
                            du = -2.0 * c3 / den
                    u = ut + du
                    continue
        guess = h / slow_speed if speed < slow_speed else h / speed
        guess = min(guess, u_range)
        u = u + _chord_step(knots, cw, degree, n_ctrl, u, p[0], p[1], p[2], h, guess, span,
                            basis, dbasis, left, right, pt, dt)


@dataclass(frozen=True, eq=False)
class Interpolation:
    """One curve's interpolation points. (N+1,) arrays except points (N+1, 3) and ds (N,)."""

    method: str
    period_s: float
    u: np.ndarray
    points: np.ndarray  # C(u_k), full precision; first and last exactly the curve ends
    t_s: np.ndarray
    s_mm: np.ndarray  # sigma * s(t_k): the targets actually stepped
    v_mm_s: np.ndarray
    a_mm_s2: np.ndarray
    j_mm_s3: np.ndarray
    ds_mm: np.ndarray  # sigma * targets, (N,)
    sigma: np.ndarray  # (P,) target scale of each stretch between rests
    landing_runs: int  # kernel runs over all stretches
    step_seconds: float  # wall time of the final kernel run of every stretch

    @property
    def n_points(self) -> int:
        return self.u.size

    def feed_fluctuation(self) -> np.ndarray:
        """SPEC §3 / Table 2: | |P_{k+1} - P_k| - ds_k | / ds_k for every full period: (N,)."""
        chord = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ff = np.abs(chord - self.ds_mm) / self.ds_mm
        return ff[self.ds_mm > 0]


@dataclass(frozen=True)
class _Stretch:
    """The result of stepping one stretch between two rests."""

    u: np.ndarray
    points: np.ndarray
    ds_mm: np.ndarray
    sigma: float
    runs: int
    seconds: float


def _step_stretch(curve, code: int, u_start: float, u_end: float, end_point: np.ndarray,
                  ds: np.ndarray, slow: float, sigma_guess: float) -> _Stretch:
    """Step from u_start through ds (N,) and land exactly on end_point.

    The kernel makes the first N-1 steps with targets sigma * ds; the last point is end_point
    itself, and sigma is found by a secant search so that the last chord, |end - P_{N-1}|,
    equals its target sigma * ds[-1]. That residual is continuous and monotone in sigma even
    where C' vanishes at the end (the curve folds back there when extrapolated).
    """
    n = ds.size
    u = np.empty(n + 1)
    pts = np.empty((n + 1, 3))
    total = float(ds.sum())
    knots, cw = curve.knots, curve.homogeneous
    head = ds[:-1]
    n_spans = int(np.searchsorted(knots, u_end, side="left"))  # last span ends at u_end
    # sigma resolves the landing only to about eps * (length + coordinates): ask no more
    noise = LANDING_ULPS * np.finfo(float).eps * (total + float(np.max(np.abs(end_point))))
    tol = max(LANDING_REL_TOL * float(ds[-1]), noise)

    def run(sigma: float) -> float:
        step_curve(code, knots, cw, curve.degree, n_spans, u_start, head, sigma, slow,
                   u[:-1], pts[:-1])
        gap = float(np.linalg.norm(end_point - pts[-2]))
        return (gap if u[-2] <= u_end else -gap) - sigma * float(ds[-1])

    # d(residual)/d(sigma) ~ -total: a Newton step from the guess, then secant steps
    sigma_prev, r_prev = sigma_guess, run(sigma_guess)
    best = (abs(r_prev), sigma_guess)
    sigma, runs, seconds = sigma_guess + r_prev / total, 1, 0.0
    while abs(r_prev) > tol:
        start = time.perf_counter()
        r = run(sigma)
        seconds = time.perf_counter() - start
        runs += 1
        improved = abs(r) < best[0]
        if improved:
            best = (abs(r), sigma)
        # stop at the tolerance, or where the residual stops improving: below ~1e-12 mm it
        # is rounding (and branch switches inside the kernel), not a function of sigma
        if abs(r) <= tol or runs >= LANDING_MAX_RUNS or r == r_prev or not improved:
            break
        sigma, sigma_prev, r_prev = sigma - r * (sigma - sigma_prev) / (r - r_prev), sigma, r
    if sigma != best[1]:  # the last run was not the best one: step the best sigma again
        sigma = best[1]
        run(sigma)
        runs += 1
    u[-1] = u_end
    pts[-1] = end_point
    return _Stretch(u, pts, sigma * ds, sigma, runs, seconds)


def _sigma_guess(plan: Plan, method: str, t_plan: np.ndarray, ds: np.ndarray) -> float:
    """Where the landing search starts. rk2c steps chords of length ds, so it runs ahead of the
    arc by sum(kappa^2 ds^3 / 24) (arc minus chord of a circular arc); rk4 follows the arc itself
    and taylor1's drift has no cheap estimate, so both start from 1."""
    if method != "rk2c":
        return 1.0
    s_mid = plan.law.at(0.5 * (t_plan[:-1] + t_plan[1:]))[0]
    kappa = np.interp(s_mid, plan.grid.s_mm, plan.grid.kappa_1_mm)
    total = float(ds.sum())
    ahead = float(np.sum(np.minimum(kappa * ds, 2.0) ** 2 * ds)) / 24.0
    return 1.0 - ahead / total if total > 0.0 else 1.0


def interpolate(plan: Plan, method: str = "rk2c") -> Interpolation:
    """Step along the planned curve with `method`; see the module docstring."""
    curve = plan.curve
    law = plan.law
    period = plan.limits.period_s
    code = METHODS[method]
    mean_speed = plan.length_mm / (curve.u_max - curve.u_min)
    slow = SLOW_SPEED_REL * mean_speed
    key_u = plan.key_u
    us, pts, dss, ts, vs, accs, jerks, sigmas = ([curve.u_min], [curve.points[:1]], [], [0.0],
                                                 [], [], [], [])
    runs, seconds = 0, 0.0
    for p in range(len(plan.piece_periods)):
        n = int(plan.piece_periods[p])
        k0, k1 = plan.piece_key[p], plan.piece_key[p + 1]
        if n == 0:
            continue
        t_a, t_b = law.key_t_s[k0], law.key_t_s[k1]
        # plan time of period k of this stretch: t_a + k (t_b - t_a) / n, exact at both ends
        t_plan = t_a + np.arange(n + 1, dtype=float) * ((t_b - t_a) / n)
        t_plan[-1] = t_b
        ds = law.increments(t_plan)
        last = p == len(plan.piece_periods) - 1
        end_point = curve.points[-1] if last else curve.point(key_u[k1])
        stretch = _step_stretch(curve, code, float(key_u[k0]), float(key_u[k1]),
                                np.asarray(end_point, dtype=float), ds, slow,
                                _sigma_guess(plan, method, t_plan, ds))
        runs += stretch.runs
        seconds += stretch.seconds
        scale = float(plan.piece_scale[p])
        _, v, a, j = law.at(t_plan[1:])
        us.append(stretch.u[1:])
        pts.append(stretch.points[1:])
        dss.append(stretch.ds_mm)
        vs.append(stretch.sigma * v / scale)
        accs.append(stretch.sigma * a / scale**2)
        jerks.append(stretch.sigma * np.broadcast_to(j, v.shape) / scale**3)
        sigmas.append(stretch.sigma)
    ds_all = np.concatenate(dss) if dss else np.zeros(0)
    u_all = np.concatenate([np.asarray(x, dtype=float).ravel() for x in us])
    points = np.concatenate(pts)
    points[0] = curve.points[0]
    n_all = u_all.size
    s_all = np.concatenate([[0.0], np.cumsum(ds_all)])
    # at rest at the start (and at every stretch start): v = a = 0, the jerk of the first piece
    first_j = float(law.jerk_mm_s3[0]) if law.jerk_mm_s3.size else 0.0
    first_scale = float(plan.piece_scale[0]) if plan.piece_scale.size else 1.0
    first_sigma = sigmas[0] if sigmas else 1.0
    v_all = np.concatenate([[0.0]] + vs)
    a_all = np.concatenate([[0.0]] + accs)
    j_all = np.concatenate([[first_sigma * first_j / first_scale**3]] + jerks)
    return Interpolation(method, period, u_all, points, np.arange(n_all, dtype=float) * period,
                         s_all, v_all, a_all, j_all, ds_all, np.array(sigmas), runs, seconds)
