"""Geometry against the textbook oracle (tests/naive_nurbs.py), plus invariants."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from nurbsfeed.errors import CurveError
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.arclength import simpson_lengths
from nurbsfeed.geometry.kernel import eval_d1, find_span, point_d1, point_d2
from nurbsfeed.geometry.nurbs import (
    MAX_COORDINATE,
    MAX_DEGREE,
    MAX_WEIGHT_RATIO,
    MIN_SPAN_REL,
    curvature_from_derivatives,
)
from nurbsfeed.planning.grid import build_grid
from tests import naive_nurbs
from tests.bench.programs import random_curves
from tests.conftest import load_curve


def random_curve(rng: np.random.Generator) -> NurbsCurve:
    """Degree 1-5, 2-D or 3-D, rational, sometimes with repeated interior knots, any range."""
    degree = int(rng.integers(1, 6))
    n = int(rng.integers(degree + 1, degree + 9))
    interior = np.sort(rng.uniform(0, 1, n - degree - 1))
    if interior.size >= 2 and degree >= 2 and rng.random() < 0.5:
        interior[1] = interior[0]  # multiplicity 2
    lo, span = rng.uniform(-5, 5), rng.uniform(0.5, 20)
    knots = lo + span * np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])
    dim = int(rng.integers(2, 4))
    pts = rng.uniform(-50, 50, (n, dim))
    weights = rng.uniform(0.3, 3.0, n)
    return NurbsCurve.build(degree, knots, pts, weights)


def sample_params(curve: NurbsCurve, rng: np.random.Generator) -> np.ndarray:
    inner = rng.uniform(curve.u_min, curve.u_max, 6)
    return np.concatenate([[curve.u_min, curve.u_max], inner, curve.span_breaks[1:-1] + 1e-9])


@pytest.mark.parametrize("seed", range(25))
def test_vectorised_and_kernel_evaluation_match_the_textbook_oracle(seed: int) -> None:
    rng = np.random.default_rng(seed)
    curve = random_curve(rng)
    u = sample_params(curve, rng)
    c0, c1, c2 = curve.derivatives(u)
    p = curve.degree
    work = [np.empty(p + 1) for _ in range(4)]
    p_out, d_out = np.empty(3), np.empty(3)
    scale = np.max(np.abs(curve.points)) + 1.0
    for k, uk in enumerate(u):
        n0, n1, n2 = naive_nurbs.evaluate(p, curve.knots, curve.points, curve.weights, uk)
        dscale = scale * (1 + np.linalg.norm(n1))
        assert np.allclose(c0[k], n0, atol=1e-9 * scale)
        assert np.allclose(c1[k], n1, atol=1e-8 * dscale)
        assert np.allclose(c2[k], n2, atol=1e-7 * dscale * (1 + np.linalg.norm(n2)))
        span = find_span(curve.knots, p, curve.n_ctrl, uk, -1)
        eval_d1(curve.knots, curve.homogeneous, p, uk, span, *work, p_out, d_out)
        assert np.allclose(p_out, n0, atol=1e-9 * scale)
        assert np.allclose(d_out, n1, atol=1e-8 * dscale)


def test_clamped_curve_starts_and_ends_on_its_end_control_points() -> None:
    curve = random_curve(np.random.default_rng(7))
    ends = curve.point(np.array([curve.u_min, curve.u_max]))
    assert np.allclose(ends, curve.points[[0, -1]], atol=1e-12)


def test_exact_circle_has_constant_curvature_radius_and_length() -> None:
    circle = load_curve("circle")
    u = np.linspace(circle.u_min, circle.u_max, 997)
    c0, c1, c2 = circle.derivatives(u)
    assert np.allclose(np.linalg.norm(c0 - [50.0, 0.0, 0.0], axis=1), 50.0, atol=1e-12)
    assert np.allclose(curvature_from_derivatives(c1, c2), 0.02, rtol=1e-12)
    grid = build_grid(circle, 0.1)
    assert grid.length_mm == pytest.approx(100 * np.pi, abs=1e-9)
    assert grid.peak_index.size == 0 or np.ptp(grid.kappa_1_mm) < 1e-12


def test_adaptive_simpson_agrees_with_gauss_legendre_on_the_oracle(butterfly) -> None:
    nodes = np.array([0.0, 0.05, 0.37, 1.0])
    a, b = nodes[:-1], nodes[1:]
    ours = np.diff(simpson_lengths(butterfly.knots, butterfly.span_polynomials, butterfly.degree,
                                   nodes, butterfly.speed(nodes), np.full(4, np.nan), 1e-10))
    for k in range(3):
        ref = naive_nurbs.length(3, butterfly.knots, butterfly.points, butterfly.weights,
                                 a[k], b[k], n=200)
        assert ours[k] == pytest.approx(ref, rel=1e-9)


def test_grid_arc_lengths_are_within_a_nanometre_of_a_tight_reference(butterfly) -> None:
    """ARC_REL_TOL trades evaluations for nothing visible: every node's length is as good as
    with a tolerance 10^5 times tighter, to well below the output's 0.1 um."""
    curves = [butterfly] + [NurbsCurve.build(c["degree"], c["knots"], c["control_points"],
                                             c["weights"]) for c in random_curves(8, seed=5)]
    for curve in curves:
        grid = build_grid(curve, 0.2)
        speed = curve.speed(grid.u)
        # (a writable u, as the grid passes it: a read-only one would compile the kernel again)
        reference = simpson_lengths(curve.knots, curve.span_polynomials, curve.degree,
                                    grid.u.copy(), speed, np.full(speed.size, np.nan),
                                    1e-13 * float(np.mean(speed)))
        assert np.max(np.abs(grid.s_mm - reference)) < 1e-9


