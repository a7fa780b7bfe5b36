"""One curve's interpolation: the stretches between rests in order, each stepped and landed
(interpolate.landing), handed on chunk by chunk (`Stepping.chunks`, what pipeline.convert_window
writes) or collected into whole-curve arrays (`interpolate`, for the analyses).

Memory is bounded whatever the curve's duration: a stretch is sampled and stepped CHUNK_PERIODS
periods at a time (`landing.Stretch`), and a chunk of points is handed on before the next is
stepped. v, a and j at the points are worked out from the stretches' laws (`StretchLaw`) only
when asked for (`--trace`, the analyses).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nurbsfeed.interpolate.kernels import METHODS, SLOW_SPEED_REL
from nurbsfeed.interpolate.landing import Bump, Landing, Stretch
from nurbsfeed.interpolate.targets import plan_times
from nurbsfeed.planning.plan import Plan
from nurbsfeed.planning.timelaw import TimeLaw

CHUNK_PERIODS = 65536  # periods of a stretch sampled, stepped or held in memory at a time


@dataclass(frozen=True, eq=False)
class StretchLaw:
    """The law over one stretch between rests as it was stepped: points k0 .. k0 + n of the
    curve, at plan times t_a .. t_b (`plan_time`); the stretch's time scale, its sigma, its
    landing bump and that bump's depth. v, a and j are worked out from it when asked for."""

    k0: int
    n: int
    law: TimeLaw
    t_a: float
    t_b: float
    scale: float
    sigma: float
    bump: Bump | None
    slowdown: float

    def kinematics(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """v, a, j at its points lo .. hi - 1 (hi - lo,), scaled like the targets stepped (sigma,
        and the stretch's scale), with the landing bump's own."""
        _, _, v, a, j = self.law.sample(plan_times(self.t_a, self.t_b, self.n, lo, hi))
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
    stretch: StretchLaw | None
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
    stretches: tuple[StretchLaw, ...]  # what v, a, j are computed from when asked for
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
        """v, a, j of the law at the points (`StretchLaw.kinematics`); at rest at every
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


class Stepping:
    """One curve's interpolation, produced chunk by chunk (`chunks`): memory is bounded by
    CHUNK_PERIODS whatever the curve's duration. The landing figures (runs, the stretches' laws,
    `landed`) are complete once the chunks are exhausted.

    `landings`: how the stretches landed when this plan was stepped with this method before
    (a Stepping's `landed`): each stretch is stepped once with its landing instead of searching
    for it again, the same points to the last bit (`Stretch.replay`), and `runs` counts the
    runs the search took then."""

    def __init__(self, plan: Plan, method: str = "rk2c",
                 landings: tuple[Landing, ...] | None = None) -> None:
        self.plan = plan
        self.method = method
        self.given = landings
        self.runs = 0.0
        self.stretches: list[StretchLaw] = []
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
            stretch = Stretch(plan, p, code, slow, CHUNK_PERIODS)
            if self.given is not None:
                landing = self.given[i]
                stretch.replay(landing)
            else:
                landing = stretch.land(stretch.first_sigma())
            self.landings.append(landing)
            self.runs += landing.runs
            st = StretchLaw(k0, stretch.n, law, stretch.t_a, stretch.t_b,
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
    a conversion streams `Stepping.chunks` instead); how each stretch lands: interpolate.landing."""
    stepping = Stepping(plan, method)
    chunks = list(stepping.chunks())
    u = np.concatenate([c.u for c in chunks])
    points = np.concatenate([c.points for c in chunks])
    ds = np.concatenate([c.ds_mm for c in chunks])[1:]
    return Interpolation(method, plan.limits.period_s, u, points, ds, stepping.runs,
                         tuple(stepping.stretches), stepping.start_jerk_mm_s3)
