"""The reference schedule's grid (analysis.bound): the rests (corners, cusps: where the motion
must stop) and the cells, the knot spans cut until each cell turns the tangent, changes kappa
and lasts little enough (see the package docstring).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbsfeed.analysis.bound.frames import Geometry, derivatives3, geometry
from nurbsfeed.geometry.arclength import gauss_lengths
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.limits import Limits

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
GAUSS_POINTS = 16  # of a cell's arc length (`gauss_length`) and time (`schedule.cell_times`)


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


def gauss_length(curve: NurbsCurve, u0: np.ndarray, u1: np.ndarray, spans: np.ndarray
                  ) -> np.ndarray:
    """Arc length from u0 to u1 (both (M,), on `spans`) by Gauss-Legendre on |C'|."""
    def speed(u: np.ndarray) -> np.ndarray:  # the nodes of piece i on spans[i]
        return np.linalg.norm(derivatives3(curve, u, np.repeat(spans, GAUSS_POINTS))[1], axis=1)

    return gauss_lengths(speed, u0, u1, GAUSS_POINTS)


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
    total = float(gauss_length(curve, starts, ends, spans).sum())
    h_max = min(MAX_CELL_PERIODS * lim.feed_mm_s * lim.period_s, total / MIN_CELLS)
    h_rest = min(REST_CELL_SHARE * lim.acc_mm_s2**3 / (6 * lim.jerk_mm_s3**2), h_max / 64)
    rest_u = np.concatenate([[curve.u_min], rests, [curve.u_max]])
    # below this kappa the caps stand far above the feed: its relative change does not matter
    kappa_floor = KAPPA_FLOOR_SHARE * lim.normal_acc_mm_s2 / lim.feed_mm_s**2
    # cells (u0, u1, span), refined by halving in u until every cell passes
    u0, u1, span = starts.copy(), ends.copy(), spans.copy()
    for _ in range(MAX_REFINE_ROUNDS):
        length = gauss_length(curve, u0, u1, span)
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
    length = gauss_length(curve, u0, u1, span)
    mid_u = (u0 + u1) / 2
    s = np.concatenate([[0.0], np.cumsum(length)])
    u = np.concatenate([u0, u1[-1:]])
    rest = np.isin(u, rest_u)
    node = geometry(curve, u, np.concatenate([span, span[-1:]]))
    node_left = geometry(curve, u, np.concatenate([span[:1], span]))
    return Grid(u, s, span, rest, mid_u, gauss_length(curve, u0, mid_u, span),
                node, node_left, geometry(curve, mid_u, span))

