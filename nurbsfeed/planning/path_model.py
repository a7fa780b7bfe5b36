"""The path jerk model (design §2b): the limits the machine feels, along the path and per axis.

Along C(s) at speed v with tangential acceleration a and jerk j (T, N, B the Frenet frame, kappa
the curvature, kappa' = dkappa/ds, tau the torsion):

    velocity     = v T
    acceleration = a T + kappa v^2 N
    jerk         = (j - kappa^2 v^3) T + (3 kappa v a + kappa' v^3) N + kappa tau v^3 B

The paper's model limits j and the proxy v^3 kappa^2; the path model limits the tangential
component of the jerk by J_t, its normal part (N and B together) by J_n, and each axis's
velocity, acceleration and jerk by the profile's per-axis limits. Slowing a motion uniformly in
time by lambda >= 1 divides velocities by lambda, accelerations by lambda^2 and every jerk term
by lambda^3, so `motion_ratio` gives, per point, the lambda that brings every quantity within
its limit.

Where the curve is only C1 (a degree-2 curve's knots) the curvature, hence kappa v^2 N, jumps:
the jerk is unbounded there, and over one period it reads v^2 |D| / T, D the jump of kappa N.
The limit on that is a speed limit at the knot, `jump_limits`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.jit import jit
from nurbsfeed.planning.limits import Limits

# The S-curve's own acceleration and jerk, as a share of the lowest limit they add to: the
# rest is left for the terms the curve adds where the S-curve accelerates (kappa^2 v^3 beside
# j = -J along the path, kappa v^2 N_x beside a T_x per axis); what they still break is removed
# by the planner's uniform slowdown (`path_check.path_excess`). 0.75 gave the shortest cycles of
# 0.6, 0.75, 0.85 and 1.0 on the samples and dense test curves.
SCURVE_SHARE = 0.75
STRAIGHT_REL = 1e-12  # |C' x C''| below this share of |C'| |C''|: the curve is straight there
JUMP_REL = 1e-9  # a jump of kappa N below this share of it is rounding, not a jump


@dataclass(frozen=True)
class Frames:
    """Per point (M,): kappa (1/mm), dkappa/ds (1/mm^2), tau (1/mm); T, N, B (M, 3)."""

    kappa: np.ndarray
    dkappa_ds: np.ndarray
    torsion: np.ndarray
    tangent: np.ndarray
    normal: np.ndarray
    binormal: np.ndarray


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def frames(curve: NurbsCurve, u: np.ndarray) -> Frames:
    """The frame and the curvature terms at parameters u (M,).

    b = C' x C'' (|b| = kappa |C'|^3), b' = C' x C''' its derivative in u, so
    dkappa/du = (b . b') / (|b| |C'|^3) - 3 |b| (C' . C'') / |C'|^5 and tau = (b . C''') / |b|^2.
    Where the curve is straight (b = 0: an inflection, a line) kappa is 0, the binormal is b''s
    direction (the one the normal takes as kappa leaves 0) and |dkappa/ds| = |b'| / |C'|^4; where
    b' is 0 too, N and B are 0 (no jerk term can point there). Where C' = 0 (a stop: the motion
    rests) everything is 0."""
    c1, c2, c3 = curve.derivatives3(np.ascontiguousarray(u, dtype=float))
    scalars = np.zeros((3, c1.shape[0]))
    vectors = np.zeros((3, c1.shape[0], 3))
    _frame_kernel(np.ascontiguousarray(c1), np.ascontiguousarray(c2), np.ascontiguousarray(c3),
                  STRAIGHT_REL, scalars, vectors)
    return Frames(scalars[0], scalars[1], scalars[2], vectors[0], vectors[1], vectors[2])


@jit
def _frame_kernel(c1: np.ndarray, c2: np.ndarray, c3: np.ndarray, straight_rel: float,
                  scalars: np.ndarray, vectors: np.ndarray) -> None:
    """`frames` point by point, into scalars (3, M): kappa, dkappa/ds, tau, and vectors
    (3, M, 3): T, N, B; all left 0 where C' = 0."""
    for i in range(c1.shape[0]):
        x1, y1, z1 = c1[i, 0], c1[i, 1], c1[i, 2]
        x2, y2, z2 = c2[i, 0], c2[i, 1], c2[i, 2]
        x3, y3, z3 = c3[i, 0], c3[i, 1], c3[i, 2]
        speed = math.sqrt(x1 * x1 + y1 * y1 + z1 * z1)
        if not speed > 0.0:
            continue
        bx, by, bz = y1 * z2 - z1 * y2, z1 * x2 - x1 * z2, x1 * y2 - y1 * x2  # b
        ex, ey, ez = y1 * z3 - z1 * y3, z1 * x3 - x1 * z3, x1 * y3 - y1 * x3  # b'
        nb = math.sqrt(bx * bx + by * by + bz * bz)
        ne = math.sqrt(ex * ex + ey * ey + ez * ez)
        speed3 = speed**3
        tx, ty, tz = x1 / speed, y1 / speed, z1 / speed
        if nb > straight_rel * speed * math.sqrt(x2 * x2 + y2 * y2 + z2 * z2):
            scalars[0, i] = nb / speed3
            dk_du = ((bx * ex + by * ey + bz * ez) / (nb * speed3)
                     - 3.0 * nb * (x1 * x2 + y1 * y2 + z1 * z2) / speed**5)
            scalars[2, i] = (bx * x3 + by * y3 + bz * z3) / nb**2
            ux, uy, uz = bx / nb, by / nb, bz / nb
        else:
            dk_du = ne / speed3
            ux, uy, uz = 0.0, 0.0, 0.0
            if ne > 0.0:
                ux, uy, uz = ex / ne, ey / ne, ez / ne
        scalars[1, i] = dk_du / speed
        vectors[0, i, 0], vectors[0, i, 1], vectors[0, i, 2] = tx, ty, tz
        vectors[1, i, 0] = uy * tz - uz * ty  # N = B x T
        vectors[1, i, 1] = uz * tx - ux * tz
        vectors[1, i, 2] = ux * ty - uy * tx
        vectors[2, i, 0], vectors[2, i, 1], vectors[2, i, 2] = ux, uy, uz


