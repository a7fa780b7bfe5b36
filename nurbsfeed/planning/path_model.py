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

Each quantity is worked out point by point by one compiled function (`frame`, `static_terms`,
`kappa_n_jump`, `jump_speed`), which the vectorised entry points here and the fused kernels of
planning.path_check and `geometry_rows` call alike; cube roots are numpy's (a compiled one rounds
differently), taken on the kernels' results.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.kernel import find_span, point_d3
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.jit import jit
from nurbsfeed.planning.basis import G_CAP, G_D, G_K, G_KAPPA, G_KS, G_SIZE, G_T
from nurbsfeed.planning.limits import (
    L_AXIS_ACC,
    L_AXIS_JERK,
    L_AXIS_VEL,
    L_CHORD,
    L_FEED,
    L_JERK,
    L_NORMAL_ACC,
    L_NORMAL_JERK,
    L_PERIOD,
    Limits,
    chord_acc_limit,
    least,
    limit_values,
    most,
)

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


def kernel_array(a: object, dtype: type = float) -> np.ndarray:
    """a as the one array type the kernels here compile for: writable, C-contiguous, of dtype
    (copied only where it is not one already; the kernels never write into their inputs)."""
    out: np.ndarray = np.asarray(a, dtype=dtype)
    return out if out.flags.writeable and out.flags.c_contiguous else out.copy()


@jit
def dot3(ax, ay, az, bx, by, bz):
    """a . b, summed as numpy's einsum sums three products, (x + z) + y: the kernels give the
    values the vectorised code gave (and `NurbsCurve.speed` gives)."""
    return (ax * bx + az * bz) + ay * by


def frames(curve: NurbsCurve, u: np.ndarray) -> Frames:
    """The frame and the curvature terms at parameters u (M,) (`frame` at each)."""
    at = kernel_array(np.ravel(u))
    scalars = np.empty((3, at.size))
    vectors = np.empty((3, at.size, 3))
    _frames_at(curve.knots, curve.span_polynomials, curve.degree, at, scalars, vectors)
    return Frames(scalars[0], scalars[1], scalars[2], vectors[0], vectors[1], vectors[2])


@jit
def frame(x1, y1, z1, x2, y2, z2, x3, y3, z3):
    """kappa, dkappa/ds, tau, T (3), N (3), B (3) at a point with derivatives C', C'', C'''.

    b = C' x C'' (|b| = kappa |C'|^3), b' = C' x C''' its derivative in u, so
    dkappa/du = (b . b') / (|b| |C'|^3) - 3 |b| (C' . C'') / |C'|^5 and tau = (b . C''') / |b|^2.
    Where the curve is straight (b = 0: an inflection, a line) kappa is 0, the binormal is b''s
    direction (the one the normal takes as kappa leaves 0) and |dkappa/ds| = |b'| / |C'|^4; where
    b' is 0 too, N and B are 0 (no jerk term can point there). Where C' = 0 (a stop: the motion
    rests) everything is 0."""
    speed = math.sqrt(x1 * x1 + y1 * y1 + z1 * z1)
    if not speed > 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    bx, by, bz = y1 * z2 - z1 * y2, z1 * x2 - x1 * z2, x1 * y2 - y1 * x2  # b
    ex, ey, ez = y1 * z3 - z1 * y3, z1 * x3 - x1 * z3, x1 * y3 - y1 * x3  # b'
    nb = math.sqrt(bx * bx + by * by + bz * bz)
    ne = math.sqrt(ex * ex + ey * ey + ez * ez)
    speed3 = speed**3
    tx, ty, tz = x1 / speed, y1 / speed, z1 / speed
    kappa = 0.0
    torsion = 0.0
    if nb > STRAIGHT_REL * speed * math.sqrt(x2 * x2 + y2 * y2 + z2 * z2):
        kappa = nb / speed3
        dk_du = ((bx * ex + by * ey + bz * ez) / (nb * speed3)
                 - 3.0 * nb * (x1 * x2 + y1 * y2 + z1 * z2) / speed**5)
        torsion = (bx * x3 + by * y3 + bz * z3) / nb**2
        ux, uy, uz = bx / nb, by / nb, bz / nb
    else:
        dk_du = ne / speed3
        ux, uy, uz = 0.0, 0.0, 0.0
        if ne > 0.0:
            ux, uy, uz = ex / ne, ey / ne, ez / ne
    return (kappa, dk_du / speed, torsion, tx, ty, tz,
            uy * tz - uz * ty, uz * tx - ux * tz, ux * ty - uy * tx,  # N = B x T
            ux, uy, uz)