BAD_CURVES = [
    (dict(degree=0, knots=[0, 1], points=[[0, 0]]), "degree must be a whole number >= 1, not 0"),
    (dict(degree=2.5, knots=[0, 1], points=[[0, 0]]),
     "degree must be a whole number >= 1, not 2.5"),
    (dict(degree=3, knots=[0, 0, 0, 0, 1, 1, 1, 1], points=[[0, 0], [1, 1], [2, 0]]),
     "a curve of degree 3 needs at least 4 control points, got 3"),
    (dict(degree=2, knots=[0, 0, 0, 1, 1], points=[[0, 0], [1, 1], [2, 0]]),
     "3 control points of degree 2 need 6 knots (control points + order), got 5"),
    (dict(degree=2, knots=[0, 0, 0, 1, 1, 1], points=[[0, 0], [1, 1], [2, 0]],
          weights=[1, 0, 1]), "weight 1 must be positive and finite, not 0.0"),
    (dict(degree=2, knots=[0, 0, 0, 1, 1, 1], points=[[0, 0], [1, 1], [2, 0]],
          weights=[1, 1]), "3 control points need 3 weights, got 2"),
    (dict(degree=1, knots=[0, 0, 0.5, 0.4, 1, 1], points=[[0, 0], [1, 1], [2, 0], [3, 3]]),
     "knots must not decrease: knot 3 (0.4) < knot 2 (0.5)"),
    (dict(degree=2, knots=[0, 0, 0.1, 0.5, 1, 1, 1], points=[[0, 0], [1, 1], [2, 0], [3, 3]]),
     "knot vector must be clamped: the first 3 and the last 3 knots must be equal (order 3)"),
    (dict(degree=1, knots=[2, 2, 2, 2], points=[[0, 0], [1, 1]]),
     "knot range is empty: all knots are 2"),
    (dict(degree=2, knots=[0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1],
          points=[[0, 0], [1, 1], [2, 0], [3, 3], [4, 0], [5, 5]]),
     "interior knot 0.5 is repeated 3 times; at most 2 (the degree) keeps the curve connected"),
    (dict(degree=1, knots=[0, 0, 1, 1], points=[[0, float("nan")], [1, 1]]),
     "control point 0 is not finite: [0.0, nan]"),
    (dict(degree=1, knots=[0, 0, 1, 1], points=[[0, 0, 0, 0], [1, 1, 1, 1]]),
     "control points must be lists of 2 or 3 numbers, got an array of shape (2, 4)"),
]


@pytest.mark.parametrize(("fields", "message"), BAD_CURVES)
def test_invalid_curves_are_rejected_naming_field_and_value(fields, message) -> None:
    with pytest.raises(CurveError) as err:
        NurbsCurve.build(fields["degree"], fields["knots"], fields["points"],
                         fields.get("weights"))
    assert str(err.value) == message


