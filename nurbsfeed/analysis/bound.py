"""A jerk-limited time-optimal schedule along one curve: the reference `plan` compares with.

Independent of the planner by construction: nothing of `nurbsfeed.planning` runs here (only its
`Limits` record is read); the geometry comes from the curve's span polynomials
(`NurbsCurve.span_polynomials`), the optimisation from scipy's HiGHS.

Motion along C(s) at speed v, tangential acceleration a and tangential jerk j, with the
curvature vector K = kappa N and its arc-length derivative K_s = -kappa^2 T + kappa' N +
kappa tau B (both computed as vectors from C', C'', C''', so an inflection, kappa = 0, needs no
Frenet frame):

    velocity = v T,   acceleration = a T + v^2 K,   jerk = j T + 3 v a K + v^3 K_s.

In b = v^2 over arc length, a = b'/2 and j = sqrt(b) b''/2, so every jerk component is sqrt(b)
times an expression linear in (b, b', b''):  jerk = sqrt(b) (b''/2 T + 3/2 b' K + b K_s).

Constraint models (`Limits.jerk_model`):
- "paper", what the planner enforces: v <= min(feed, chord limit (2/T) sqrt(2 rho delta -
  delta^2), saturating at 2 rho / T once delta >= rho, sqrt(A_n / kappa), cbrt(J_n / kappa^2)),
  |a| <= A_t, |j| <= J_t (j the time law's jerk).
- "path", what the machine feels: the same speed caps without the cbrt(J_n / kappa^2) proxy,
  |a| <= A_t, kappa v^2 <= A_n, |jerk . T| <= J_t, |jerk across T| <= J_n, and per axis
  |velocity_x| <= V_x, |acceleration_x| <= A_x, |jerk_x| <= J_x where given.

The schedule is a C1 piecewise quadratic b(s) on a grid of nodes (variables: b and its slope
b' at each node; on each cell b'' is constant), so a = b'/2 is continuous and j is bounded: the
motion it describes is jerk-limited between the nodes too, however long a cell lasts. A cell
beside a rest (the ends, a corner or a cusp, where the motion must stop) is
b = b_far (x)^(4/3), x the distance to the rest over the cell's length: constant jerk from rest,
a = 0 at the rest, the shape of the time-optimal start (a quadratic with a = 0 there would never
leave the rest). The constraints are imposed at each cell's ends and middle.

Method: sequential linear programming. The jerk constraints are sqrt(b) L(b, b', b'') <= J with
L linear; with sqrt(b) frozen at the previous iterate they are linear, and the LP (HiGHS, sparse)
maximises the integral of b inside a trust region around that iterate. Each iterate is made
exactly feasible at the constraint points by the uniform time scaling lambda >= 1 (v / lambda,
a / lambda^2, jerk / lambda^3 keep every limit) and judged by its scaled cycle time; a worse one
shrinks the trust region. The best scaled iterate is the result: a schedule that keeps every
constraint at every constraint point, so its cycle time is one that a jerk-limited motion
reaches (on a finer grid it can only get shorter).

Grid: the knot spans, each cut so that a cell turns the tangent by at most MAX_TURN_RAD, changes
kappa by at most MAX_KAPPA_CHANGE_REL and is at most MAX_CELL_PERIODS periods of travel at the
feed cap long; cells beside a rest are cut down to REST_CELL_SHARE of the distance a jerk-limited
start takes to reach A_t.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from nurbsfeed.geometry.kernel import eval3_on_spans
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.limits import Limits

MODELS = ("paper", "path")
MAX_TURN_RAD = 0.05  # tangent turn across one cell
MAX_KAPPA_CHANGE_REL = 0.05  # |kappa_i+1 - kappa_i| / max of the two, per cell
MAX_CELL_PERIODS = 4.0  # cell length in periods of travel at the feed cap
REST_CELL_SHARE = 0.02  # of A_t^3 / (6 J_t^2), the distance a constant-jerk start reaches A_t in
KAPPA_FLOOR_SHARE = 0.25  # of A_n / feed^2, where the normal acceleration starts to cap v
REST_GRADING = 0.25  # a cell at most h_rest + this times its distance from the nearest rest
MIN_CELLS = 100  # a curve is cut into at least this many cells
MIN_CELL_MM = 1e-7  # refinement stops here (a curvature jump inside a span cannot be resolved)
MAX_REFINE_ROUNDS = 40
CORNER_COS_TOL = 1e-8  # one-sided tangents at a knot turning by more than ~1.4e-4 rad: a rest
CORNER_PROBE_REL = 1e-6  # of the span's width: where the one-sided chords end
NORMAL_DIRECTIONS = 16  # polygon standing in for the circle |jerk across T| <= J_n (3-D curves)
PLANAR_REL = 1e-9  # off-plane parts below this (relative) make a curve planar
GAUSS_POINTS = 16
MAX_ITERATIONS = 40  # of the first phase
CONVERGED_REL = 2e-5  # a convex-concave step gaining less than this (relative): converged
LP_METHOD = "highs"
TRUST_START, TRUST_SWITCH, TRUST_MAX = 0.5, 0.2, 4.0
MAX_TANGENT_ITERATIONS = 4  # how far b may grow, relative to itself
START_SHARE = 0.25  # of the acceleration-limited b: the first linearisation point
FLOOR_SHARE = 1e-8  # of feed^2: the smallest b a linearisation point takes


@dataclass(frozen=True, eq=False)
class Geometry:
    """Everything the constraints read at M parameters: (M,) and (M, 3) arrays."""

    u: np.ndarray
    point: np.ndarray
    speed_u: np.ndarray  # |C'(u)|
    tangent: np.ndarray  # T
    curvature_vector: np.ndarray  # K = kappa N
    curvature_vector_s: np.ndarray  # dK/ds = -kappa^2 T + kappa' N + kappa tau B

    @property
    def kappa(self) -> np.ndarray:
        return np.linalg.norm(self.curvature_vector, axis=1)


def derivatives3(curve: NurbsCurve, u: np.ndarray, spans: np.ndarray | None = None
                 ) -> np.ndarray:
    """C and its first three derivatives at u: (M,) -> (4, M, 3), from the span polynomials
    (`geometry.kernel.eval3_on_spans`).

    spans (M,) picks the span each u is evaluated on (a knot's left limit is the span before
    it); by default the one with knots[i] <= u < knots[i+1].
    """
    u = np.array(np.ravel(u), dtype=float)
    p = curve.degree
    if spans is None:
        spans = np.clip(np.searchsorted(curve.knots, u, side="right") - 1, p, curve.n_ctrl - 1)
    out = np.empty((4, u.size, 3))
    eval3_on_spans(curve.knots, curve.span_polynomials, p, u,
                   np.ascontiguousarray(spans, dtype=np.int64), out)
    return out


def geometry(curve: NurbsCurve, u: np.ndarray, spans: np.ndarray | None = None) -> Geometry:
    """The frame quantities at u (M,). K = (|C'|^2 C'' - (C'.C'') C') / |C'|^4 and, differentiated
    in u and divided by |C'|, K_s = ([|C'|^2 C''' + (C'.C'') C'' - (|C''|^2 + C'.C''') C'] /
    |C'|^4 - 4 (C'.C'') K / |C'|^2) / |C'|. NaN where C' = 0."""
    c0, c1, c2, c3 = derivatives3(curve, u, spans)
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    speed2 = dot(c1, c1)
    speed = np.sqrt(speed2)
    d12 = dot(c1, c2)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = (speed2[:, None] * c2 - d12[:, None] * c1) / speed2[:, None] ** 2
        dk_du = ((speed2[:, None] * c3 + d12[:, None] * c2
                  - (dot(c2, c2) + dot(c1, c3))[:, None] * c1) / speed2[:, None] ** 2
                 - 4 * d12[:, None] * k / speed2[:, None])
        return Geometry(u, c0, speed, c1 / speed[:, None], k, dk_du / speed[:, None])