@jit
def _frames_at(knots, coef, degree, u, scalars, vectors):
    """`frames` point by point, into scalars (3, M): kappa, dkappa/ds, tau, and vectors
    (3, M, 3): T, N, B."""
    span = degree
    for i in range(u.size):
        span = find_span(knots, degree, coef.shape[0], u[i], span)
        c = point_d3(knots, coef, degree, span, u[i])
        f = frame(c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10], c[11])
        for j in range(3):
            scalars[j, i] = f[j]
            vectors[0, i, j] = f[3 + j]
            vectors[1, i, j] = f[6 + j]
            vectors[2, i, j] = f[9 + j]


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


@jit
def static_terms(lims, kappa, dkappa_ds, torsion, tx, ty, tz, nx, ny, nz, bx, by, bz, roots,
                 i):
    """`static_limit` at one point, lims its `limit_values`, but for its cube roots: the lowest
    of its other terms, and into roots[:, i] (roots (5, M)) what its five cube roots are taken
    of (inf where a term sets no limit): J_t / kappa^2, J_n / |kappa' N + kappa tau B| and per
    axis J_x / |(-kappa^2 T + kappa' N + kappa tau B)_x|."""
    roots[0, i] = lims[L_JERK] / (kappa * kappa) if kappa * kappa > 0.0 else math.inf
    normal = np.hypot(dkappa_ds, kappa * torsion)
    roots[1, i] = lims[L_NORMAL_JERK] / normal if normal > 0.0 else math.inf
    v = math.inf
    for x in range(3):
        t_x = tx if x == 0 else (ty if x == 1 else tz)
        n_x = nx if x == 0 else (ny if x == 1 else nz)
        b_x = bx if x == 0 else (by if x == 1 else bz)
        along = abs(t_x)
        v = least(v, lims[L_AXIS_VEL + x] / along if along > 0.0 else math.inf)
        across = kappa * abs(n_x)
        v = least(v, math.sqrt(lims[L_AXIS_ACC + x] / across) if across > 0.0 else math.inf)
        jerk = abs((-(kappa * kappa) * t_x + dkappa_ds * n_x) + (kappa * torsion) * b_x)
        roots[2 + x, i] = lims[L_AXIS_JERK + x] / jerk if jerk > 0.0 else math.inf
    return v


@jit
def _static_terms_of(lims, kappa, dkappa_ds, torsion, tangent, normal, binormal, low, roots):
    """`static_terms` of every point of a `Frames` into low (M,) and roots (5, M)."""
    for i in range(kappa.size):
        low[i] = static_terms(lims, kappa[i], dkappa_ds[i], torsion[i], tangent[i, 0],
                              tangent[i, 1], tangent[i, 2], normal[i, 0], normal[i, 1],
                              normal[i, 2], binormal[i, 0], binormal[i, 1], binormal[i, 2],
                              roots, i)


def with_roots(low: np.ndarray, roots: np.ndarray) -> np.ndarray:
    """The static limit (M,) from `static_terms`' low (M,) and roots (5, M) (five rows: a
    minimum across them is quick, one across a short last axis is not)."""
    return np.minimum(low, np.cbrt(roots).min(axis=0))


