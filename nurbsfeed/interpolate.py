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
stops them improving (then the best run stands).
Where the plan rests inside the curve (a corner), each stretch between rests is stepped and
landed on its own, so a point falls exactly on the corner.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nurbsfeed.geometry.kernel import find_span, point_d1, span_polynomials
from nurbsfeed.jit import jit
from nurbsfeed.planning.planner import Plan
from nurbsfeed.planning.timelaw import evaluate

METHODS = {"taylor1": 0, "rk4": 1, "rk2c": 2}
SLOW_SPEED_REL = 1e-3  # |C'| below this fraction of the mean |C'| is treated as "zero"
# rk2c / rk4: when |C'| changes by more than this fraction across one step, the step is next to
# a point where C' = 0 and the Taylor-based update is not valid there: solve the chord instead.
STEP_SPEED_CHANGE_MAX = 0.25
LANDING_REL_TOL = 1e-6  # of the last target: the last chord matches it to 1e-4 % ...
LANDING_REL_MAX = 5e-6  # ... or, where rounding does not resolve that, to half rk2c's 1e-5
LANDING_MAX_RUNS = 8
LANDING_MARGIN_REL = 1e-8  # the first run's sigma lies this far (relative) above the estimate
BUMP_PERIODS = 32
BUMP_MAX_SLOWDOWN = 1e-4
CHORD_ITERATIONS = 200
EPS = float(np.finfo(float).eps)


@jit
def _chord_step(knots, coef, degree, n_ctrl, u, px, py, pz, ds, guess, span):
    """The du > 0 with |C(u + du) - P| = ds, by bracketing and Illinois regula falsi."""
    lo = 0.0
    g_lo = -ds
    hi = guess
    g_hi = -ds
    for _ in range(CHORD_ITERATIONS):
        span = find_span(knots, degree, n_ctrl, u + hi, span)
        cx, cy, cz, _, _, _ = point_d1(knots, coef, degree, span, u + hi)
        g_hi = math.sqrt((cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2) - ds
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
        cx, cy, cz, _, _, _ = point_d1(knots, coef, degree, span, u + x)
        g = math.sqrt((cx - px) ** 2 + (cy - py) ** 2 + (cz - pz) ** 2) - ds
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
def step_spans(method, knots, coef, degree, n_spans, u0, ds, sigma, slow_speed, u_out, p_out):
    """Step from u0 through the targets sigma * ds (N,): u_out (N+1,), p_out (N+1, 3) = C(u_k).

    coef: the curve's span polynomials (geometry.kernel.span_polynomials). Spans past index
    n_spans - 1 are not used: beyond the end of the stretch the last span's polynomial
    extrapolates, so the landing search sees a smooth continuation even at a corner.
    """
    n_ctrl = n_spans
    u_range = knots[knots.size - 1] - knots[0]
    u = u0
    span = find_span(knots, degree, n_ctrl, u, degree)
    for k in range(ds.size + 1):
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
                        or abs(1.0 - speed / sp4) > STEP_SPEED_CHANGE_MAX)
                if not slow:
                    u = u + h * (k1 + 2.0 / sp2 + 2.0 / sp3 + 1.0 / sp4) / 6.0
                    continue
            else:
                s2 = find_span(knots, degree, n_ctrl, u + h * k1, span)
                _, _, _, tx, ty, tz = point_d1(knots, coef, degree, s2, u + h * k1)
                sp2 = math.sqrt(tx * tx + ty * ty + tz * tz)
                slow = sp2 < slow_speed or abs(1.0 - speed / sp2) > STEP_SPEED_CHANGE_MAX
                if not slow:
                    ut = u + 0.5 * h * (k1 + 1.0 / sp2)
                    s3 = find_span(knots, degree, n_ctrl, ut, s2)
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
                    u = ut + du
                    continue
        guess = h / slow_speed if speed < slow_speed else h / speed
        guess = min(guess, u_range)
        u = u + _chord_step(knots, coef, degree, n_ctrl, u, px, py, pz, h, guess, span)


@jit
def step_curve(method, knots, cw, degree, n_spans, u0, ds, sigma, slow_speed, u_out, p_out):
    """`step_spans` for a curve given by its homogeneous control points cw (n+1, 4)."""
    step_spans(method, knots, span_polynomials(knots, cw, degree), degree, n_spans, u0, ds,
               sigma, slow_speed, u_out, p_out)