# ---- the grid -----------------------------------------------------------------------------------

def _one_sided_tangent(curve: NurbsCurve, u0: float, span: int, towards: int) -> np.ndarray:
    """Unit chord from C(u0) to C(u0 + towards * probe) on `span`: the direction the path leaves
    (towards = +1) or arrives from (towards = -1, reversed) u0, zeros of C' included."""
    width = curve.knots[span + 1] - curve.knots[span]
    u1 = u0 + towards * CORNER_PROBE_REL * width
    pts = derivatives3(curve, np.array([u0, u1]), np.array([span, span]))[0]
    chord = (pts[1] - pts[0]) * towards
    return chord / np.linalg.norm(chord)


def rest_parameters(curve: NurbsCurve) -> np.ndarray:
    """(R,) interior break points where the tangent jumps or turns back: the motion rests there.

    (A zero of C' strictly inside a span is not looked for: fitted near-cusps have a small but
    nonzero |C'|, and their curvature caps the speed.)"""
    breaks = curve.span_breaks
    knots = curve.knots
    rests = []
    for u0 in breaks[1:-1]:
        right = int(np.searchsorted(knots, u0, side="right") - 1)
        left = int(np.searchsorted(knots, u0, side="left") - 1)
        before = _one_sided_tangent(curve, u0, left, -1)
        after = _one_sided_tangent(curve, u0, right, +1)
        if float(before @ after) < 1.0 - CORNER_COS_TOL:
            rests.append(u0)
    return np.array(rests)


