"""The reference schedule's constraints (analysis.bound): the constraint points (each cell's ends
and middle, with b, b', b'' there as linear maps of the variables), the pointwise speed cap, and
per limit a family of rows linear in (b, b', b'') (times sqrt(b) for a jerk); `worst_ratios`
measures a schedule against them all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nurbsfeed.analysis.bound.frames import Geometry
from nurbsfeed.analysis.bound.grid import Grid
from nurbsfeed.planning.limits import Limits

NORMAL_DIRECTIONS = 16  # polygon standing in for the circle |jerk across T| <= J_n (3-D curves)
PLANAR_REL = 1e-9  # off-plane parts below this (relative) make a curve planar


@dataclass(frozen=True, eq=False)
class Points:
    """The P constraint points: where each lies and b, b', b'' there as linear maps of the
    variables x = (b_0 .. b_M-1, b'_0 .. b'_M-1), three entries per point (cols, and a
    coefficient per entry for each of b, b', b'')."""

    cell: np.ndarray  # (P,)
    sigma_mm: np.ndarray  # (P,) from the cell's start
    geo: Geometry
    speed_cap_mm_s: np.ndarray  # (P,)
    cols: np.ndarray  # (P, 3)
    b: np.ndarray  # (P, 3)
    d: np.ndarray  # (P, 3)
    dd: np.ndarray  # (P, 3)
    # (P, 3) the jump of kappa N at a point on a knot where it jumps (0 elsewhere): read over
    # one period by the machine's positions it is a jerk b |D| / T
    jump: np.ndarray

    def value(self, coef: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.einsum("pk,pk->p", coef, x[self.cols])


def _take(g: Geometry, idx: np.ndarray) -> Geometry:
    return Geometry(*(getattr(g, f)[idx] for f in
                      ("u", "point", "speed_u", "tangent", "curvature_vector",
                       "curvature_vector_s")))


def _concat(parts: list[Geometry]) -> Geometry:
    return Geometry(*(np.concatenate([getattr(g, f) for g in parts]) for f in
                      ("u", "point", "speed_u", "tangent", "curvature_vector",
                       "curvature_vector_s")))


def speed_cap(lim: Limits, geo: Geometry, feed_mm_s: np.ndarray) -> np.ndarray:
    """The pointwise speed limit (P,) of the model at each point."""
    k = geo.kappa
    t, delta = lim.period_s, lim.chord_mm
    with np.errstate(divide="ignore", invalid="ignore"):
        chord = np.where(k * delta < 1.0, (2.0 / t) * np.sqrt(delta * (2.0 - k * delta) / k),
                         2.0 / (k * t))
        cap = np.minimum(chord, np.sqrt(lim.normal_acc_mm_s2 / k))
        if lim.jerk_model == "paper":
            cap = np.minimum(cap, np.cbrt(lim.normal_jerk_mm_s3 / (k * k)))
        cap = np.where(k > 0.0, cap, np.inf)
        axis = np.min(np.asarray(lim.axis_vel_mm_s)[None, :] / np.abs(geo.tangent), axis=1)
    cap = np.minimum(cap, axis)
    cap = np.where(np.isfinite(k), cap, 0.0)
    return np.minimum(np.minimum(cap, lim.feed_mm_s), feed_mm_s)


def _feed_at(u: np.ndarray, feed_u: np.ndarray, feed_mm_s: np.ndarray) -> np.ndarray:
    """The programmed feed (a step function of u, inf before its first break) at u."""
    if feed_u.size == 0:
        return np.full(u.size, np.inf)
    table = np.concatenate(([np.inf], feed_mm_s))
    return table[np.searchsorted(feed_u, u, side="right")]


def constraint_points(grid: Grid, lim: Limits, feed_u: np.ndarray,
                      feed_mm_s: np.ndarray) -> Points:
    m = grid.u.size
    cells = np.arange(m - 1)
    h = np.diff(grid.s_mm)
    rest_left, rest_right = grid.rest[:-1], grid.rest[1:]
    if (rest_left & rest_right).any():
        raise ValueError("a cell between two rests")  # the grid always cuts such a cell
    # each cell at its start, middle and end; a rest end carries no constraint (b = 0 there)
    sel = [(~rest_left, np.zeros(m - 1), "start"), (np.ones(m - 1, bool), grid.mid_s_mm, "mid"),
           (~rest_right, h, "end")]
    cell = np.concatenate([cells[mask] for mask, _, _ in sel])
    sigma = np.concatenate([pos[mask] for mask, pos, _ in sel])
    geo = _concat([_take(grid.node, cells[sel[0][0]]), _take(grid.mid, cells),
                   _take(grid.node_left, cells[sel[2][0]] + 1)])
    feed = np.concatenate([
        np.minimum(_feed_at(grid.u[:-1], feed_u, feed_mm_s),
                   _feed_at(np.nextafter(grid.u[:-1], -np.inf), feed_u, feed_mm_s))[sel[0][0]],
        _feed_at(grid.mid_u, feed_u, feed_mm_s),
        np.minimum(_feed_at(grid.u[1:], feed_u, feed_mm_s),
                   _feed_at(np.nextafter(grid.u[1:], -np.inf), feed_u, feed_mm_s))[sel[2][0]]])
    # the jump of K = kappa N at each node: its value on its own span less the cell's before
    node_jump = grid.node.curvature_vector - grid.node_left.curvature_vector
    node_jump[grid.rest] = 0.0  # (b = 0 there)
    jump = np.concatenate([node_jump[cells[sel[0][0]]], np.zeros((m - 1, 3)),
                           node_jump[cells[sel[2][0]] + 1]])
    hc = h[cell]
    x = sigma / hc
    n = cell.size
    cols = np.stack([cell, m + cell, m + cell + 1], axis=1)
    b = np.stack([np.ones(n), sigma - sigma**2 / (2 * hc), sigma**2 / (2 * hc)], axis=1)
    d = np.stack([np.zeros(n), 1 - x, x], axis=1)
    dd = np.stack([np.zeros(n), -1 / hc, 1 / hc], axis=1)
    # constant jerk from a rest: b = b_far y^(4/3), y the distance to the rest / h
    for rest_side, far, y, sign in ((rest_left[cell], cell + 1, x, 1.0),
                                    (rest_right[cell], cell, 1 - x, -1.0)):
        cols[rest_side] = np.stack([far[rest_side]] * 3, axis=1)
        yr, hr = y[rest_side], hc[rest_side]
        zero = np.zeros(yr.size)
        b[rest_side] = np.stack([yr ** (4 / 3), zero, zero], axis=1)
        d[rest_side] = np.stack([sign * 4 / 3 * yr ** (1 / 3) / hr, zero, zero], axis=1)
        dd[rest_side] = np.stack([4 / 9 * yr ** (-2 / 3) / hr**2, zero, zero], axis=1)
    return Points(cell, sigma, geo, speed_cap(lim, geo, feed), cols, b, d, dd, jump)


# ---- constraint families ------------------------------------------------------------------------

@dataclass(frozen=True)
class Family:
    """Rows coef_b b + coef_d b' + coef_dd b'' (times sqrt(b) for a jerk, power 3) + jump b
    <= limit, one per constraint point (P,); `power` is how the family scales with time (1
    speed, 2 acceleration, 3 jerk: lambda = ratio ^ (1 / power)). `jump` (P,) is the jerk a
    jump of kappa N adds per unit of b, |D| / T: it scales as an acceleration does (the period
    does not stretch), so where it is not 0 a jerk's lambda is the ratio's square root."""

    name: str
    coef_b: np.ndarray
    coef_d: np.ndarray
    coef_dd: np.ndarray
    limit: float
    power: int
    jump: np.ndarray | None = None


def _normal_basis(geo: Geometry) -> tuple[np.ndarray, np.ndarray, bool]:
    """Two unit vectors across T at every point, and whether the curve is planar (then the
    normal jerk has no part along the second)."""
    t = geo.tangent
    spread = geo.point - geo.point.mean(axis=0)
    _, sv, vt = np.linalg.svd(spread, full_matrices=False)
    plane_normal = vt[-1]
    size = max(float(sv[0]), 1e-300)
    planar = float(sv[-1]) <= PLANAR_REL * size and bool(
        np.all(np.abs(t @ plane_normal) <= 1e-6))
    if planar:
        e1 = np.cross(plane_normal, t)
    else:
        k = geo.curvature_vector
        helper = np.where(np.linalg.norm(k, axis=1)[:, None] > 0, k, np.roll(t, 1, axis=1))
        e1 = helper - np.einsum("ij,ij->i", helper, t)[:, None] * t
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    return e1, np.cross(t, e1), planar


def families(lim: Limits, geo: Geometry, jump: np.ndarray) -> tuple[list[Family], Family | None]:
    """The linear and linearised rows of the model; and for the path model, the normal jerk
    family whose exact value is a norm (checked exactly, imposed as a polygon). jump (P, 3):
    the jump of kappa N at each point (`Points.jump`)."""
    zero = np.zeros(geo.u.size)
    one = np.ones(geo.u.size)
    out: list[Family] = []
    if lim.jerk_model == "paper":
        out += [Family("tangential jerk", zero, zero, 0.5 * one, lim.jerk_mm_s3, 3)]
        return out, None
    ks_t = np.einsum("ij,ij->i", geo.curvature_vector_s, geo.tangent)  # -kappa^2
    out += [Family("tangential jerk", ks_t, zero, 0.5 * one, lim.jerk_mm_s3, 3)]
    for axis in range(3):
        tx, kx = geo.tangent[:, axis], geo.curvature_vector[:, axis]
        ksx = geo.curvature_vector_s[:, axis]
        if math.isfinite(lim.axis_acc_mm_s2[axis]):
            out.append(Family(f"acceleration {'XYZ'[axis]}", kx, 0.5 * tx, zero,
                              lim.axis_acc_mm_s2[axis], 2))
        if math.isfinite(lim.axis_jerk_mm_s3[axis]):
            out.append(Family(f"jerk {'XYZ'[axis]}", ksx, 1.5 * kx, 0.5 * tx,
                              lim.axis_jerk_mm_s3[axis], 3,
                              np.abs(jump[:, axis]) / lim.period_s))
    normal_jump = np.linalg.norm(jump, axis=1) / lim.period_s
    e1, e2, planar = _normal_basis(geo)
    dirs = [0.0, math.pi] if planar else list(
        np.linspace(0, 2 * math.pi, NORMAL_DIRECTIONS, endpoint=False))
    ks = geo.curvature_vector_s
    for theta in dirs:
        e = math.cos(theta) * e1 + math.sin(theta) * e2
        out.append(Family("normal jerk polygon", np.einsum("ij,ij->i", ks, e),
                          1.5 * np.einsum("ij,ij->i", geo.curvature_vector, e), zero,
                          lim.normal_jerk_mm_s3, 3, normal_jump))
    return out, Family("normal jerk", zero, zero, zero, lim.normal_jerk_mm_s3, 3, normal_jump)


def _normal_jerk(pts: Points, x: np.ndarray) -> np.ndarray:
    """|jerk across T| / sqrt(b) = |3/2 b' K + b (K_s - (K_s.T) T)| at every point (P,)."""
    g = pts.geo
    ks_perp = g.curvature_vector_s - np.einsum(
        "ij,ij->i", g.curvature_vector_s, g.tangent)[:, None] * g.tangent
    vec = (1.5 * pts.value(pts.d, x)[:, None] * g.curvature_vector
           + pts.value(pts.b, x)[:, None] * ks_perp)
    return np.linalg.norm(vec, axis=1)


def worst_ratios(pts: Points, lim: Limits, fams: list[Family], normal: Family | None,
                 x: np.ndarray) -> dict[str, float]:
    """Each family's largest value / limit raised to 1 / power (the lambda it needs), exact
    sqrt(b): {name: lambda}."""
    b = np.maximum(pts.value(pts.b, x), 0.0)
    root = np.sqrt(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(b > 0, root / pts.speed_cap_mm_s, 0.0)
    out = {"speed": float(speed.max()),
           "tangential acceleration": math.sqrt(
               float(np.abs(pts.value(pts.d, x)).max()) / (2 * lim.acc_mm_s2))}
    for fam in fams:
        if fam.name == "normal jerk polygon":
            continue
        val = np.abs(fam.coef_b * b + fam.coef_d * pts.value(pts.d, x)
                     + fam.coef_dd * pts.value(pts.dd, x))
        if fam.power == 3:
            val = val * root
        out[fam.name] = max(out.get(fam.name, 0.0), _share(val, b, fam))
    if normal is not None:
        out[normal.name] = _share(root * _normal_jerk(pts, x), b, normal)
    return out


def _share(value: np.ndarray, b: np.ndarray, fam: Family) -> float:
    """The lambda that brings value (P,) (with the family's jump term added) within its
    limit."""
    if fam.jump is None or not fam.jump.any():
        return float((value.max() / fam.limit) ** (1 / fam.power))
    ratio = (value + b * fam.jump) / fam.limit
    jumped = fam.jump > 0.0
    return float(max(np.max(ratio[~jumped], initial=0.0) ** (1 / fam.power),
                     np.max(ratio[jumped], initial=0.0) ** 0.5))