@dataclass(frozen=True, eq=False)
class Interpolation:
    """One curve's interpolation points. (N+1,) arrays except points (N+1, 3) and ds (N,)."""

    method: str
    period_s: float
    u: np.ndarray
    points: np.ndarray  # C(u_k), full precision; first and last exactly the curve ends
    ds_mm: np.ndarray  # the targets actually stepped, (N,)
    landing_runs: float  # kernel runs over all stretches, a run from a bump on in its share
    step_seconds: float  # wall time of the last full kernel run of every stretch
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
        """v, a, j of the law at the points, scaled like the targets stepped (sigma, and the
        stretch's scale), with the landing bump's own; at rest at every stretch start."""
        v_all = np.zeros(self.n_points)
        a_all = np.zeros(self.n_points)
        j_all = np.zeros(self.n_points)
        for st in self.stretches:
            v, a, j = st.v[1:], st.a[1:], st.j[1:]
            if st.bump is not None:  # the bump's own v, a, j at its points (see _Bump)
                bump = slice(st.bump.k0, st.bump.k0 + st.bump.periods)
                vw, aw, jw = st.bump.shape(st.t_plan[1:][bump])
                v, a, j = v.copy(), a.copy(), j.copy()
                v[bump] -= st.slowdown * vw
                a[bump] -= st.slowdown * aw
                j[bump] -= st.slowdown * jw
            span = slice(st.k0 + 1, st.k0 + v.size + 1)
            v_all[span] = st.sigma * v / st.scale
            a_all[span] = st.sigma * a / st.scale**2
            j_all[span] = st.sigma * j / st.scale**3
        j_all[0] = self.start_jerk_mm_s3
        for arr in (v_all, a_all, j_all):
            arr.setflags(write=False)
        return v_all, a_all, j_all

    def feed_fluctuation(self) -> np.ndarray:
        """SPEC §3 / Table 2: | |P_{k+1} - P_k| - ds_k | / ds_k for every full period: (N,)."""
        chord = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ff = np.abs(chord - self.ds_mm) / self.ds_mm
        return ff[self.ds_mm > 0]


@jit
def _sample_stretch(t0, s0, v0, a0, jk, t_a, t_b, n, grid_s, grid_kappa, with_drift):
    """The law over a stretch of n periods from plan time t_a to t_b: the plan times (N+1,)
    t_a + k (t_b - t_a) / n (t_b exactly at the end), v, a, j there (N+1,), the targets ds (N,)
    and, if with_drift, how far rk2c's arc position will run ahead of them (else 0).

    ds_k = s(t_k+1) - s(t_k) is taken piece by piece (the pieces' starts s0 differ, then the
    arcs within them), so that a tiny step far along the curve keeps its relative precision.
    The drift is sum(min(kappa ds, 2)^2 ds) / 24, the arc minus the chord of a circular arc of
    curvature kappa per step, with kappa at the middle of each step interpolated linearly on
    the grid (grid_s, grid_kappa (M,)); beside a corner (kappa infinite) from its finite side.
    """
    t_plan = np.empty(n + 1)
    step = (t_b - t_a) / n
    for k in range(n):
        t_plan[k] = t_a + k * step
    t_plan[n] = t_b
    piece = np.empty(n + 1, dtype=np.int64)
    local = np.empty(n + 1)
    v = np.empty(n + 1)
    a = np.empty(n + 1)
    j = np.empty(n + 1)
    evaluate(t0, s0, v0, a0, jk, t_plan, piece, local, v, a, j)
    ds = np.empty(n)
    for k in range(n):
        ds[k] = (s0[piece[k + 1]] - s0[piece[k]]) + (local[k + 1] - local[k])
    drift = 0.0
    if with_drift:
        last = grid_s.size - 1
        node = 0
        for k in range(n):
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
        drift /= 24.0
    return t_plan, ds, v, a, j, drift