def _gauss_length(curve: NurbsCurve, u0: np.ndarray, u1: np.ndarray, spans: np.ndarray
                  ) -> np.ndarray:
    """Arc length from u0 to u1 (both (M,), on `spans`) by Gauss-Legendre on |C'|."""
    x, w = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    half = (u1 - u0) / 2
    uq = (u0 + u1)[:, None] / 2 + half[:, None] * x[None, :]
    c1 = derivatives3(curve, uq.ravel(), np.repeat(spans, GAUSS_POINTS))[1]
    speed = np.linalg.norm(c1, axis=1).reshape(uq.shape)
    return half * (speed @ w)


@dataclass(frozen=True, eq=False)
class Grid:
    """Nodes (M,) and the middles of the cells between them (M-1,), in u and s."""

    u: np.ndarray
    s_mm: np.ndarray
    span: np.ndarray  # (M-1,) the knot span each cell lies in
    rest: np.ndarray  # (M,) bool: the motion is at rest at this node
    mid_u: np.ndarray
    mid_s_mm: np.ndarray  # arc length from the cell's start to its middle
    node: Geometry  # nodes: a cell's end evaluated on its own span (see `node_left`)
    node_left: Geometry  # nodes as the end of the cell before them (differs at a knot)
    mid: Geometry


