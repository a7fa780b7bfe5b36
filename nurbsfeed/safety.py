"""The last look at a curve's points before they become moves: what the machine would do.

The planner and the interpolator keep the limits by construction; this guard does not trust
them. It reads the points as positions one period apart, as a controller executing one move per
period would, and refuses the curve (a located CurveError: exit 2, no output file) if any of
them is not finite, a move is faster than the feed cap allows, or a second difference shows an
acceleration the profile cannot give. A bug that would otherwise send a wild move to a machine
(a whole curve collapsed into one G1, a corner taken at full feed) is stopped here.

Bounds, with room for the finite differences of one period (a second difference is the
acceleration to O(T^2 j'), its chordal normal part v^2 kappa to O((kappa v T)^2)):
    |P_k+1 - P_k|                 <= v_m T (1 + GUARD_FEED_REL)
    |P_k+1 - 2 P_k + P_k-1| / T^2 <= sqrt(A_t^2 + A_n^2) (1 + GUARD_ACC_REL)
plus GUARD_ABS_MM of rounding on every difference. Under the jerk model `path` (design §2b),
whose limits are those of the motion itself, also the jerk and every axis with limits of its own:
    |P_k+2 - 3 P_k+1 + 3 P_k - P_k-1| / T^3 <= sqrt(J_t^2 + J_n^2) (1 + GUARD_JERK_REL)
    per axis x: the step <= V_x T (1 + GUARD_FEED_REL), the second difference <= A_x T^2
    (1 + GUARD_ACC_REL), the third <= J_x T^3 (1 + GUARD_JERK_REL)
(a k-th difference is a weighted mean of the k-th derivative over k periods: it never exceeds
the motion's own peak; the paper model's jerk limits are the law's and a proxy, not the motion's,
so its jerk is not guarded). The bounds are necessary, not sufficient: `nurbsfeed check` and the
tests measure each limit on its own.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from nurbsfeed.errors import CurveError
from nurbsfeed.jit import jit
from nurbsfeed.planning.limits import Limits
from nurbsfeed.program import CurveBlock

GUARD_FEED_REL = 1e-3  # a wild move is far above; a stepping error of 1e-4 is not one
GUARD_ACC_REL = 0.05
GUARD_JERK_REL = 0.05
GUARD_ABS_MM = 1e-9
DRIFT_REFUSAL = ("taylor1's points drift off the planned feed, which the limits do not allow "
                 "here: use rk2c")
# `_difference_maxima`'s (13,) result: whether every point is finite (1 or 0); then for k = 1,
# 2, 3 the largest norm of a k-th difference (k = 2: P_k+1 - 2 P_k + P_k-1, as the guard takes
# it; k = 1, 3: as np.diff takes them) and the largest absolute k-th difference of each axis
# (np.diff's), X, Y, Z
_FINITE, _STEP, _D1, _TURN, _D2, _JERK, _D3 = 0, 1, 2, 5, 6, 9, 10
_MAXIMA = 13


@jit
def _difference_maxima(points, out):
    """The largest differences of points (N, 3), one pass, into out (_MAXIMA,) (0 where there
    is no difference of that order). Each is the number numpy's reading of the same points gives
    (`_first_wild`, `MotionGuard._check_path`, `slowdown_from_points`), operation for operation:
    the differences subtracted as np.diff does, a norm summed x, y then z, and NaN where any
    value it is the largest of is NaN, as np.max has it. The maximum of correctly rounded
    quotients is the quotient of the maximum, so the ratios to a limit follow exactly."""
    values = np.empty(_MAXIMA)  # this point's differences, in out's order
    nan = np.zeros(_MAXIMA, dtype=np.bool_)
    out[:] = 0.0
    finite = True
    d1x = d1y = d1z = d2x = d2y = d2z = 0.0  # the last first and second differences
    for i in range(points.shape[0]):
        px = points[i, 0]
        py = points[i, 1]
        pz = points[i, 2]
        finite = finite and math.isfinite(px) and math.isfinite(py) and math.isfinite(pz)
        if i == 0:
            continue
        ex = px - points[i - 1, 0]
        ey = py - points[i - 1, 1]
        ez = pz - points[i - 1, 2]
        values[_STEP] = math.sqrt(ex * ex + ey * ey + ez * ez)
        values[_D1] = abs(ex)
        values[_D1 + 1] = abs(ey)
        values[_D1 + 2] = abs(ez)
        filled = _TURN
        if i >= 2:
            tx = (px - 2.0 * points[i - 1, 0]) + points[i - 2, 0]
            ty = (py - 2.0 * points[i - 1, 1]) + points[i - 2, 1]
            tz = (pz - 2.0 * points[i - 1, 2]) + points[i - 2, 2]
            values[_TURN] = math.sqrt(tx * tx + ty * ty + tz * tz)
            fx = ex - d1x
            fy = ey - d1y
            fz = ez - d1z
            values[_D2] = abs(fx)
            values[_D2 + 1] = abs(fy)
            values[_D2 + 2] = abs(fz)
            filled = _JERK
            if i >= 3:
                jx = fx - d2x
                jy = fy - d2y
                jz = fz - d2z
                values[_JERK] = math.sqrt(jx * jx + jy * jy + jz * jz)
                values[_D3] = abs(jx)
                values[_D3 + 1] = abs(jy)
                values[_D3 + 2] = abs(jz)
                filled = _MAXIMA
            d2x = fx
            d2y = fy
            d2z = fz
        d1x = ex
        d1y = ey
        d1z = ez
        for q in range(_STEP, filled):
            v = values[q]
            if v > out[q]:
                out[q] = v
            elif v != v:
                nan[q] = True
    for q in range(_STEP, _MAXIMA):
        if nan[q]:
            out[q] = math.nan
    out[_FINITE] = 1.0 if finite else 0.0


def difference_maxima(points: np.ndarray) -> np.ndarray:
    """`_difference_maxima` of points (N, 3): (_MAXIMA,)."""
    out = np.empty(_MAXIMA)
    _difference_maxima(np.ascontiguousarray(points, dtype=float), out)
    return out


def _first_wild(points: np.ndarray, before: np.ndarray, max_step_mm: float,
                max_turn_mm: float) -> tuple[int, int, float]:
    """The first k of points (N, 3), after the points `before` (2, 3: the last but one, the
    last; NaN: none), whose move or second difference breaks its bound, and what broke (0 none,
    1 not finite, 2 step, 3 second difference) with its size. In numpy: it runs once per chunk
    of points, and a kernel would cost the first conversion its compile time."""
    joined = np.concatenate([before, points])
    current, last, last_but_one = joined[2:], joined[1:-1], joined[:-2]
    # a missing point before (NaN) or one after a non-finite point makes a NaN, which breaks
    # no bound; inf - inf and overflowing squares are not warned about
    with np.errstate(invalid="ignore", over="ignore"):
        move = current - last
        turn = current - 2.0 * last + last_but_one
        step_mm = np.sqrt(move[:, 0] ** 2 + move[:, 1] ** 2 + move[:, 2] ** 2)
        turn_mm = np.sqrt(turn[:, 0] ** 2 + turn[:, 1] ** 2 + turn[:, 2] ** 2)
    finite = np.isfinite(points).all(axis=1)
    wild = np.flatnonzero(~finite | (step_mm > max_step_mm) | (turn_mm > max_turn_mm))
    if wild.size == 0:
        return -1, 0, 0.0
    k = int(wild[0])
    if not finite[k]:
        return k, 1, 0.0
    if step_mm[k] > max_step_mm:
        return k, 2, float(step_mm[k])
    return k, 3, float(turn_mm[k])


def feed_cap_mm_s(lim: Limits, block: CurveBlock) -> float:
    """The highest feed anywhere on the block's curve: the machine's, or the highest programmed
    F if one covers the whole curve."""
    if block.feed_mm_s.size and block.feed_u[0] <= block.curve.u_min:
        return min(lim.feed_mm_s, float(block.feed_mm_s.max()))
    return lim.feed_mm_s


class MotionGuard:
    """Checks a curve's points chunk by chunk, in order, as they are handed to the writer.

    Each chunk is read once in compiled code (`_difference_maxima`, with the last three points
    before it): where every largest difference is within its bound, so is every difference.
    Otherwise the chunk is read again in numpy (`_first_wild`, `_check_path`), which finds the
    first point at fault and says what it would do; both readings compute the same numbers, so
    the second always refuses (should it not, the curve is refused all the same)."""

    def __init__(self, lim: Limits, curve_label: str, method: str = "rk2c") -> None:
        period = lim.period_s
        # what a refusal tells the user: the first-order baseline's points drift off the
        # planned feed by its nature (the convert command warns of it); any other method's
        # refusal is a defect to report
        self.why = (DRIFT_REFUSAL if method == "taylor1"
                    else "a safety check: please report this curve")
        self.max_step_mm = lim.feed_mm_s * period * (1.0 + GUARD_FEED_REL) + GUARD_ABS_MM
        acc = math.hypot(lim.acc_mm_s2, lim.normal_acc_mm_s2)
        self.max_turn_mm = acc * period**2 * (1.0 + GUARD_ACC_REL) + 4.0 * GUARD_ABS_MM
        self.period_s = period
        self.feed_mm_s = lim.feed_mm_s
        self.acc_mm_s2 = acc
        self.label = curve_label
        self.tail = np.empty((0, 3))  # the last three points seen (fewer at the start)
        self.seen = 0
        # jerk model `path`: bounds on the k-th differences (k = 1, 2, 3), per axis and (k = 3)
        # on the vector; the last three points seen
        self.path = lim.jerk_model == "path"
        if self.path:
            margin = (1.0 + GUARD_FEED_REL, 1.0 + GUARD_ACC_REL, 1.0 + GUARD_JERK_REL)
            per_axis = (lim.axis_vel_mm_s, lim.axis_acc_mm_s2, lim.axis_jerk_mm_s3)
            self.axis_limits = [np.asarray(limits, dtype=float) for limits in per_axis]
            self.axis_bounds = [limits * period**k * margin[k - 1] + 2 ** (k - 1) * GUARD_ABS_MM
                                for k, limits in enumerate(self.axis_limits, start=1)]
            self.jerk_mm_s3 = math.hypot(lim.jerk_mm_s3, lim.normal_jerk_mm_s3)
            self.max_jerk_mm = self.jerk_mm_s3 * period**3 * margin[2] + 8.0 * GUARD_ABS_MM

    def check(self, points: np.ndarray, maxima: np.ndarray | None = None) -> None:
        """points (N, 3): the next points of the curve, one period apart. maxima: their
        `PointReader` reading, where the same chunks were read in the same order from the
        curve's first point (verified.py reads them so): the differences are not taken again."""
        points = np.ascontiguousarray(points, dtype=float)
        joined = np.concatenate([self.tail, points])
        if maxima is None:
            maxima = difference_maxima(joined)
        if not self._within(maxima):
            self._refuse(points)
        self.tail = joined[-3:].copy()
        self.seen += points.shape[0]

    def _within(self, maxima: np.ndarray) -> bool:
        """Whether the largest differences (`_difference_maxima`) keep every bound."""
        if not (maxima[_FINITE] == 1.0 and maxima[_STEP] <= self.max_step_mm
                and maxima[_TURN] <= self.max_turn_mm):
            return False
        if not self.path:
            return True
        return bool(all(np.all(maxima[first:first + 3] <= bound)
                        for first, bound in zip((_D1, _D2, _D3), self.axis_bounds))
                    and maxima[_JERK] <= self.max_jerk_mm)

    def _refuse(self, points: np.ndarray) -> None:
        """Raise the CurveError for the first point of `points` (after the tail) at fault."""
        self._numpy_reading(points)
        raise CurveError(f"{self.label}: refused, a difference of its points is above its bound "
                         f"in compiled code and within it in numpy (point {self.seen} on); "
                         "nothing was written (a safety check: please report this curve)")

    def _numpy_reading(self, points: np.ndarray) -> None:
        """Every bound on points (N, 3), after the tail, in numpy: the CurveError for the first
        point at fault, if any."""
        before = np.full((2, 3), np.nan)
        last = self.tail[-2:]
        before[2 - last.shape[0]:] = last
        k, what, size = _first_wild(points, before, self.max_step_mm, self.max_turn_mm)
        if k >= 0:
            at = self.seen + k
            if what == 1:
                problem = "is not a finite number"
            elif what == 2:
                problem = (f"would move at {size / self.period_s:.6g} mm/s, above the feed cap "
                           f"of {self.feed_mm_s:.6g} mm/s")
            else:
                problem = (f"would accelerate at {size / self.period_s**2:.6g} mm/s^2, above "
                           f"the profile's {self.acc_mm_s2:.6g} mm/s^2 (tangential and normal)")
            raise CurveError(f"{self.label}: refused, point {at} {problem}; nothing was "
                             f"written ({self.why})")
        if self.path:
            self._check_path(points)

    def _check_path(self, points: np.ndarray) -> None:
        """The jerk model's own bounds on points (N, 3), after the last three points seen."""
        held = self.tail.shape[0]
        joined = np.concatenate([self.tail, points])
        period = self.period_s
        worst: tuple[int, str] | None = None
        diff = joined
        for k, bound in enumerate(self.axis_bounds, start=1):
            diff = np.diff(diff, axis=0)  # diff[i] ends at joined[i + k]
            names = ("move", "accelerate", "jerk")
            over = np.flatnonzero(np.any(np.abs(diff) > bound, axis=1))
            if k == 3:
                size = np.linalg.norm(diff, axis=1)
                over = np.union1d(over, np.flatnonzero(size > self.max_jerk_mm))
            over = over[over + k >= held]  # ending on a new point
            if over.size and (worst is None or over[0] + k - held < worst[0]):
                i = int(over[0])
                axis = int(np.argmax(np.abs(diff[i]) / np.maximum(bound, 1e-300)))
                value = abs(diff[i, axis]) / period**k
                unit = ("mm/s", "mm/s^2", "mm/s^3")[k - 1]
                limit = self.axis_limits[k - 1][axis]
                problem = (f"would {names[k - 1]} at {value:.6g} {unit} along {'XYZ'[axis]}, "
                           f"above the axis's {limit:.6g} {unit}")
                if k == 3 and np.linalg.norm(diff[i]) > self.max_jerk_mm:
                    problem = (f"would jerk at {np.linalg.norm(diff[i]) / period**3:.6g} "
                               f"mm/s^3, above the profile's {self.jerk_mm_s3:.6g} mm/s^3 "
                               f"(tangential and normal)")
                worst = (i + k - held, problem)
        if worst is not None:
            raise CurveError(f"{self.label}: refused, point {self.seen + worst[0]} {worst[1]}; "
                             f"nothing was written ({self.why})")