@pytest.mark.parametrize("seed", range(10))
def test_span_polynomials_match_the_oracle_at_knots_and_extrapolate_smoothly(seed: int) -> None:
    """The stepping loop's and the grid's evaluation (Taylor expansions of each span at both
    ends): the oracle's values at every knot, from either side's expansion, and beyond the ends
    the end spans' polynomials continue (C and C' continuous at u_min and u_max)."""
    rng = np.random.default_rng(100 + seed)
    curve = random_curve(rng)
    p, knots, coef = curve.degree, curve.knots, curve.span_polynomials
    scale = np.max(np.abs(curve.points)) + 1.0
    width = curve.u_max - curve.u_min
    for uk in np.concatenate([curve.span_breaks, rng.uniform(curve.u_min, curve.u_max, 8)]):
        span = find_span(knots, p, curve.n_ctrl, uk, -1)
        n0, n1, n2 = naive_nurbs.evaluate(p, knots, curve.points, curve.weights, uk)
        got = np.array(point_d2(knots, coef, p, span, uk)).reshape(3, 3)
        dscale = scale * (1 + np.linalg.norm(n1))
        assert np.allclose(got[0], n0, atol=1e-9 * scale)
        assert np.allclose(got[1], n1, atol=1e-8 * dscale)
        assert np.allclose(got[2], n2, atol=1e-7 * dscale * (1 + np.linalg.norm(n2)))
        assert np.array_equal(np.array(point_d1(knots, coef, p, span, uk)), got[:2].ravel())
    for end, span in ((curve.u_min, p), (curve.u_max, curve.n_ctrl - 1)):
        inside = np.array(point_d1(knots, coef, p, span, end)).reshape(2, 3)
        for side in (-1.0, 1.0):
            u = end + side * 1e-9 * width
            beyond = np.array(point_d1(knots, coef, p, span, u)).reshape(2, 3)
            assert np.allclose(beyond[0], inside[0] + (u - end) * inside[1], atol=1e-9 * scale)


def test_a_repeated_end_control_point_gives_c_prime_exactly_zero() -> None:
    """design §3a: C'(u) = 0 where control points repeat, exactly, so that the grid sees it."""
    knots = [0, 0, 0, 0, 0.4, 1, 1, 1, 1]
    curve = NurbsCurve.build(3, knots, [[0, 0], [0, 0], [20, 10], [40, -5], [60, 0]])
    _, c1, _ = curve.derivatives(np.array([curve.u_min]))
    assert np.all(c1 == 0.0)
    assert np.all(curve.point(np.array([curve.u_min, curve.u_max]))
                  == curve.points[[0, -1]])


def test_a_knot_where_curvature_jumps_carries_its_higher_side() -> None:
    """A quadratic is only C1 at a simple knot: kappa jumps there, here from 2.33 on the left
    to 0.72 on the right. The grid's node at the knot, and the curvature peak found there,
    carry the left value (evaluated by the textbook oracle just before the knot): the limit
    at the knot must not be taken from the flatter side."""
    knots = [0, 0, 0, 0.5, 1, 1, 1]
    points = [[8, 1], [2, 0], [1, 2], [0, 0]]
    curve = NurbsCurve.build(2, knots, points)
    left = naive_nurbs.curvature(*naive_nurbs.evaluate(2, knots, points, np.ones(4),
                                                       0.5 - 1e-10)[1:])
    right = naive_nurbs.curvature(*naive_nurbs.evaluate(2, knots, points, np.ones(4), 0.5)[1:])
    assert left > 3 * right  # the jump this test is about
    grid = build_grid(curve, 0.01, np.empty(0), 0.0)
    node = int(np.searchsorted(grid.u, 0.5))
    assert grid.u[node] == 0.5
    assert grid.kappa_1_mm[node] == pytest.approx(left, rel=1e-8)
    assert node in grid.peak_index


@pytest.mark.parametrize("seed", range(8))
def test_refined_curvature_peaks_are_the_maxima_around_them(seed: int) -> None:
    """Sampling then Brent's method: no curvature between the peak's neighbouring nodes,
    sampled densely, is higher than the refined peak's (kappa_floor 0: every peak refined;
    the rounding noise of straight pieces, kappa ~ 1e-18, is no peak to check)."""
    curve = random_curve(np.random.default_rng(200 + seed))
    grid = build_grid(curve, 0.05 * curve.speed(np.array([curve.u_min]))[0] + 0.01, np.empty(0),
                      0.0)
    for node in grid.peak_index:
        if not (0 < node < grid.u.size - 1 and 1e-9 < grid.kappa_1_mm[node] < np.inf):
            continue
        u = np.linspace(grid.u[node - 1], grid.u[node + 1], 2001)
        _, c1, c2 = curve.derivatives(u)
        dense = np.nanmax(curvature_from_derivatives(c1, c2))
        assert grid.kappa_1_mm[node] >= dense * (1 - 1e-9)