def build_grid(curve: NurbsCurve, lim: Limits, feed_u: np.ndarray) -> Grid:
    breaks = np.unique(np.concatenate([curve.span_breaks, feed_u[(feed_u > curve.u_min)
                                                                   & (feed_u < curve.u_max)]]))
    rests = rest_parameters(curve)
    starts, ends = breaks[:-1], breaks[1:]
    spans = np.clip(np.searchsorted(curve.knots, starts, side="right") - 1, curve.degree,
                    curve.n_ctrl - 1)
    total = float(_gauss_length(curve, starts, ends, spans).sum())
    h_max = min(MAX_CELL_PERIODS * lim.feed_mm_s * lim.period_s, total / MIN_CELLS)
    h_rest = min(REST_CELL_SHARE * lim.acc_mm_s2**3 / (6 * lim.jerk_mm_s3**2), h_max / 64)
    rest_u = np.concatenate([[curve.u_min], rests, [curve.u_max]])
    # below this kappa the caps stand far above the feed: its relative change does not matter
    kappa_floor = KAPPA_FLOOR_SHARE * lim.normal_acc_mm_s2 / lim.feed_mm_s**2
    # cells (u0, u1, span), refined by halving in u until every cell passes
    u0, u1, span = starts.copy(), ends.copy(), spans.copy()
    for _ in range(MAX_REFINE_ROUNDS):
        length = _gauss_length(curve, u0, u1, span)
        g0, g1 = geometry(curve, u0, span), geometry(curve, u1, span)
        k0, k1 = g0.kappa, g1.kappa
        turn = np.arccos(np.clip(np.einsum("ij,ij->i", g0.tangent, g1.tangent), -1, 1))
        kappa_change = np.abs(k1 - k0) > MAX_KAPPA_CHANGE_REL * np.maximum(
            np.maximum(k0, k1), kappa_floor)
        # away from a rest cells grow geometrically: b ~ s^(4/3) there, and a cell over which
        # sqrt(b) changes much uses the jerk limit at one end only
        s_start = np.concatenate([[0.0], np.cumsum(length)[:-1]])
        s_rest = np.concatenate([s_start[np.isin(u0, rest_u)], [s_start[-1] + length[-1]]])
        nearest = np.abs(s_start[:, None] - s_rest[None, :])
        dist = np.minimum(nearest.min(axis=1), np.abs(s_start + length
                                                      - s_rest[:, None]).min(axis=0))
        bad = ((turn > MAX_TURN_RAD) | kappa_change | (length > h_max)
               | (length > h_rest + REST_GRADING * dist))
        bad &= length > MIN_CELL_MM
        bad |= ~(np.isfinite(k0) & np.isfinite(k1)) & (length > MIN_CELL_MM)
        if not bad.any():
            break
        middle = (u0[bad] + u1[bad]) / 2
        u0 = np.concatenate([u0[~bad], u0[bad], middle])
        u1 = np.concatenate([u1[~bad], middle, u1[bad]])
        span = np.concatenate([span[~bad], span[bad], span[bad]])
        order = np.argsort(u0, kind="stable")
        u0, u1, span = u0[order], u1[order], span[order]
    length = _gauss_length(curve, u0, u1, span)
    mid_u = (u0 + u1) / 2
    s = np.concatenate([[0.0], np.cumsum(length)])
    u = np.concatenate([u0, u1[-1:]])
    rest = np.isin(u, rest_u)
    node = geometry(curve, u, np.concatenate([span, span[-1:]]))
    node_left = geometry(curve, u, np.concatenate([span[:1], span]))
    return Grid(u, s, span, rest, mid_u, _gauss_length(curve, u0, mid_u, span),
                node, node_left, geometry(curve, mid_u, span))


# ---- constraint points --------------------------------------------------------------------------

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
    return Points(cell, sigma, geo, speed_cap(lim, geo, feed), cols, b, d, dd)


# ---- constraint families ------------------------------------------------------------------------

@dataclass(frozen=True)
class Family:
    """Rows coef_b b + coef_d b' + coef_dd b'' (times sqrt(b) when `jerk`) <= limit, one per
    constraint point (P,); `power` is how the family scales with time (1 speed, 2 acceleration,
    3 jerk: lambda = ratio ^ (1 / power))."""

    name: str
    coef_b: np.ndarray
    coef_d: np.ndarray
    coef_dd: np.ndarray
    limit: float
    power: int


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


def families(lim: Limits, geo: Geometry) -> tuple[list[Family], Family | None]:
    """The linear and linearised rows of the model; and for the path model, the normal jerk
    family whose exact value is a norm (checked exactly, imposed as a polygon)."""
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
                              lim.axis_jerk_mm_s3[axis], 3))
    e1, e2, planar = _normal_basis(geo)
    dirs = [0.0, math.pi] if planar else list(
        np.linspace(0, 2 * math.pi, NORMAL_DIRECTIONS, endpoint=False))
    ks = geo.curvature_vector_s
    for theta in dirs:
        e = math.cos(theta) * e1 + math.sin(theta) * e2
        out.append(Family("normal jerk polygon", np.einsum("ij,ij->i", ks, e),
                          1.5 * np.einsum("ij,ij->i", geo.curvature_vector, e), zero,
                          lim.normal_jerk_mm_s3, 3))
    return out, Family("normal jerk", zero, zero, zero, lim.normal_jerk_mm_s3, 3)


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
        val = (fam.coef_b * b + fam.coef_d * pts.value(pts.d, x)
               + fam.coef_dd * pts.value(pts.dd, x))
        if fam.power == 3:
            val = val * root
        out[fam.name] = max(out.get(fam.name, 0.0),
                            float((np.abs(val).max() / fam.limit) ** (1 / fam.power)))
    if normal is not None:
        out[normal.name] = float(((root * _normal_jerk(pts, x)).max() / normal.limit)
                                 ** (1 / 3))
    return out