def static_limit(f: Frames, lim: Limits) -> np.ndarray:
    """The highest speed (M,) at which every path-model quantity holds with a = j = 0 (a key
    point's state: the S-curve segments start and end there at zero acceleration):
    kappa^2 v^3 <= J_t, |kappa' N + kappa tau B| v^3 <= J_n, and per axis |v T_x| <= V_x,
    kappa v^2 |N_x| <= A_x, |(-kappa^2 T + kappa' N + kappa tau B)_x| v^3 <= J_x. Normal
    acceleration and the chord limit are `limits.speed_limit`'s."""
    low = np.empty(f.kappa.size)
    roots = np.empty((5, f.kappa.size))
    kappa, dkappa_ds, torsion, tangent, normal, binormal = (
        kernel_array(a) for a in (f.kappa, f.dkappa_ds, f.torsion, f.tangent, f.normal,
                                  f.binormal))
    _static_terms_of(limit_values(lim), kappa, dkappa_ds, torsion, tangent, normal, binormal, low,
                     roots)
    return with_roots(low, roots)


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
        accel = most(abs(ai) / acc, k * vi * vi / normal_acc)
        jolt = most(abs(jt) / jerk, math.hypot(jn, jb) / normal_jerk)
        for x in range(3):
            t_x, n_x, b_x = tangent[i, x], normal[i, x], binormal[i, x]
            vel = most(vel, abs(vi * t_x) / axis_vel[x])
            accel = most(accel, abs(ai * t_x + k * vi * vi * n_x) / axis_acc[x])
            jolt = most(jolt, abs(jt * t_x + jn * n_x + jb * b_x) / axis_jerk[x])
        out[i] = most(most(vel, math.sqrt(accel)), np.cbrt(jolt))


@jit
def kappa_n_jump(knots, coef, degree, u_break, zero_speed):
    """The jump D (3 floats) of kappa N at the interior knot u_break, 0 where it does not jump
    (`kappa_n_jumps`)."""
    n_ctrl = coef.shape[0]
    rx = ry = rz = right_speed = 0.0
    lx = ly = lz = left_speed = 0.0
    for side in range(2):  # the span after the knot, then the one before it
        at = u_break if side == 0 else math.nextafter(u_break, -math.inf)
        c = point_d3(knots, coef, degree, find_span(knots, degree, n_ctrl, at, degree), at)
        # kappa N = (C'' |C'|^2 - (C' . C'') C') / |C'|^4, 0 where C' = 0
        sp2 = dot3(c[3], c[4], c[5], c[3], c[4], c[5])
        kx = ky = kz = 0.0
        if sp2 > 0.0:
            along = dot3(c[3], c[4], c[5], c[6], c[7], c[8])
            square = sp2 * sp2
            kx = (c[6] * sp2 - along * c[3]) / square
            ky = (c[7] * sp2 - along * c[4]) / square
            kz = (c[8] * sp2 - along * c[5]) / square
        if side == 0:
            rx, ry, rz, right_speed = kx, ky, kz, math.sqrt(sp2)
        else:
            lx, ly, lz, left_speed = kx, ky, kz, math.sqrt(sp2)
    framed = 1.0 if least(left_speed, right_speed) > zero_speed else 0.0
    jx, jy, jz = (rx - lx) * framed, (ry - ly) * framed, (rz - lz) * framed
    size = math.sqrt(dot3(jx, jy, jz, jx, jy, jz))
    # rounding noise where kappa N is continuous (a smooth knot) is no jump
    larger = most(dot3(rx, ry, rz, rx, ry, rz), dot3(lx, ly, lz, lx, ly, lz))
    real = 1.0 if size > JUMP_REL * math.sqrt(larger) else 0.0
    return jx * real, jy * real, jz * real


@jit
def _kappa_n_jumps_at(knots, coef, degree, u_breaks, zero_speed, out):
    for i in range(u_breaks.size):
        out[i, 0], out[i, 1], out[i, 2] = kappa_n_jump(knots, coef, degree, u_breaks[i],
                                                       zero_speed)


def kappa_n_jumps(curve: NurbsCurve, u_breaks: np.ndarray, zero_speed: float = 0.0
                  ) -> np.ndarray:
    """At interior knots u_breaks (K,): the jump D (K, 3) of kappa N there, 0 where it does not
    jump. kappa N = (C'' |C'|^2 - (C' . C'') C') / |C'|^4 on each side; the left side is the
    span before the knot, evaluated one ulp below it. A side where |C'| <= zero_speed has no
    frame to jump from (kappa N there is rounding noise, 1e15 beside a span of no length once
    set a limit of 2e-14 mm/s): 0, the knot is a zero of C' that the grid handles (a rest where
    the path turns back, kappa from inside the spans where it goes on)."""
    at = kernel_array(np.ravel(u_breaks))
    out = np.empty((at.size, 3))
    _kappa_n_jumps_at(curve.knots, curve.span_polynomials, curve.degree, at, float(zero_speed),
                      out)
    return out