# ---- the input envelope (docs/refusals.md; measured by tests/bench/envelope.py) ----------------
def envelope_edges() -> dict[str, tuple]:
    """(degree, knots, points, weights) of curves at each edge of the envelope, just inside."""
    rng = np.random.default_rng(41)

    def fields(degree: int, n: int, lo: float = 0.0, width: float = 1.0, size: float = 10.0):
        interior = np.sort(rng.uniform(0.05, 0.95, n - degree - 1))
        knots = lo + width * np.concatenate([np.zeros(degree + 1), interior,
                                             np.ones(degree + 1)])
        return knots, rng.uniform(-size, size, (n, 3)), rng.uniform(0.5, 2.0, n)

    edges = {"degree": (MAX_DEGREE, *fields(MAX_DEGREE, MAX_DEGREE + 5))}
    for name, heavy in (("heavy weight", MAX_WEIGHT_RATIO), ("light weight", 1 / MAX_WEIGHT_RATIO)):
        knots, points, _ = fields(3, 8)
        weights = np.ones(8)
        weights[[3, 4]] = heavy
        edges[name] = (3, knots, points, weights)
    knots, points, weights = fields(5, 11)
    knots[6] = knots[5] + 1.01 * MIN_SPAN_REL  # range 1
    edges["narrowest span"] = (5, np.sort(knots), points, weights)
    knots, points, weights = fields(3, 8)
    points = MAX_COORDINATE - 20.0 + np.abs(points)  # up to 1e6 - 10
    points[2] = [MAX_COORDINATE, -MAX_COORDINATE, MAX_COORDINATE]
    edges["largest coordinates"] = (3, knots, points, weights)
    edges["knot range 1e-6"] = (3, *fields(3, 8, width=1e-6))
    edges["knot range 1e6"] = (3, *fields(3, 8, width=1e6))
    edges["knots [1e6, 1e6 + 1]"] = (3, *fields(3, 8, lo=1e6))
    edges["knots [-1e9, -1e9 + 1e-3]"] = (7, *fields(7, 12, lo=-1e9, width=1e-3))
    return edges


EDGES = envelope_edges()


@pytest.mark.parametrize("name", list(EDGES))
def test_curves_at_the_envelope_edges_evaluate_as_the_exact_curve(name: str) -> None:
    """C, C', C'' at the stored u against the exact rational curve of the input at the same
    point of the input's own parameter (our derivatives scaled back to it): within 1e-13 of
    the curve's size, 1e-12 of the largest |C'| and |C''| (measured: 2.3e-14 at degree 9,
    below 1e-14 at the other edges)."""
    degree, knots, points, weights = EDGES[name]
    curve = NurbsCurve.build(degree, knots, points, weights)
    rng = np.random.default_rng(3)
    unit = np.concatenate([[0.0, 1.0], rng.uniform(0.0, 1.0, 8), curve.span_breaks[1:-1],
                           curve.span_breaks[1:-1] + 0.3 * MIN_SPAN_REL])
    ours = np.stack(curve.derivatives(unit), axis=1)
    ours[:, 1] /= curve.u_scale
    ours[:, 2] /= curve.u_scale ** 2
    origin, scale = Fraction(curve.u_origin), Fraction(curve.u_scale)
    exact = np.stack([naive_nurbs.exact_evaluate(degree, knots, points, weights,
                                                 origin + scale * Fraction(float(x)))
                      for x in unit])
    size = np.max(np.abs(points))
    assert np.max(np.abs(ours[:, 0] - exact[:, 0])) <= 1e-13 * size
    for order in (1, 2):
        largest = np.max(np.linalg.norm(exact[:, order], axis=1))
        assert np.max(np.abs(ours[:, order] - exact[:, order])) <= 1e-12 * largest