# ---- the schedule -------------------------------------------------------------------------------

def _cell_times(b0: np.ndarray, b1: np.ndarray, d0: np.ndarray, d1: np.ndarray, h: np.ndarray,
                rest_left: np.ndarray, rest_right: np.ndarray, share: np.ndarray | float = 1.0
                ) -> np.ndarray:
    """Time to cover the first `share` of each cell. Quadratic cells: Gauss-Legendre after
    sigma = h (1 - cos(pi theta)) / 2, which takes away the 1/sqrt singularity of a cell that
    starts or ends at (nearly) zero speed. Cells from or to a rest: the closed form of
    b = b_far y^(4/3): 3 h / sqrt(b_far) for the whole cell."""
    x, w = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    theta_end = np.arccos(1 - 2 * np.asarray(share, dtype=float) * np.ones(h.size)) / np.pi
    theta = theta_end[:, None] * (x[None, :] + 1) / 2
    sigma = h[:, None] * (1 - np.cos(np.pi * theta)) / 2
    jac = h[:, None] * np.pi / 2 * np.sin(np.pi * theta) * theta_end[:, None] / 2
    c = (d1 - d0) / h
    b = b0[:, None] + d0[:, None] * sigma + c[:, None] * sigma**2 / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        quad = np.sum(w[None, :] * jac / np.sqrt(np.maximum(b, 0.0)), axis=1)
        share = np.broadcast_to(share, h.size)
        b_far_left = b1  # rest at the start
        from_rest = 3 * h / np.sqrt(b_far_left) * np.cbrt(share)
        b_far_right = b0  # rest at the end
        to_rest = 3 * h / np.sqrt(b_far_right) * (1 - np.cbrt(1 - share))
    return np.where(rest_left, from_rest, np.where(rest_right, to_rest, quad))


@dataclass(frozen=True, eq=False)
class BoundSchedule:
    """The reference schedule on its grid, in mm and s.

    s_mm, v_mm_s, a_mm_s2, t_s: (M,) at the nodes. j_mm_s3: (M-1,) the time law's jerk
    sqrt(b) b''/2 at each cell's middle (b'' is constant on a cell; j varies with sqrt(b)).
    `arc_at` and `points_at` sample it at any time."""

    curve: NurbsCurve
    limits: Limits
    cycle_s: float
    u: np.ndarray
    s_mm: np.ndarray
    v_mm_s: np.ndarray
    a_mm_s2: np.ndarray
    j_mm_s3: np.ndarray
    t_s: np.ndarray
    rest: np.ndarray
    time_scale: float  # lambda of the final scaling (1: the LP's optimum was feasible as it was)
    iterations: int
    ratios: dict[str, float] = field(default_factory=dict)  # after scaling: all <= 1

    @property
    def _b(self) -> np.ndarray:
        return self.v_mm_s**2

    @property
    def _d(self) -> np.ndarray:
        return 2 * self.a_mm_s2

    def arc_at(self, t_s: np.ndarray) -> np.ndarray:
        """s (K,) at times t_s (K,) in [0, cycle_s], by bisection on each cell's own time."""
        t_s = np.clip(np.asarray(t_s, dtype=float), 0.0, self.cycle_s)
        cell = np.clip(np.searchsorted(self.t_s, t_s, side="right") - 1, 0, self.s_mm.size - 2)
        h = np.diff(self.s_mm)[cell]
        b0, b1 = self._b[cell], self._b[cell + 1]
        d0, d1 = self._d[cell], self._d[cell + 1]
        rl, rr = self.rest[cell], self.rest[cell + 1]
        target = t_s - self.t_s[cell]
        low, high = np.zeros(t_s.size), np.ones(t_s.size)
        for _ in range(60):
            mid = (low + high) / 2
            ahead = _cell_times(b0, b1, d0, d1, h, rl, rr, mid) < target
            low, high = np.where(ahead, mid, low), np.where(ahead, high, mid)
        return self.s_mm[cell] + h * (low + high) / 2

    def points_at(self, t_s: np.ndarray) -> np.ndarray:
        """Positions (K, 3) at times t_s (K,): arc length inverted by Newton's method on the
        Gauss-Legendre length of each cell."""
        s = self.arc_at(t_s)
        cell = np.clip(np.searchsorted(self.s_mm, s, side="right") - 1, 0, self.s_mm.size - 2)
        spans = np.clip(np.searchsorted(self.curve.knots, self.u[cell], side="right") - 1,
                        self.curve.degree, self.curve.n_ctrl - 1)
        u0, u1 = self.u[cell], self.u[cell + 1]
        want = s - self.s_mm[cell]
        h = self.s_mm[cell + 1] - self.s_mm[cell]
        u = u0 + (u1 - u0) * np.divide(want, h, out=np.zeros_like(h), where=h > 0)
        for _ in range(8):
            have = _gauss_length(self.curve, u0, u, spans)
            speed = np.linalg.norm(derivatives3(self.curve, u, spans)[1], axis=1)
            u = np.clip(u - (have - want) / speed, u0, u1)
        return derivatives3(self.curve, u, spans)[0]