class PointReader:
    """A curve's points read chunk by chunk, in order, for their largest differences: each
    chunk with the last three points before it, as `MotionGuard.check` reads them, so that the
    guard can take a reading made before (verified.py) instead of its own."""

    def __init__(self) -> None:
        self.tail = np.empty((0, 3))

    def read(self, points: np.ndarray) -> tuple[int, np.ndarray]:
        """The next points (N, 3): the points read with them (N plus those before them, at most
        3) and their `_difference_maxima`."""
        joined = np.concatenate([self.tail, np.ascontiguousarray(points, dtype=float)])
        self.tail = joined[-3:].copy()
        return joined.shape[0], difference_maxima(joined)


def slowdown_from_points(lim: Limits, chunks: Iterable[np.ndarray]) -> tuple[float, float]:
    """`slowdown_from_readings` of the points (each chunk (N, 3), one period apart, in order)."""
    reader = PointReader()
    return slowdown_from_readings(lim, (reader.read(points) for points in chunks))


def slowdown_from_readings(lim: Limits, readings: Iterable[tuple[int, np.ndarray]]
                           ) -> tuple[float, float]:
    """The least uniform slowdowns (>= 1) after which a curve's points keep their limits, read
    from their differences (`PointReader.read` of each chunk, in order; a slowdown by lambda
    divides a k-th difference by lambda^k): the one the speeds ask (the path's, under
    lim.feed_mm_s, and each axis's velocity), which the motion guard holds within
    GUARD_FEED_REL, and the one every axis's acceleration and jerk and the jerk vector (within
    sqrt(J_t^2 + J_n^2)) ask, which it holds within GUARD_ACC_REL and GUARD_JERK_REL."""
    period = lim.period_s
    limits = [np.asarray(per_axis, dtype=float) for per_axis in
              (lim.axis_vel_mm_s, lim.axis_acc_mm_s2, lim.axis_jerk_mm_s3)]
    jerk = math.hypot(lim.jerk_mm_s3, lim.normal_jerk_mm_s3)
    speed, worst = 1.0, 1.0
    for n_read, maxima in readings:
        for k, per_axis in enumerate(limits, start=1):
            if n_read <= k:  # no difference of this order yet
                break
            first = (_D1, _D2, _D3)[k - 1]
            ratio = float(np.max(maxima[first:first + 3] / (per_axis * period**k)))
            if k == 1:
                speed = max(speed, ratio, float(maxima[_STEP]) / (lim.feed_mm_s * period))
                continue
            if k == 3:
                ratio = max(ratio, float(maxima[_JERK]) / (jerk * period**3))
            worst = max(worst, ratio ** (1.0 / k))
    return speed, worst
