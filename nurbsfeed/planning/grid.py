"""The dense grid a curve is planned on: parameters, arc length, curvature, pointwise limits.

The grid has nodes at every knot and enough nodes inside each span that consecutive nodes are
at most `spacing_mm` apart; refined curvature maxima are nodes too. The planner checks its speed
profile at these nodes ("limits everywhere"), so the spacing is tied to the step length v_m T.

Building it, in order (`_grid_nodes`, compiled steps; then `simpson_lengths`):
1. Samples: per span, a node count from a 16-chord length estimate, evenly spaced in u; at a
   knot, the higher of kappa's two one-sided values.
2. Curvature maxima: local maxima of kappa on the samples that stand out from their valleys,
   each refined inside the bracket of its two neighbours (sampling, then Brent's method span by
   span, with kappa from both sides at a knot; only roughly where kappa stays well below
   kappa_floor, where the limit is flat). A maximum inside the last interval before a knot or
   an end, beside which the samples keep rising (an end, or a knot where kappa jumps down),
   is no local maximum of the samples: each side of each boundary is probed for it
   (`geometry.peaks.boundary_maxima`).
3. Stops, where the feed must come to rest (kappa is infinite there):
   a. corners at knots of multiplicity >= degree, where the unit tangent jumps
      (`geometry.stops.find_corners`);
   b. zeros of C' (a control point repeated, a cusp, a path that turns back on itself), found
      as local minima of |C'| on the samples refined by Gauss-Newton, and at every knot from
      both sides (`geometry.stops.stop_candidates`, `classify_stops`). A zero is classified by
      the one-sided tangents, taken as chords from it:
        - they differ (a corner) or are opposite (a cusp, a reversal): a stop;
        - they agree, but kappa grows without bound towards the zero: a stop (v^2 kappa would
          be unbounded at any speed above 0);
        - they agree and kappa has finite one-sided limits: removable, the curve is smooth
          there; its kappa is the limit (the next finite value, `fill_singular`).
      The ends of the curve are at rest anyway; a zero of C' there only blanks kappa.
   c. near cusps, where |C'| refines to a minimum close to 0 but not 0: kappa peaks there in a
      needle that neither neighbouring sample need show. One across which the path turns back
      (`geometry.stops._near_cusp_turn`) is a hairpin, and a stop like a cusp: the stepping's
      arc position runs a fraction of a micrometre off the law's between rests, enough to meet
      a tip of nanometres before the law has slowed down for it. Any other is refined there and
      becomes a peak (`geometry.peaks.near_cusp_peaks`).
4. The maxima, corners and caller's parameters are merged in as nodes; then every interval
   across which kappa jumps is halved, a few times over (geometry.sampling).
5. Arc length by adaptive Simpson between consecutive nodes (geometry.arclength).
Everything is evaluated one parameter at a time from the span polynomials (geometry.kernel), in
numba's subset: the cost is the evaluations, not thousands of small array operations. The
classification of candidate stops and near cusps runs only on a curve that has such candidates
(most have none).
The grid keeps C and C' at its nodes, for the path model to read (planning.path_check).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nurbsfeed.errors import CurveError
from nurbsfeed.geometry.arclength import simpson_lengths
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.geometry.peaks import boundary_maxima, near_cusp_peaks, refined_maxima
from nurbsfeed.geometry.sampling import (
    ZERO_SPEED_REL,
    merge,
    refine_where_kappa_jumps_or_turns,
    samples,
)
from nurbsfeed.geometry.stops import classify_stops, find_corners, stop_candidates
from nurbsfeed.jit import jit

# Simpson's tolerance per node interval, relative to the interval's length at the mean |C'|.
# The accepted values carry the Richardson term, so they are far more accurate than this:
# on the butterfly and the benchmark curves every node's length is within 1e-10 mm of a
# 1e-13 reference (tests/test_geometry.py); 1e-10 cost 60 % more evaluations for nothing.
ARC_REL_TOL = 1e-9
TANGENT_CHORD_REL = 1e-9  # chords beside a stop grow tenfold until this long (of the polygon)


@dataclass(frozen=True, eq=False)
class Grid:
    """Nodes along one curve; every array is (M,) but where said, and read-only."""

    u: np.ndarray
    s_mm: np.ndarray  # cumulative arc length, s[0] = 0
    kappa_1_mm: np.ndarray  # curvature; at a point where C' = 0, the limit from inside
    peak_index: np.ndarray  # (P,) nodes that are local curvature maxima (refined, see step 2)
    stop_index: np.ndarray  # (Q,) nodes where the motion rests: corners, cusps, reversals (step 3)
    stop_cos: np.ndarray  # (Q,) cosine of the tangent's turn at each stop (-1: turns back)
    points_mm: np.ndarray  # (M, 3) C at the nodes
    d1_mm: np.ndarray  # (M, 3) C' at the nodes (mm per unit of u; at a knot, the span after it)

    @property
    def length_mm(self) -> float:
        return float(self.s_mm[-1])

    @cached_property
    def speed_mm(self) -> np.ndarray:
        """|C'| at the nodes (M,), read-only, as `NurbsCurve.speed` gives it (numpy's sum of
        the three squares, which the grid's own |C'| need not match to the last bit)."""
        speed = np.sqrt(np.einsum("...i,...i->...", self.d1_mm, self.d1_mm))
        speed.setflags(write=False)
        return speed


@jit
def polygon_length(points):
    """Length of the control polygon (N, 3; a curve's, read-only): the curve is no longer. The
    legs are summed in order (np.sum would pair them): the grid's tolerances derive from the
    last bits."""
    total = 0.0
    for i in range(points.shape[0] - 1):
        total += math.sqrt((points[i + 1, 0] - points[i, 0]) ** 2
                           + (points[i + 1, 1] - points[i, 1]) ** 2
                           + (points[i + 1, 2] - points[i, 2]) ** 2)
    return total


def _grid_nodes(knots, coef, degree, breaks, spacing_mm, extra_u, kappa_floor, floor_mm):
    """Steps 1-4: nodes u, kappa, |C'| (M,), C and C' at them (M, 3), |C'| at the middle of
    each node's interval where the refinement took it (M,; NaN elsewhere), refined peak
    parameters (P,), stops (Q,) with the cosine of their turn (Q,), and the mean |C'| over the
    samples (the arc length tolerance's scale).

    The steps are compiled and each is called once from here (a compiled driver would compile
    every step's code a second time, into itself: seconds of the first run); between them a
    few numpy calls sort and join what they found, and the corners and the classification of
    candidate stops run only on a curve that has candidates."""
    u, kappa, speed, pts, d1, tan, mean_speed = samples(knots, coef, degree, breaks, spacing_mm)
    zero_speed = ZERO_SPEED_REL * mean_speed
    found_u, minima, turns, back, full = stop_candidates(knots, coef, degree, breaks, u, speed,
                                                         pts, tan, zero_speed, mean_speed,
                                                         floor_mm)
    stop_u = stop_cos = needle_u = np.empty(0)
    if full.size:
        stop_u = find_corners(knots, coef, degree, breaks, floor_mm, full)
        stop_cos = np.zeros(stop_u.size)
    if found_u.size or minima.size or turns.size or back.shape[0]:
        zero_u, zero_cos, near_u = classify_stops(knots, coef, degree, breaks, u, tan,
                                                  zero_speed, mean_speed, floor_mm, kappa_floor,
                                                  found_u, minima, turns, back)
        stop_u = np.concatenate((stop_u, zero_u))
        stop_cos = np.concatenate((stop_cos, zero_cos))
        order = np.argsort(stop_u, kind="stable")
        stop_u = stop_u[order]
        stop_cos = stop_cos[order]
        needle_u = near_cusp_peaks(knots, coef, degree, u, kappa, near_u, kappa_floor)
    peak_u = refined_maxima(knots, coef, degree, u, kappa, np.empty(0), stop_u, kappa_floor,
                            -np.inf)
    peak_u = np.sort(np.concatenate((peak_u, needle_u)) if needle_u.size else peak_u)
    beside_u = boundary_maxima(knots, coef, degree, breaks, u, peak_u, stop_u)
    if beside_u.size:
        peak_u = np.sort(np.concatenate((peak_u, beside_u)))
    extra = np.sort(np.concatenate((peak_u, stop_u, extra_u)))
    u, kappa, speed, pts, d1, tan = merge(knots, coef, degree, u, kappa, speed, pts, d1, tan,
                                          extra, zero_speed)
    u, kappa, speed, pts, d1, tan, mid_speed = refine_where_kappa_jumps_or_turns(
        knots, coef, degree, u, kappa, speed, pts, d1, tan, kappa_floor, zero_speed, floor_mm)
    # a spike of kappa narrower than the samples shows only in the refined grid: its maxima
    # at or above kappa_floor that no peak's bracket holds are peaks too (refined likewise)
    added = refined_maxima(knots, coef, degree, u, kappa, peak_u, stop_u, kappa_floor,
                           kappa_floor)
    if added.size:
        added = np.sort(added)
        u, kappa, speed, pts, d1, tan = merge(knots, coef, degree, u, kappa, speed, pts, d1,
                                              tan, added, zero_speed)
        mid_speed = np.full(u.size, np.nan)  # (the new nodes split intervals: none known)
        peak_u = np.sort(np.concatenate((peak_u, added)))
    return u, kappa, speed, pts, d1, mid_speed, peak_u, stop_u, stop_cos, mean_speed


def _zero_length_grid(curve: NurbsCurve, extra_u: np.ndarray) -> Grid:
    """The grid of a curve whose control points all coincide: it stays at one point, whatever
    its weights. Built here, not sampled: C' is then rounding noise over 0 (a weight != 1 leaves
    ~1e-16 of it), which made an arc length integrated to a tolerance relative to its own mean
    split without end, and a chord of length 0 a division by 0. The knots and the caller's
    parameters are the nodes; no length, no curvature, no peaks, no stops (rest throughout)."""
    u = np.union1d(curve.span_breaks, np.asarray(extra_u, dtype=float))
    zeros = np.zeros(u.size)
    none = np.empty(0, dtype=np.int64)
    points, d1 = curve.point(u), curve.derivatives(u)[1]
    for a in (u, zeros, none, points, d1):
        a.setflags(write=False)
    return Grid(u, zeros, zeros, none, none, np.empty(0), points, d1)


def build_grid(curve: NurbsCurve, spacing_mm: float, extra_u: np.ndarray = np.empty(0),
               kappa_floor: float = np.inf) -> Grid:
    """Sample, find and refine curvature maxima, integrate arc length: the planning grid.

    extra_u: parameters that must be nodes (where the programmed feed changes); kappa_floor:
    below it the limit does not depend on curvature (kappa_0), so neither jumps of kappa nor its
    maxima below it need refining.
    """
    if curve.is_degenerate:
        return _zero_length_grid(curve, extra_u)
    knots, coef, degree = curve.knots, curve.span_polynomials, curve.degree
    floor_mm = TANGENT_CHORD_REL * polygon_length(curve.points)
    u, kappa, speed, points, d1, mid_speed, peak_u, stop_u, stop_cos, mean_speed = _grid_nodes(
        knots, coef, degree, curve.span_breaks, float(spacing_mm),
        np.array(extra_u, dtype=float), float(kappa_floor), floor_mm)
    # two stops on one node (a corner knot where C' also vanishes) are one: the sharper turn
    stop_index = np.searchsorted(u, stop_u)
    if stop_index.size > 1:
        stop_index, first = np.unique(stop_index, return_index=True)
        stop_cos = np.minimum.reduceat(stop_cos, first)
    peak_index = np.searchsorted(u, peak_u)
    s = simpson_lengths(knots, coef, degree, u, speed, mid_speed,
                        ARC_REL_TOL * (mean_speed + 1e-300))
    if not math.isfinite(s[-1]):
        q = int(np.argmin(np.isfinite(s)))
        raise CurveError(f"arc length does not converge between u = {curve.input_u(u[q - 1]):.9g}"
                         f" and {curve.input_u(u[q]):.9g} (|C'| there is rounding noise?)")
    # stops with no length between them (a span whose control points are all equal) are one
    # place: the first stands, the others become plain nodes with the kappa that follows them
    same = np.flatnonzero(np.diff(s[stop_index]) <= floor_mm) + 1 if stop_index.size > 1 else ()
    if len(same):
        for n in stop_index[same][::-1]:
            kappa[n] = kappa[n + 1]
        stop_index = np.delete(stop_index, same)
        stop_cos = np.delete(stop_cos, same)
    kappa[stop_index] = np.inf
    for a in (u, s, kappa, peak_index, stop_index, stop_cos, points, d1):
        a.setflags(write=False)
    return Grid(u, s, kappa, peak_index, stop_index, stop_cos, points, d1)