def _acc_limited(cap: np.ndarray, h: np.ndarray, acc: float) -> np.ndarray:
    """b at the nodes under the speed caps and |a| <= A alone (two passes): the start of the
    iteration, scaled down."""
    b = cap**2
    for i in range(1, b.size):
        b[i] = min(b[i], b[i - 1] + 2 * acc * h[i - 1])
    for i in range(b.size - 2, -1, -1):
        b[i] = min(b[i], b[i + 1] + 2 * acc * h[i])
    return b


def jerk_limited_schedule(curve: NurbsCurve, limits: Limits,
                          feed_u: np.ndarray | None = None, feed_mm_s: np.ndarray | None = None
                          ) -> BoundSchedule:
    """The jerk-limited time-optimal schedule of `curve` from rest to rest (module docstring),
    under `limits` and its jerk model.

    feed_u / feed_mm_s: a programmed feed, a step function of the curve's u (as
    `CurveBlock.feed_u`), capping v beside limits.feed_mm_s.
    """
    feed_u = np.empty(0) if feed_u is None else np.asarray(feed_u, dtype=float)
    feed_mm_s = np.empty(0) if feed_mm_s is None else np.asarray(feed_mm_s, dtype=float)
    grid = build_grid(curve, limits, feed_u)
    pts = constraint_points(grid, limits, feed_u, feed_mm_s)
    fams, normal = families(limits, pts.geo)
    m = grid.u.size
    h = np.diff(grid.s_mm)
    rest_left, rest_right = grid.rest[:-1], grid.rest[1:]

    # equalities: a quadratic cell's b1 - b0 - h (d0 + d1) / 2 = 0; a rest cell's far slope
    # +-(4/3) b_far / h
    rows = np.arange(m - 1)
    eq = sp.coo_matrix(
        (np.concatenate([-np.ones(m - 1), np.ones(m - 1), -h / 2, -h / 2]),
         (np.tile(rows, 4), np.concatenate([rows, rows + 1, m + rows, m + rows + 1]))),
        shape=(m - 1, 2 * m)).tocsr()
    quadratic = ~(rest_left | rest_right)
    eq_rest_left = sp.coo_matrix(
        (np.concatenate([np.ones(rest_left.sum()), -4 / 3 / h[rest_left]]),
         (np.tile(np.arange(rest_left.sum()), 2),
          np.concatenate([m + rows[rest_left] + 1, rows[rest_left] + 1]))),
        shape=(int(rest_left.sum()), 2 * m))
    eq_rest_right = sp.coo_matrix(
        (np.concatenate([np.ones(rest_right.sum()), 4 / 3 / h[rest_right]]),
         (np.tile(np.arange(rest_right.sum()), 2),
          np.concatenate([m + rows[rest_right], rows[rest_right]]))),
        shape=(int(rest_right.sum()), 2 * m))
    a_eq = sp.vstack([eq[quadratic], eq_rest_left, eq_rest_right]).tocsr()
    b_eq = np.zeros(a_eq.shape[0])

    node_cap = np.zeros(m)
    start = pts.sigma_mm == 0
    node_cap[:] = np.inf
    np.minimum.at(node_cap, pts.cell[start], pts.speed_cap_mm_s[start])
    end = pts.sigma_mm == h[pts.cell]
    np.minimum.at(node_cap, pts.cell[end] + 1, pts.speed_cap_mm_s[end])
    node_cap[grid.rest] = 0.0
    node_cap = np.where(np.isfinite(node_cap), node_cap, limits.feed_mm_s)

    n_pts = pts.cell.size
    point_rows = np.repeat(np.arange(n_pts), 3)

    def rows_of(coef: np.ndarray, scale: np.ndarray) -> sp.csr_matrix:
        return sp.coo_matrix(((coef * scale[:, None]).ravel(), (point_rows, pts.cols.ravel())),
                             shape=(n_pts, 2 * m)).tocsr()

    weight = np.zeros(m)
    weight[:-1] += h / 2
    weight[1:] += h / 2
    d_cap = np.where(grid.rest, 0.0, 2 * limits.acc_mm_s2)
    # the linear rows that do not depend on the iterate: speed caps at every point, b >= 0,
    # per-axis accelerations
    fixed_rows = [rows_of(pts.b, np.ones(n_pts)), rows_of(pts.b, -np.ones(n_pts))]
    fixed_rhs = [pts.speed_cap_mm_s**2, np.zeros(n_pts)]
    jerk_coefs = []
    for fam in fams:
        coef = (fam.coef_b[:, None] * pts.b + fam.coef_d[:, None] * pts.d
                + fam.coef_dd[:, None] * pts.dd)
        signs = (1.0,) if fam.name == "normal jerk polygon" else (1.0, -1.0)
        for sign in signs:
            if fam.power == 2:
                fixed_rows.append(rows_of(coef, sign * np.ones(n_pts)))
                fixed_rhs.append(np.full(n_pts, fam.limit))
            else:
                jerk_coefs.append((sign * coef, fam.limit))

    def solve(slowness: np.ndarray, a_ub: sp.csr_matrix, b_ub: np.ndarray, high: np.ndarray
              ) -> tuple[np.ndarray, float, float]:
        """One LP: maximise the slowness-weighted b under the rows, b <= high; the solution,
        the time scaling lambda that makes it feasible and its scaled cycle."""
        objective = -np.concatenate([slowness / slowness.sum(), np.zeros(m)])
        bounds = np.concatenate([np.stack([np.zeros(m), high], axis=1),
                                 np.stack([-d_cap, d_cap], axis=1)])
        res = linprog(objective, A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=b_eq, bounds=bounds,
                      method=LP_METHOD)
        if res.status != 0:
            raise RuntimeError(f"the reference schedule's linear program failed: {res.message}")
        lam = max(1.0, max(worst_ratios(pts, limits, fams, normal, res.x).values()))
        return res.x, lam, lam * _cycle(res.x, h, m, rest_left, rest_right)

    floor_b = FLOOR_SHARE * limits.feed_mm_s**2
    x_best = np.concatenate([START_SHARE * _acc_limited(node_cap.copy(), h, limits.acc_mm_s2),
                             np.zeros(m)])
    best_scaled, best_lambda = math.inf, 1.0
    x_lin = x_best
    trust = TRUST_START
    iterations = 0
    for _ in range(MAX_ITERATIONS):
        iterations += 1
        b_lin = np.maximum(x_lin[:m], floor_b)
        root = np.sqrt(np.maximum(pts.value(pts.b, x_lin), 0.0))
        a_ub = sp.vstack(fixed_rows + [rows_of(coef, root) for coef, _ in jerk_coefs]).tocsr()
        b_ub = np.concatenate(fixed_rhs + [np.full(n_pts, lim) for _, lim in jerk_coefs])
        # the cycle time sum w / sqrt(b), linearised: a node where b is small weighs in as
        # much as the time it costs
        slowness = weight / b_lin**1.5
        # only growth is bounded: where b falls below the linearisation point, sqrt(b_lin) |L|
        # bounds the true sqrt(b) |L|, and the jerk rows are conservative
        high = np.minimum(node_cap**2, b_lin + trust * np.maximum(b_lin, 1e-3 * node_cap**2))
        x, lam, scaled = solve(slowness, a_ub, b_ub, high)
        if scaled < best_scaled:
            x_best, best_scaled, best_lambda = x, scaled, lam
            x_lin = x
            trust = min(trust * 1.5, TRUST_MAX)
        else:
            # the step went too far for the linearisation: back to the best, a smaller step
            x_lin = x_best
            trust /= 2
            if trust < TRUST_SWITCH:
                break
    # phase 2, from the best iterate made feasible: L <= J / sqrt(b), whose right side is
    # convex in b, so its tangent at b_lin lies below it and L <= J (3 - b / b_lin) /
    # (2 sqrt(b_lin)) keeps the true constraint (a convex-concave step): every iterate is
    # feasible at the constraint points, each at least as fast as the last, and the tangent is
    # exact at the fixed point
    x = x_best / best_lambda**2
    best_scaled = _cycle(x, h, m, rest_left, rest_right)
    x_best, best_lambda = x, 1.0
    for _ in range(MAX_TANGENT_ITERATIONS):
        iterations += 1
        lin_nodes = np.maximum(x[:m], floor_b)
        lin_points = np.maximum(pts.value(pts.b, x), floor_b)
        slope = 0.5 / (lin_points * np.sqrt(lin_points))
        a_ub = sp.vstack(fixed_rows + [rows_of(coef + (lim * slope)[:, None] * pts.b,
                                               np.ones(n_pts)) for coef, lim in jerk_coefs])
        b_ub = np.concatenate(fixed_rhs + [1.5 * lim / np.sqrt(lin_points)
                                           for _, lim in jerk_coefs])
        x, lam, scaled = solve(weight / lin_nodes**1.5, a_ub.tocsr(), b_ub, node_cap**2)
        if scaled < best_scaled:
            gain = best_scaled - scaled
            x_best, best_scaled, best_lambda = x, scaled, lam
            if gain < CONVERGED_REL * scaled:
                break
        else:
            break
    x = x_best.copy()
    x[:m] /= best_lambda**2
    x[m:] /= best_lambda**2
    x[:m] = np.maximum(x[:m], 0.0)
    b, d = x[:m], x[m:]
    times = _cell_times(b[:-1], b[1:], d[:-1], d[1:], h, rest_left, rest_right)
    t_nodes = np.concatenate([[0.0], np.cumsum(times)])
    mid = pts.sigma_mm > 0
    mid &= pts.sigma_mm < h[pts.cell]
    jerk_mid = np.zeros(m - 1)
    jerk_mid[pts.cell[mid]] = (np.sqrt(np.maximum(pts.value(pts.b, x), 0)) * 0.5
                               * pts.value(pts.dd, x))[mid]
    return BoundSchedule(curve, limits, float(t_nodes[-1]), grid.u, grid.s_mm, np.sqrt(b), d / 2,
                         jerk_mid, t_nodes, grid.rest, best_lambda, iterations,
                         worst_ratios(pts, limits, fams, normal, x))


def _cycle(x: np.ndarray, h: np.ndarray, m: int, rest_left: np.ndarray, rest_right: np.ndarray
           ) -> float:
    b, d = np.maximum(x[:m], 0.0), x[m:]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cell_times(b[:-1], b[1:], d[:-1], d[1:], h, rest_left, rest_right)
    return float(np.sum(t)) if np.all(np.isfinite(t)) else math.inf