JUST_OUTSIDE = [
    (dict(degree=MAX_DEGREE + 1), f"degree {MAX_DEGREE + 1} is above {MAX_DEGREE}, the highest "
     "nurbsfeed evaluates accurately"),
    (dict(weights=[1.0, 1.0, 1.0, 1.0001 * MAX_WEIGHT_RATIO, 1.0]),
     f"weight 3 ({1.0001 * MAX_WEIGHT_RATIO:g}) is more than {MAX_WEIGHT_RATIO:g} times weight "
     "0 (1); nurbsfeed plans curves up to that ratio"),
    (dict(weights=[1.0, 1.0, 1.0, 0.9999 / MAX_WEIGHT_RATIO, 1.0]),
     f"weight 0 (1) is more than {MAX_WEIGHT_RATIO:g} times weight 3 "
     f"({0.9999 / MAX_WEIGHT_RATIO:g}); nurbsfeed plans curves up to that ratio"),
    (dict(knots=[0, 0, 0, 0.5, 0.5 + 0.99 * MIN_SPAN_REL, 1, 1, 1]),
     f"knot span 0.5 .. {0.5 + 0.99 * MIN_SPAN_REL!r} is 9.9e-13 of the knot range; at least "
     f"{MIN_SPAN_REL:g}"),
    (dict(points=[[0, 0], [1, 1], [2, np.nextafter(-MAX_COORDINATE, -np.inf)], [3, 3], [4, 0]]),
     "control point 2 [2.0, -1000000.0000000001] has a coordinate beyond +-1000000, the range "
     "nurbsfeed converts"),
    (dict(knots=[-1e308, -1e308, -1e308, 0, 1, 1e308, 1e308, 1e308]),
     "knot range -1e+308 .. 1e+308 is wider than a double holds"),
]


@pytest.mark.parametrize(("change", "message"), JUST_OUTSIDE)
def test_curves_just_outside_the_envelope_are_refused(change: dict, message: str) -> None:
    fields = dict(degree=2, knots=[0, 0, 0, 0.3, 0.6, 1, 1, 1],
                  points=[[0, 0], [1, 1], [2, 0], [3, 3], [4, 0]], weights=None) | change
    if fields["degree"] != 2:
        fields["knots"] = [0] * 11 + [1] * 11
        fields["points"] = [[i, i % 2] for i in range(11)]
    with pytest.raises(CurveError) as err:
        NurbsCurve.build(fields["degree"], fields["knots"], fields["points"], fields["weights"])
    assert str(err.value) == message


def test_knots_are_stored_on_0_1_and_map_back_to_the_input() -> None:
    knots = [5.0, 5.0, 5.0, 7.0, 9.0, 9.0, 9.0]
    curve = NurbsCurve.build(2, knots, [[0, 0], [1, 1], [2, 0], [3, 1]])
    assert curve.knots.tolist() == [0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0]
    assert (curve.u_origin, curve.u_scale) == (5.0, 4.0)
    assert curve.input_u(curve.knots).tolist() == knots
    assert [curve.unit_u(k) for k in knots] == curve.knots.tolist()


def test_weights_are_scaled_by_a_power_of_two_and_the_curve_is_the_same() -> None:
    """Only the weights' ratios matter: weights 2^1000 times larger or smaller give the very same
    doubles, and weights of 1e300 (which once overflowed: the curve became NaN, "zero-length")
    the same curve."""
    knots, points = [0, 0, 0, 0.4, 1, 1, 1], [[0, 0], [1, 1], [2, 0], [3, 1]]
    weights = np.array([1.0, 0.5, 1.5, 1.0])
    one = NurbsCurve.build(2, knots, points, weights)
    u = np.linspace(0.0, 1.0, 101)
    for factor in (2.0**1000, 2.0**-1000, 6.0, 1e300, 1e-300):
        curve = NurbsCurve.build(2, knots, points, weights * factor)
        assert 1.0 <= curve.weights.max() < 2.0
        ratio = curve.weights / (weights * factor)
        assert np.all(ratio == ratio[0]) and np.frexp(ratio[0])[0] == 0.5  # a power of two
        for ours, reference in zip(curve.derivatives(u), one.derivatives(u)):
            if np.frexp(factor)[0] == 0.5:
                np.testing.assert_array_equal(ours, reference)
            else:
                np.testing.assert_allclose(ours, reference, rtol=1e-14, atol=1e-14)