@jit
def jump_speed(jx, jy, jz, lims):
    """The speed at which a jump D = (jx, jy, jz) of kappa N, read over one period as
    v^2 |D| / T, keeps J_n and every axis's jerk (inf where D = 0)."""
    t = lims[L_PERIOD]
    size = math.sqrt(dot3(jx, jy, jz, jx, jy, jz))
    v = math.sqrt(lims[L_NORMAL_JERK] * t / size) if size > 0.0 else math.inf
    for x in range(3):
        d = abs(jx if x == 0 else (jy if x == 1 else jz))
        v = least(v, math.sqrt(lims[L_AXIS_JERK + x] * t / d) if d > 0.0 else math.inf)
    return v


@jit
def _jump_speeds_of(jump, lims, out):
    for i in range(out.size):
        out[i] = jump_speed(jump[i, 0], jump[i, 1], jump[i, 2], lims)


def jump_limits(curve: NurbsCurve, u_breaks: np.ndarray, lim: Limits,
                zero_speed: float = 0.0) -> np.ndarray:
    """At interior knots u_breaks (K,): `jump_speeds` of the jumps of kappa N there
    (`kappa_n_jumps`)."""
    return jump_speeds(kappa_n_jumps(curve, u_breaks, zero_speed), lim)


def jump_speeds(jump: np.ndarray, lim: Limits) -> np.ndarray:
    """The speed (K,) at which jumps D (K, 3) of kappa N, read over one period as v^2 |D| / T,
    keep J_n and every axis's jerk (inf where D = 0)."""
    out = np.empty(jump.shape[0])
    _jump_speeds_of(kernel_array(np.reshape(jump, (-1, 3))), limit_values(lim), out)
    return out


def geometry_rows(curve: NurbsCurve, lim: Limits, u: np.ndarray, feed_mm_s: np.ndarray,
                  at_knot: np.ndarray) -> np.ndarray:
    """The path planner's geometry rows (N, G_SIZE) at parameters u (N,) (planning.basis:
    kappa, T, K = kappa N, K_s = dK/ds, the jump D of kappa N where at_knot (N,) names the
    knot's index into curve.span_breaks (-1 elsewhere), and the squared speed cap: the chord
    error and normal acceleration limit (`limits.speed_limit`), the programmed feed
    feed_mm_s (N,), each axis's velocity). The path model's alone: the paper's plans on no
    rows (its jerk proxy is not among them)."""
    if lim.jerk_model != "path":
        raise ValueError("geometry rows are the path model's (jerk_model: path)")
    out = np.empty((u.size, G_SIZE))
    _geometry_rows(curve.knots, curve.span_polynomials, curve.degree, curve.span_breaks,
                   kernel_array(u), kernel_array(feed_mm_s), kernel_array(at_knot, np.int64),
                   limit_values(lim), out)
    return out


@jit
def _geometry_rows(knots, coef, degree, breaks, u, feed_mm_s, at_knot, lims, out):
    """`geometry_rows` point by point into out (N, G_SIZE)."""
    span = degree
    for i in range(u.size):
        span = find_span(knots, degree, coef.shape[0], u[i], span)
        c = point_d3(knots, coef, degree, span, u[i])
        f = frame(c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10], c[11])
        k = f[0]
        out[i, G_KAPPA] = k
        cap = chord_acc_limit(k, lims[L_PERIOD], lims[L_CHORD], lims[L_NORMAL_ACC])
        cap = least(least(cap, least(lims[L_FEED], feed_mm_s[i])), lims[L_FEED])
        d = (0.0, 0.0, 0.0)
        if at_knot[i] >= 0:
            d = kappa_n_jump(knots, coef, degree, breaks[at_knot[i]], 0.0)
        for x in range(3):
            t_x, n_x, b_x = f[3 + x], f[6 + x], f[9 + x]
            out[i, G_T + x] = t_x
            out[i, G_K + x] = k * n_x
            out[i, G_KS + x] = (-(k * k) * t_x + f[1] * n_x) + (k * f[2]) * b_x
            out[i, G_D + x] = d[x]
            along = abs(t_x)
            cap = least(cap, lims[L_AXIS_VEL + x] / along if along > 0.0 else math.inf)
        out[i, G_CAP] = cap * cap
