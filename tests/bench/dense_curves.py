"""Dense test curves in the style of the feedrate-planning literature, for tests/bench/path_jerk.

Each curve is a closed-form path sampled densely, the samples taken as the control points of a
clamped cubic B-spline with knots averaged from the chord lengths (de Boor, as
tests/bench/programs.py does), which follows the path to within the polygon's own sagging; or one
of the benchmark's seeded CAM-like curves; or a toolpath's shapes as a CAM system writes them
(straight legs along the axes, exact arcs). All are deterministic.
"""

from __future__ import annotations

import numpy as np

from nurbsfeed.geometry import NurbsCurve
from tests.bench.programs import random_curves


def _fitted(name: str, points: np.ndarray) -> NurbsCurve:
    """points (M, 2 or 3) as the control points of a clamped cubic B-spline."""
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    t = chord / chord[-1]
    inner = [t[j:j + 3].mean() for j in range(1, len(points) - 3)]
    return NurbsCurve.build(3, np.concatenate([np.zeros(4), inner, np.ones(4)]), points, None,
                            name)


def _figure_eight(width_mm: float, tip_bump: float, samples: int) -> np.ndarray:
    """x = w/2 sin t, y = w/4 (sin 2t + tip_bump sin 4t): at tip_bump 0.475 the lobe tips at
    t = pi/2, 3pi/2 move at 1/20 of the speed elsewhere, with a curvature spike there."""
    t = np.linspace(0.0, 2 * np.pi, samples)
    return np.column_stack([width_mm / 2 * np.sin(t),
                            width_mm / 4 * (np.sin(2 * t) + tip_bump * np.sin(4 * t))])


def _star(radius_mm: float, cusp_share: float, samples: int) -> np.ndarray:
    """The hypotrochoid x = 4r cos t + d cos 4t, y = 4r sin t - d sin 4t (r = radius_mm / 5):
    five cusps at d = r, five near-cusps of radius shrinking with 1 - d / r below it."""
    r = radius_mm / 5
    d = cusp_share * r
    t = np.linspace(0.0, 2 * np.pi, samples)
    return np.column_stack([4 * r * np.cos(t) + d * np.cos(4 * t),
                            4 * r * np.sin(t) - d * np.sin(4 * t)])


def _helix(radius_mm: float, pitch_mm: float, turns: float, samples: int) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi * turns, samples)
    return np.column_stack([radius_mm * np.cos(t), radius_mm * np.sin(t),
                            pitch_mm * t / (2 * np.pi)])


def axis_bend() -> NurbsCurve:
    """40 mm along X, a bend of about 1 mm radius, 40 mm along Y: a toolpath's corner as the
    CAM rounds it, in one cubic (the legs are exactly straight, along the axes)."""
    return NurbsCurve.build(3, [0, 0, 0, 0, 0.45, 0.5, 0.55, 1, 1, 1, 1],
                            [[0, 0, 0], [20, 0, 0], [40, 0, 0], [41, 0, 0], [41, 1, 0],
                             [41, 21, 0], [41, 41, 0]], None, "axis-bend")


def _pocket(width_mm: float, height_mm: float, radius_mm: float) -> NurbsCurve:
    """A pocket's outline, width x height with corners of radius_mm, once round as one
    quadratic NURBS: straight spans along the axes and exact quarter circles (weight 1/sqrt 2),
    double knots between them (the curvature jumps there)."""
    w, h, r = width_mm, height_mm, radius_mm
    arc = np.sqrt(0.5)
    spans = [((w / 2, -r), 1.0), ((w, -r), 1.0), ((w + r, -r), arc), ((w + r, 0.0), 1.0),
             ((w + r, h / 2), 1.0), ((w + r, h), 1.0), ((w + r, h + r), arc), ((w, h + r), 1.0),
             ((w / 2, h + r), 1.0), ((0.0, h + r), 1.0), ((-r, h + r), arc), ((-r, h), 1.0),
             ((-r, h / 2), 1.0), ((-r, 0.0), 1.0), ((-r, -r), arc), ((0.0, -r), 1.0)]
    points = np.array([(0.0, -r)] + [xy for xy, _ in spans])
    weights = np.array([1.0] + [wt for _, wt in spans])
    pieces = len(spans) // 2
    inner = np.repeat(np.arange(1, pieces), 2)
    knots = np.concatenate([[0, 0, 0], inner, [pieces] * 3]) / pieces
    return NurbsCurve.build(2, knots, points, weights, "pocket")