@dataclass(frozen=True)
class _Bump:
    """The landing bump over periods k0 .. k0 + periods of a stretch (see the module docstring):
    the law's speed v_c there is lowered by e v_c w(t), w = sin^2(pi x / D), x = t - t_start,
    in plan time."""

    k0: int
    periods: int
    t_start: float
    duration: float  # D
    v_mm_s: float  # v_c

    def removed(self, t_s: np.ndarray) -> np.ndarray:
        """Arc taken out by plan time t (per unit of e): v_c integral of w, (M,) -> (M,)."""
        x = np.minimum(np.maximum(t_s - self.t_start, 0.0), self.duration)
        d = self.duration
        return self.v_mm_s * (0.5 * x - d / (4.0 * math.pi) * np.sin(2.0 * math.pi * x / d))

    def shape(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """v_c w, v_c w' and v_c w'' at plan times (M,) inside the bump."""
        phase = 2.0 * math.pi * (t_s - self.t_start) / self.duration
        w = 0.5 * (1.0 - np.cos(phase))
        w1 = math.pi / self.duration * np.sin(phase)
        w2 = 2.0 * (math.pi / self.duration) ** 2 * np.cos(phase)
        return self.v_mm_s * w, self.v_mm_s * w1, self.v_mm_s * w2


@dataclass(frozen=True, eq=False)
class _StretchLaw:
    """The law over one stretch between rests as it was stepped: points k0 .. k0 + N of the
    curve; the plan times, v, a, j (N+1,) from `_sample_stretch` (the bump not yet in them);
    the stretch's time scale, its sigma, its landing bump and that bump's depth."""

    k0: int
    t_plan: np.ndarray
    v: np.ndarray
    a: np.ndarray
    j: np.ndarray
    scale: float
    sigma: float
    bump: _Bump | None
    slowdown: float


@jit
def _last_flat_periods(t0, a0, jk, v0, duration, t_plan, periods):
    """The first period k0 of the stretch's (t_plan (N+1,)) last `periods` periods that lie in
    one piece of the law that cruises or holds (a = j = 0, v > 0), all before the stretch's
    last period; the piece's speed. (-1, 0) if there are none."""
    n = t_plan.size - 1
    for i in range(t0.size - 1, -1, -1):
        end = t0[i + 1] if i + 1 < t0.size else duration
        if end <= t_plan[0]:
            break
        if jk[i] != 0.0 or a0[i] != 0.0 or v0[i] <= 0.0 or t0[i] >= t_plan[n]:
            continue
        # the periods k with t_plan[k] >= t0 and t_plan[k+1] <= end, the last one before n - 1
        first = np.searchsorted(t_plan, t0[i])
        stop = min(np.searchsorted(t_plan, end, side="right") - 1, n - 1)
        if stop - first >= periods:
            return stop - periods, v0[i]
    return -1, 0.0


def _bump_window(law, t_plan: np.ndarray) -> _Bump | None:
    """The landing bump over the stretch's (t_plan (N+1,)) last BUMP_PERIODS periods in a cruise
    or hold of the law, before its last period; None if there are none."""
    k0, v_c = _last_flat_periods(law.t0_s, law.a0_mm_s2, law.jerk_mm_s3, law.v0_mm_s,
                                 law.duration_s, t_plan, BUMP_PERIODS)
    if k0 < 0:
        return None
    return _Bump(int(k0), BUMP_PERIODS, float(t_plan[k0]),
                 float(t_plan[k0 + BUMP_PERIODS] - t_plan[k0]), float(v_c))


@dataclass(frozen=True)
class _Landing:
    """How one stretch landed: the targets stepped (N,), sigma, the bump and its depth."""

    targets: np.ndarray
    sigma: float
    bump: _Bump | None
    slowdown: float
    runs: float
    seconds: float


def _land(curve, code: int, u_start: float, u_end: float, end_point: np.ndarray,
          ds: np.ndarray, total: float, slow: float, sigma: float, bump: _Bump | None,
          t_plan: np.ndarray, u: np.ndarray, pts: np.ndarray) -> _Landing:
    """Step from u_start through ds (N,), whose sum is total, into u (N+1,) and pts (N+1, 3),
    landing exactly on end_point (see the module docstring): first with targets sigma * ds,
    then with a bump or another sigma.

    The kernel makes the first N-1 steps; the last point is end_point itself, and the residual
    |end - P_{N-1}| - (last target) is driven to zero. It is continuous and monotone in sigma
    and e even where C' vanishes at the end (the curve folds back there when extrapolated).
    """
    n = ds.size
    knots, coef, degree = curve.knots, curve.span_polynomials, curve.degree
    n_spans = int(np.searchsorted(knots, u_end, side="left"))  # last span ends at u_end
    # Each step rounds the point to ~eps (length + coordinates), and those errors add up like a
    # random walk: the landing resolves only to about sqrt(N) of them (measured: up to 1x on
    # curves 1 m from the origin); ask no more, but never accept less than LANDING_REL_MAX.
    noise = EPS * (total + max(abs(float(x)) for x in end_point)) * math.sqrt(n)
    last_ds = float(ds[-1])
    tol = max(LANDING_REL_TOL * last_ds, min(noise, LANDING_REL_MAX * last_ds))
    head = ds[:-1]

    def residual(last_target: float) -> float:
        gap = math.sqrt(sum((float(end_point[i]) - float(pts[-2, i])) ** 2 for i in range(3)))
        return (gap if u[-2] <= u_end else -gap) - last_target

    def run(s: float) -> float:
        step_spans(code, knots, coef, degree, n_spans, u_start, head, s, slow, u[:-1], pts[:-1])
        return residual(s * last_ds)

    start = time.perf_counter()
    r = run(sigma)
    seconds = time.perf_counter() - start
    runs = 1.0
    if abs(r) > tol and r < 0.0 and bump is not None:
        landed = _land_bump(code, knots, coef, degree, n_spans, ds, slow, sigma, bump, t_plan,
                            u, pts, r, tol, residual)
        if landed is not None:
            targets, slowdown, bump_runs = landed
            return _Landing(targets, sigma, bump, slowdown, runs + bump_runs, seconds)
        r = run(sigma)  # the bump could not land: back to the plain run
        runs += 1.0
    # d(residual)/d(sigma) ~ -total: Newton, then secant steps, never above 1 (that would raise
    # the speed). The best run after the first is kept aside, so that a last run that made
    # things worse (rounding) costs a copy back.
    sigma_prev, r_prev = sigma, r
    best = (abs(r), sigma)
    kept = None
    sigma = min(sigma + r / total, 1.0)
    while abs(r_prev) > tol:
        start = time.perf_counter()
        r = run(sigma)
        seconds = time.perf_counter() - start
        runs += 1.0
        improved = abs(r) < best[0]
        if improved:
            best = (abs(r), sigma)
        # stop at the tolerance, or where the residual stops improving: below ~1e-11 mm it
        # is rounding (and branch switches inside the kernel), not a function of sigma
        if abs(r) <= tol or runs >= LANDING_MAX_RUNS or r == r_prev or not improved:
            break
        kept = (sigma, u[:-1].copy(), pts[:-1].copy())
        sigma, sigma_prev, r_prev = (min(sigma - r * (sigma - sigma_prev) / (r - r_prev), 1.0),
                                     sigma, r)
    if sigma != best[1]:  # the last run was not the best one: back to the best
        sigma = best[1]
        if kept is not None and kept[0] == sigma:
            u[:-1], pts[:-1] = kept[1], kept[2]
        else:
            run(sigma)
            runs += 1.0
    return _Landing(sigma * ds, sigma, None, 0.0, runs, seconds)


def _land_bump(code, knots, coef, degree, n_spans, ds, slow, sigma, bump, t_plan, u, pts,
               r_full, tol, residual):
    """Step 2 of the landing: the depth e of the bump that takes out the overshoot r_full < 0
    of the full run, by a secant search over runs from the bump's first point on (the best run
    where rounding stops it short of the tolerance). Returns the targets, e and the runs (as a
    share of the full run), or None if e would exceed BUMP_MAX_SLOWDOWN or no bump does better
    than none."""
    n = ds.size
    k0 = bump.k0
    taken = np.diff(bump.removed(t_plan[k0:k0 + bump.periods + 1]))  # (M,) per unit of e
    targets = sigma * ds
    tail = targets[k0:n - 1].copy()
    share = (n - 1 - k0) / (n - 1)
    u0 = float(u[k0])

    def run_tail(e: float) -> float:
        tail[:bump.periods] = sigma * (ds[k0:k0 + bump.periods] - e * taken)
        step_spans(code, knots, coef, degree, n_spans, u0, tail, 1.0, slow, u[k0:-1],
                   pts[k0:-1])
        return residual(float(targets[-1]))

    # r rises by sigma * (arc taken out): exactly sigma * v_c D / 2 per unit of e
    e_prev, r_prev = 0.0, r_full
    e = -r_full / (sigma * float(taken.sum()))
    best = (abs(r_full), 0.0)
    runs = 0.0
    for _ in range(LANDING_MAX_RUNS):
        if not 0.0 < e <= BUMP_MAX_SLOWDOWN:
            return None
        r = run_tail(e)
        runs += share
        if abs(r) < best[0]:
            best = (abs(r), e)
        # stop at the tolerance, or where the residual stops improving (rounding)
        if abs(r) <= tol or r == r_prev or abs(r) >= abs(r_prev):
            break
        e, e_prev, r_prev = e - r * (e - e_prev) / (r - r_prev), e, r
    if best[1] == 0.0:  # no bump did better than none
        return None
    if e != best[1]:
        e = best[1]
        run_tail(e)
        runs += share
    targets[k0:k0 + bump.periods] = sigma * (ds[k0:k0 + bump.periods] - e * taken)
    return targets, e, runs


def interpolate(plan: Plan, method: str = "rk2c") -> Interpolation:
    """Step along the planned curve with `method`; see the module docstring.

    Every stretch between rests is sampled from the time law at its periods, stepped and landed
    in place in the curve's arrays.
    """
    curve = plan.curve
    law = plan.law
    period = plan.limits.period_s
    code = METHODS[method]
    mean_speed = plan.length_mm / (curve.u_max - curve.u_min)
    slow = SLOW_SPEED_REL * mean_speed
    key_u = plan.key_u
    n_all = 1 + plan.n_periods
    u_all = np.empty(n_all)
    points = np.empty((n_all, 3))
    ds_all = np.empty(n_all - 1)
    u_all[0] = curve.u_min
    points[0] = curve.points[0]
    stretches: list[_StretchLaw] = []
    runs, seconds = 0.0, 0.0
    k0 = 0  # index of the stretch's first point
    for p in range(len(plan.piece_periods)):
        n = int(plan.piece_periods[p])
        key_a, key_b = plan.piece_key[p], plan.piece_key[p + 1]
        if n == 0:
            continue
        t_plan, ds, v, a, j, drift = _sample_stretch(
            law.t0_s, law.s0_mm, law.v0_mm_s, law.a0_mm_s2, law.jerk_mm_s3,
            float(law.key_t_s[key_a]), float(law.key_t_s[key_b]), n, plan.grid.s_mm,
            plan.grid.kappa_1_mm, method == "rk2c")
        sigma = 1.0
        total = float(ds.sum())
        if method == "rk2c" and total > 0.0:
            sigma = min(1.0, 1.0 - drift / total + LANDING_MARGIN_REL)
        last = p == len(plan.piece_periods) - 1
        end_point = curve.points[-1] if last else curve.point(key_u[key_b])
        start_point = points[k0].copy()  # the previous landing (or the curve start): exact
        landing = _land(curve, code, float(key_u[key_a]), float(key_u[key_b]),
                        np.asarray(end_point, dtype=float), ds, total, slow, sigma,
                        _bump_window(law, t_plan), t_plan, u_all[k0:k0 + n + 1],
                        points[k0:k0 + n + 1])
        points[k0] = start_point
        u_all[k0 + n] = key_u[key_b]
        points[k0 + n] = end_point
        runs += landing.runs
        seconds += landing.seconds
        ds_all[k0:k0 + n] = landing.targets
        stretches.append(_StretchLaw(k0, t_plan, v, a, j, float(plan.piece_scale[p]),
                                     landing.sigma, landing.bump, landing.slowdown))
        k0 += n
    # at rest at the start (and at every stretch start): v = a = 0, the jerk of the first piece
    first_j = float(law.jerk_mm_s3[0]) if law.jerk_mm_s3.size else 0.0
    first_scale = float(plan.piece_scale[0]) if plan.piece_scale.size else 1.0
    first_sigma = stretches[0].sigma if stretches else 1.0
    return Interpolation(method, period, u_all, points, ds_all, runs, seconds, tuple(stretches),
                         first_sigma * first_j / first_scale**3)
