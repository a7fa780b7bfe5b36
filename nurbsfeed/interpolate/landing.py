"""One stretch between rests, stepped and landed exactly on its end (`Stretch.land`); how it
landed (`Landing`) lets a later stepping replay it without the search. interpolate.stepping makes
a Stretch per stretch; a Stretch samples its targets (interpolate.targets) and steps them
(interpolate.kernels.step_spans).

End landing: rk2c makes every chord equal to its target, so its arc position runs ahead of the
time law (by the arc minus the chord of every step, ~1 um over a curve) and the last step would
overshoot the end. The last point is the curve end itself, and the targets are lowered (never
raised: no limit is raised either) so that the last chord, from the last stepped point to the
end, equals its own target:
1. All targets are scaled by one factor sigma <= 1 (`Stretch.first_sigma`): for rk2c 1 - (the
   drift predicted from the curvature along the way, see `targets.sample_targets`) / length,
   plus LANDING_MARGIN_REL where the stretch has a bump (step 2), so that the first run
   overshoots by a little; for rk4 and taylor1, sigma = 1.
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

Memory is bounded whatever the stretch's duration: a stretch is sampled and stepped
CHUNK_PERIODS (interpolate.stepping) periods at a time. The landing needs of a run only its
last point (and u where the bump starts), so a stretch longer than a chunk samples its targets
from the law again for every run, at t_k from the integer k (never by summing periods), and
once sigma and the bump are decided steps a last time, handing its points on chunk by chunk. A
run carries only u from one chunk to the next, and the sums over the targets are taken in
order, so the points are the same to the last bit however the stretch is chunked. A stretch
within one chunk (the common case) is sampled once and its last run is what is handed on.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nurbsfeed.interpolate.kernels import METHODS, step_spans
from nurbsfeed.interpolate.targets import first_period_at, plan_time, plan_times, sample_targets
from nurbsfeed.planning.plan import Plan
from nurbsfeed.planning.timelaw import TimeLaw

LANDING_REL_TOL = 1e-6  # of the last target: the last chord matches it to 1e-4 % ...
LANDING_REL_MAX = 5e-6  # ... or, where rounding does not resolve that, to half rk2c's 1e-5
LANDING_MAX_RUNS = 8
LANDING_MARGIN_REL = 1e-8  # the first run's sigma lies this far (relative) above the estimate
BUMP_PERIODS = 32
BUMP_MAX_SLOWDOWN = 1e-4
EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class Bump:
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
        first = first_period_at(t_a, t_b, n, t0[i])
        after = first_period_at(t_a, t_b, n, end[i])  # then the first with t_k > end (plan
        if after <= n and plan_time(t_a, t_b, n, after) == end[i]:  # times strictly increase)
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
    bump: Bump | None
    slowdown: float
    runs: float


class Stretch:
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
        self.bump = None if k0 < 0 else Bump(
            k0, BUMP_PERIODS, plan_times(self.t_a, self.t_b, self.n, k0, k0 + BUMP_PERIODS + 1),
            v_c)

    def _sample(self, lo: int, ds: np.ndarray, with_drift: bool, node: int, drift: float,
                total: float, carry: float) -> tuple[int, float, float, float]:
        """`sample_targets` of periods lo .. lo + M - 1 into ds (M,)."""
        plan = self.plan
        return sample_targets(*plan.law.pieces, plan_times(self.t_a, self.t_b, self.n, lo,
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

    def first_sigma(self) -> float:
        """sigma of the first run (module docstring, step 1). The margin serves the bump only,
        which can take out an overshoot but not a shortfall; without a bump the search of step
        3 starts from the estimate itself, and its Newton step lands within the tolerance more
        often (the benchmark's 650 curves under the default profile, whose optimal laws have no
        cruise for a bump: the first run 0.2 to 2 nm off the end instead of 3 to 5, 2.36 runs a
        stretch instead of 2.68)."""
        if self.code != METHODS["rk2c"] or self.total <= 0.0:
            return 1.0
        margin = LANDING_MARGIN_REL if self.bump is not None else 0.0
        return min(1.0, 1.0 - self.drift / self.total + margin)

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

    def _land_bump(self, bump: Bump, sigma: float, r_full: float, past_full: bool,
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