def axis_toolpaths(count: int, seed: int = 1) -> list[tuple[NurbsCurve, float]]:
    """count toolpaths as a CAM system writes them, each with a feed (mm/s): a polyline of 3 to
    8 legs along the axes (mostly X and Y, a third of them Z too), 0.5 to 30 mm each, turning
    by 90 degrees or back on themselves (a cusp), each leg cut in three, as one quadratic or
    cubic NURBS (uniform or random knots, weights of 1 or random in [0.5, 2]). The legs are
    straight along an axis: the other axes' parts of T are rounding."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        corners = [np.zeros(3)]
        for _ in range(int(rng.integers(3, 9))):
            axis = rng.integers(0, 3 if rng.random() < 0.3 else 2)
            step = np.zeros(3)
            step[axis] = rng.choice([-1, 1]) * rng.uniform(0.5, 30)
            corners.append(corners[-1] + step)
        degree = int(rng.choice([2, 3]))
        points = [corners[0]]
        for a, b in zip(corners[:-1], corners[1:]):
            points += [a + (b - a) / 3, a + 2 * (b - a) / 3, b]
        m = len(points)
        inner = (np.sort(rng.uniform(0, 1, m - degree - 1)) if rng.random() < 0.5
                 else np.linspace(0, 1, m - degree + 1)[1:-1])
        knots = np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)])
        weights = None if rng.random() < 0.7 else rng.uniform(0.5, 2.0, m)
        feed = float(rng.choice([20.0, 60.0, 100.0, 200.0]))
        out.append((NurbsCurve.build(degree, knots, np.array(points), weights, f"axis-{i}"), feed))
    return out


def _long_cam_curve(n_ctrl: int) -> NurbsCurve:
    spec = random_curves(1, seed=7, n_ctrl=n_ctrl)[0]
    return NurbsCurve.build(3, spec["knots"], spec["control_points"], spec["weights"],
                            f"cam-{n_ctrl}")


def dense_curves(quick: bool = False) -> list[NurbsCurve]:
    """The curves, small to large; `quick` leaves out the long ones."""
    curves = [
        # 40 mm figure-eight, smooth: the crossing and the lobes only
        _fitted("figure-eight", _figure_eight(40.0, 0.0, 121)),
        # the same with near-cusps (~50 um radius) at both lobe tips
        _fitted("figure-eight-cusps", _figure_eight(40.0, 0.475, 241)),
        # five-pointed star, 45 mm across, near-cusps of ~10 um radius at the points
        _fitted("star", _star(25.0, 0.95, 301)),
        # a 2 mm figure-eight with near-cusps (~3 um radius): every bend far tighter than the feed
        _fitted("tiny-figure-eight", _figure_eight(2.0, 0.475, 121)),
        # a 3 mm star: near-cusps of ~0.5 um radius, below the chord tolerance
        _fitted("tiny-star", _star(1.5, 0.95, 301)),
        # a 3-turn helical ramp, radius 10 mm, pitch 2 mm: the torsion term and Z
        _fitted("helix", _helix(10.0, 2.0, 3.0, 181)),
        # a toolpath's corner: straight legs along X and Y, a 1 mm bend between
        axis_bend(),
        # a 30 x 20 mm pocket's outline with 2 mm corners: lines and exact arcs, knots where the
        # curvature jumps
        _pocket(30.0, 20.0, 2.0),
    ]
    if not quick:
        curves += [
            # a CAM-like curve of 60 spans, ~380 mm, bends down to 0.3 mm radius (bench/programs.py)
            _long_cam_curve(63),
            # a 10-turn helical ramp of 601 samples, ~630 mm: many spans, steady motion
            _fitted("long-helix", _helix(10.0, 2.0, 10.0, 601)),
        ]
    return curves