def scurve_limits(lim: Limits, moving_axes: np.ndarray) -> tuple[float, float]:
    """The acceleration and jerk the S-curve segments use: the profile's tangential limits
    under the paper model; under the path model SCURVE_SHARE of the lowest of the tangential
    limit and the limits of the axes the curve moves (a move along one axis alone is that
    axis's motion)."""
    if lim.jerk_model == "paper":
        return lim.acc_mm_s2, lim.jerk_mm_s3
    acc = min([lim.acc_mm_s2] + [lim.axis_acc_mm_s2[x] for x in range(3) if moving_axes[x]])
    jerk = min([lim.jerk_mm_s3] + [lim.axis_jerk_mm_s3[x] for x in range(3) if moving_axes[x]])
    return SCURVE_SHARE * acc, SCURVE_SHARE * jerk


def _cbrt_limit(budget: float, per_v3: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.where(per_v3 > 0.0, np.cbrt(budget / np.where(per_v3 > 0.0, per_v3, 1.0)),
                        np.inf)


def static_limit(f: Frames, lim: Limits) -> np.ndarray:
    """The highest speed (M,) at which every path-model quantity holds with a = j = 0 (a key
    point's state: the S-curve segments start and end there at zero acceleration):
    kappa^2 v^3 <= J_t, |kappa' N + kappa tau B| v^3 <= J_n, and per axis |v T_x| <= V_x,
    kappa v^2 |N_x| <= A_x, |(-kappa^2 T + kappa' N + kappa tau B)_x| v^3 <= J_x. Normal
    acceleration and the chord limit are `limits.speed_limit`'s."""
    v = _cbrt_limit(lim.jerk_mm_s3, f.kappa**2)
    v = np.minimum(v, _cbrt_limit(lim.normal_jerk_mm_s3, np.hypot(f.dkappa_ds,
                                                                  f.kappa * f.torsion)))
    jerk_dir = (-(f.kappa**2)[:, None] * f.tangent + f.dkappa_ds[:, None] * f.normal
                + (f.kappa * f.torsion)[:, None] * f.binormal)
    with np.errstate(divide="ignore"):
        for x in range(3):
            tx = np.abs(f.tangent[:, x])
            v = np.minimum(v, np.where(tx > 0.0, lim.axis_vel_mm_s[x] / np.where(tx > 0.0, tx, 1.0),
                                       np.inf))
            kn = f.kappa * np.abs(f.normal[:, x])
            v = np.minimum(v, np.where(kn > 0.0, np.sqrt(lim.axis_acc_mm_s2[x]
                                                         / np.where(kn > 0.0, kn, 1.0)), np.inf))
            v = np.minimum(v, _cbrt_limit(lim.axis_jerk_mm_s3[x], np.abs(jerk_dir[:, x])))
    return v


def motion_ratio(f: Frames, v: np.ndarray, a: np.ndarray, j: np.ndarray,
                 lim: Limits) -> np.ndarray:
    """Per point (M,): the least lambda >= 0 such that the motion slowed by lambda keeps every
    path-model limit there (<= 1: it holds as it is)."""
    out = np.empty(f.kappa.size)
    flat = np.ascontiguousarray
    _ratio_kernel(f.kappa, f.dkappa_ds, f.torsion, f.tangent, f.normal, f.binormal,
                  flat(v, dtype=float), flat(a, dtype=float), flat(j, dtype=float),
                  lim.acc_mm_s2, lim.normal_acc_mm_s2, lim.jerk_mm_s3, lim.normal_jerk_mm_s3,
                  np.array(lim.axis_vel_mm_s, dtype=float),
                  np.array(lim.axis_acc_mm_s2, dtype=float),
                  np.array(lim.axis_jerk_mm_s3, dtype=float), out)
    return out


@jit
def _most(r: float, x: float) -> float:
    """The larger of r and x, NaN if either is (as np.maximum)."""
    return x if (x > r or x != x) else r


@jit
def _ratio_kernel(kappa: np.ndarray, dkappa_ds: np.ndarray, torsion: np.ndarray,
                  tangent: np.ndarray, normal: np.ndarray, binormal: np.ndarray, v: np.ndarray,
                  a: np.ndarray, j: np.ndarray, acc: float, normal_acc: float, jerk: float,
                  normal_jerk: float, axis_vel: np.ndarray, axis_acc: np.ndarray,
                  axis_jerk: np.ndarray, out: np.ndarray) -> None:
    """`motion_ratio` point by point into out (M,): the largest share of each kind first (a
    velocity's ratio is its share, an acceleration's the square root of it, a jerk's the cube
    root), then one root of each."""
    for i in range(out.size):
        k, vi, ai = kappa[i], v[i], a[i]
        v3 = vi**3
        jt = j[i] - k * k * v3
        jn = 3.0 * k * vi * ai + dkappa_ds[i] * v3
        jb = k * torsion[i] * v3
        vel = 0.0
        accel = _most(abs(ai) / acc, k * vi * vi / normal_acc)
        jolt = _most(abs(jt) / jerk, math.hypot(jn, jb) / normal_jerk)
        for x in range(3):
            t_x, n_x, b_x = tangent[i, x], normal[i, x], binormal[i, x]
            vel = _most(vel, abs(vi * t_x) / axis_vel[x])
            accel = _most(accel, abs(ai * t_x + k * vi * vi * n_x) / axis_acc[x])
            jolt = _most(jolt, abs(jt * t_x + jn * n_x + jb * b_x) / axis_jerk[x])
        out[i] = _most(_most(vel, math.sqrt(accel)), np.cbrt(jolt))


def kappa_n_jumps(curve: NurbsCurve, u_breaks: np.ndarray, zero_speed: float = 0.0
                  ) -> np.ndarray:
    """At interior knots u_breaks (K,): the jump D (K, 3) of kappa N there, 0 where it does not
    jump. kappa N = (C'' |C'|^2 - (C' . C'') C') / |C'|^4 on each side; the left side is the
    span before the knot, evaluated one ulp below it. A side where |C'| <= zero_speed has no
    frame to jump from (kappa N there is rounding noise, 1e15 beside a span of no length once
    set a limit of 2e-14 mm/s): 0, the knot is a zero of C' that the grid handles (a rest where
    the path turns back, kappa from inside the spans where it goes on)."""
    if u_breaks.size == 0:
        return np.empty((0, 3))

    def kappa_n(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        _, c1, c2 = curve.derivatives(u)
        sp2 = _dot(c1, c1)
        safe = np.where(sp2 > 0.0, sp2, 1.0)
        return (np.where((sp2 > 0.0)[:, None],
                         (c2 * safe[:, None] - _dot(c1, c2)[:, None] * c1) / (safe**2)[:, None],
                         0.0),
                np.sqrt(sp2))

    right, right_speed = kappa_n(u_breaks)
    left, left_speed = kappa_n(np.nextafter(u_breaks, -np.inf))
    framed = (np.minimum(left_speed, right_speed) > zero_speed)[:, None]
    jump = (right - left) * framed
    size = np.sqrt(_dot(jump, jump))
    # rounding noise where kappa N is continuous (a smooth knot) is no jump
    real = size > JUMP_REL * np.sqrt(np.maximum(_dot(right, right), _dot(left, left)))
    return jump * real[:, None]


def jump_limits(curve: NurbsCurve, u_breaks: np.ndarray, lim: Limits,
                zero_speed: float = 0.0) -> np.ndarray:
    """At interior knots u_breaks (K,): `jump_speeds` of the jumps of kappa N there
    (`kappa_n_jumps`)."""
    return jump_speeds(kappa_n_jumps(curve, u_breaks, zero_speed), lim)


def jump_speeds(jump: np.ndarray, lim: Limits) -> np.ndarray:
    """The speed (K,) at which jumps D (K, 3) of kappa N, read over one period as v^2 |D| / T,
    keep J_n and every axis's jerk (inf where D = 0)."""
    t = lim.period_s
    with np.errstate(divide="ignore"):
        size = np.sqrt(_dot(jump, jump))
        v = np.where(size > 0.0, np.sqrt(lim.normal_jerk_mm_s3 * t / np.where(size > 0.0, size,
                                                                              1.0)), np.inf)
        for x in range(3):
            d = np.abs(jump[:, x])
            v = np.minimum(v, np.where(d > 0.0, np.sqrt(lim.axis_jerk_mm_s3[x] * t
                                                        / np.where(d > 0.0, d, 1.0)), np.inf))
    return v
