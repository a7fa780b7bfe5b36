"""A validated NURBS curve and its vectorised evaluation (points, derivatives, curvature).

C(u) = sum N_i,p(u) w_i P_i / sum N_i,p(u) w_i  (paper Eq. 1). Evaluation works on the homogeneous
curve A(u) = sum N_i,p w_i P_i, W(u) = sum N_i,p w_i (basis derivatives by Piegl & Tiller A2.3),
then the quotient rule (A4.2):  C = A/W,  C' = (A' - W'C)/W,  C'' = (A'' - 2W'C' - W''C)/W.
The evaluators live in `geometry.kernel` (compiled with numba): each span's polynomial is built
once per curve (`span_polynomials`, cached here) and evaluated by Horner's rule, vectorised
(`eval_many`) or per parameter in the planning grid and the stepping loop; they are checked against
a textbook evaluator that lives in the tests.

`build` refuses curves outside the input envelope below (docs/refusals.md, "Input envelope";
the numbers come from `python -m tests.bench.envelope`, which compares this evaluation with an
exact rational one and converts curves at and beyond each limit). Inside it, two rescalings that
do not change the curve keep every number the kernels see well scaled: the knots are mapped
affinely onto [0, 1] (a NURBS curve does not depend on an affine change of its parameter;
`input_u` maps back for anything shown to the user), and the weights are multiplied by a power
of two, exactly, so that the largest lies in [1, 2) (C depends only on the weights' ratios).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from nurbsfeed.errors import CurveError
from nurbsfeed.geometry.kernel import eval_many, span_polynomials

# ---- the input envelope ------------------------------------------------------------------------
# Degree: the Taylor-Horner evaluation stays within 2.3e-14 of the exact curve up to degree 9,
# 1e-12 up to 19, and breaks down from degree 21 on; controllers accept 1-3 (Fanuc P2-P4,
# Siemens BSPLINE SD <= 3) or 5 (Siemens POLY).
MAX_DEGREE = 9
# max(w) / min(w): evaluation stays accurate far beyond (1e12), but a control point that much
# heavier than its neighbours makes a corner of radius ~1e-5 mm: at 3e3 conversions run to
# millions of periods and `check` finds normal jerk broken, at 1e6 one move jumps 10 mm. At 1e3
# every move measured stays within the feed and the chord tolerance. Siemens accepts
# 0.0001 <= PW <= 3, Mitsubishi 0.0001 <= R <= 99.9999.
MAX_WEIGHT_RATIO = 1e3
# The narrowest non-empty knot span, as a share of the knot range: conversions measured correct
# down to 1e-16; 9-digit Fanuc knots (0.001 .. 999999.999) are never closer than 1e-9.
MIN_SPAN_REL = 1e-12
# |coordinate| in program units: the Fanuc range (9 digits, 999999.999 mm); the stepping loop
# resolves a position to 1e-10 there (its last bit), far below the finest output digit 1e-8
# (decimals <= 8, so the writer's int64 ticks stay below 1e14).
MAX_COORDINATE = 1e6


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class NurbsCurve:
    """A clamped NURBS curve of degree >= 1 in 3-D (2-D input has z = 0).

    knots: (n + degree + 2,) non-decreasing, clamped; points: (n + 1, 3) Cartesian (not
    pre-multiplied by the weights); weights: (n + 1,) positive. Build it with `build`, which
    checks everything and maps the knots onto [0, 1] (the input's parameter is
    u_origin + u_scale * u, `input_u`); the constructor itself is the unchecked path for
    already-valid arrays, taken as they are.
    """

    degree: int
    knots: np.ndarray
    points: np.ndarray
    weights: np.ndarray
    name: str = ""
    u_origin: float = 0.0  # the input's first knot
    u_scale: float = 1.0  # the input's knot range
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def build(cls, degree: object, knots: object, points: object, weights: object = None,
              name: str = "") -> NurbsCurve:
        """Check a user's curve field by field; raise CurveError naming the field and value.

        The knots are stored mapped onto [0, 1] and the weights scaled by a power of two (see the
        module docstring); the curve is the one given.
        """
        if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or degree < 1:
            raise CurveError(f"degree must be a whole number >= 1, not {degree!r}")
        if degree > MAX_DEGREE:
            raise CurveError(f"degree {degree} is above {MAX_DEGREE}, the highest nurbsfeed "
                             "evaluates accurately")
        degree = int(degree)
        try:
            pts = np.array(points, dtype=float)
        except (TypeError, ValueError):
            raise CurveError("control points must be lists of 2 or 3 numbers") from None
        if pts.ndim != 2 or pts.shape[1] not in (2, 3):
            raise CurveError("control points must be lists of 2 or 3 numbers, "
                             f"got an array of shape {pts.shape}")
        if not np.isfinite(pts).all():
            bad = int(np.argwhere(~np.isfinite(pts))[0][0])
            raise CurveError(f"control point {bad} is not finite: {pts[bad].tolist()}")
        far = far_control_point(pts)
        if far is not None:
            raise CurveError(far_message(far, pts[far]))
        if pts.shape[1] == 2:
            pts = np.column_stack([pts, np.zeros(len(pts))])
        n_ctrl = len(pts)
        if n_ctrl < degree + 1:
            raise CurveError(f"a curve of degree {degree} needs at least {degree + 1} control "
                             f"points, got {n_ctrl}")
        if weights is None:
            w = np.ones(n_ctrl)
        else:
            try:
                w = np.array(weights, dtype=float)
            except (TypeError, ValueError):
                raise CurveError("weights must be numbers") from None
            if w.shape != (n_ctrl,):
                raise CurveError(f"{n_ctrl} control points need {n_ctrl} weights, "
                                 f"got {w.size}")
            if not (np.isfinite(w).all() and (w > 0).all()):
                bad_w = np.flatnonzero(~(np.isfinite(w) & (w > 0)))
                raise CurveError(f"weight {bad_w[0]} must be positive and finite, "
                                 f"not {float(w[bad_w[0]])!r}")
            heavy, light = int(np.argmax(w)), int(np.argmin(w))
            if w[heavy] > MAX_WEIGHT_RATIO * w[light]:
                raise CurveError(f"weight {heavy} ({w[heavy]:g}) is more than "
                                 f"{MAX_WEIGHT_RATIO:g} times weight {light} ({w[light]:g}); "
                                 "nurbsfeed plans curves up to that ratio")
            w = np.ldexp(w, 1 - np.frexp(w[heavy])[1])  # exact: the largest now in [1, 2)
        try:
            k = np.array(knots, dtype=float)
        except (TypeError, ValueError):
            raise CurveError("knots must be numbers") from None
        check_knots(k, degree, n_ctrl)
        u_origin, u_scale = float(k[0]), float(k[-1] - k[0])
        unit = (k - u_origin) / u_scale  # monotone; 0 and 1 exactly at the ends
        return cls(degree, _readonly(unit), _readonly(pts), _readonly(w), name, u_origin, u_scale)

    # ---- basic facts -------------------------------------------------------------------------
    @property
    def u_min(self) -> float:
        return float(self.knots[self.degree])

    @property
    def u_max(self) -> float:
        return float(self.knots[-self.degree - 1])

    def input_u(self, u: np.ndarray | float) -> np.ndarray | float:
        """The input's own parameter at u (the knots as the user wrote them): (N,) -> (N,)."""
        return self.u_origin + self.u_scale * u

    def unit_u(self, u_input: float) -> float:
        """The inverse of `input_u`, computed as `build` maps the knots: an input knot gives
        exactly the stored knot."""
        return (u_input - self.u_origin) / self.u_scale

    @property
    def n_ctrl(self) -> int:
        return len(self.points)

    @cached_property
    def homogeneous(self) -> np.ndarray:
        """(n+1, 4): w_i P_i and w_i, the form the kernels evaluate."""
        return _readonly(np.column_stack([self.points * self.weights[:, None], self.weights]))

    @cached_property
    def span_polynomials(self) -> np.ndarray:
        """(n+1, 2, degree+1, 4): Taylor coefficients of (A, W) at both ends of each span
        (geometry.kernel.span_polynomials), the form every evaluation uses."""
        return _readonly(span_polynomials(self.knots, self.homogeneous, self.degree))

    @cached_property
    def span_breaks(self) -> np.ndarray:
        """(m,) the distinct knot values from u_min to u_max, in order."""
        inner = self.knots[self.degree:len(self.knots) - self.degree]  # non-decreasing
        first = np.empty(inner.size, dtype=bool)  # the first of each run of equal knots
        first[0] = True
        np.not_equal(inner[1:], inner[:-1], out=first[1:])
        return _readonly(inner[first])

    @cached_property
    def is_degenerate(self) -> bool:
        """All control points equal: a curve of zero length."""
        return bool(np.all(np.ptp(self.points, axis=0) == 0.0))

    # ---- vectorised evaluation -------------------------------------------------------------------
    def _eval(self, u: np.ndarray | float, order: int) -> np.ndarray:
        """(order+1, *shape(u), 3) via the compiled evaluator of geometry.kernel (u copied: a
        read-only u would compile the evaluator once more, for nothing)."""
        flat = np.array(np.ravel(u), dtype=float)
        out = np.empty((order + 1, flat.size, 3))
        eval_many(self.knots, self.span_polynomials, self.degree, flat, order, out)
        return out.reshape((order + 1,) + np.shape(u) + (3,))

    def point(self, u: np.ndarray | float) -> np.ndarray:
        """C(u): (N,) -> (N, 3), or () -> (3,)."""
        return self._eval(u, 0)[0]

    def derivatives(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """C, C', C'' at u: (N,) -> three (N, 3) arrays."""
        c0, c1, c2 = self._eval(u, 2)
        return c0, c1, c2

    def derivatives3(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The first three derivatives of C at u: (N,) -> three (N, 3) arrays (the path
        model's dkappa/ds and torsion need the third)."""
        _, c1, c2, c3 = self._eval(u, 3)
        return c1, c2, c3

    def speed(self, u: np.ndarray) -> np.ndarray:
        """|C'(u)|: (N,) -> (N,)."""
        c1 = self._eval(u, 1)[1]
        return np.sqrt(np.einsum("...i,...i->...", c1, c1))


def curvature_from_derivatives(c1: np.ndarray, c2: np.ndarray) -> np.ndarray:
    """kappa = |C' x C''| / |C'|^3: (..., 3), (..., 3) -> (...); NaN where C' = 0.

    The arithmetic of `geometry.kernel.curvature`, operation for operation, in numpy: the
    compiled loops take it from there, and no kernel compiles for the few calls from Python."""
    c1 = np.asarray(c1, dtype=float)
    c2 = np.asarray(c2, dtype=float)
    x1, y1, z1 = c1[..., 0], c1[..., 1], c1[..., 2]
    x2, y2, z2 = c2[..., 0], c2[..., 1], c2[..., 2]
    cx = y1 * z2 - z1 * y2
    cy = z1 * x2 - x1 * z2
    cz = x1 * y2 - y1 * x2
    cross = np.sqrt(cx * cx + cy * cy + cz * cz)
    speed = np.sqrt(x1 * x1 + y1 * y1 + z1 * z1)
    cube = speed * speed * speed  # underflows to 0 below ~1e-103 even where speed > 0
    return np.divide(cross, cube, out=np.full(cube.shape, np.nan), where=cube > 0.0)


def check_knots(k: np.ndarray, degree: int, n_ctrl: int) -> None:
    """The knot-vector rules every controller enforces; one CurveError per rule."""
    order = degree + 1
    if k.ndim != 1 or k.size != n_ctrl + order:
        raise CurveError(f"{n_ctrl} control points of degree {degree} need "
                         f"{n_ctrl + order} knots (control points + order), got {k.size}")
    if not np.isfinite(k).all():
        raise CurveError(f"knot {int(np.argmax(~np.isfinite(k)))} is not finite")
    widths = np.diff(k)
    if widths.min() < 0.0:
        i = int(np.flatnonzero(widths < 0.0)[0]) + 1
        raise CurveError(f"knots must not decrease: knot {i} ({k[i]:g}) < knot {i - 1} "
                         f"({k[i - 1]:g})")
    if k[order - 1] != k[0] or k[-order] != k[-1]:  # (non-decreasing: the ends' runs equal)
        raise CurveError(f"knot vector must be clamped: the first {order} and the last {order} "
                         f"knots must be equal (order {order})")
    if k[-1] <= k[0]:
        raise CurveError(f"knot range is empty: all knots are {k[0]:g}")
    knot_range = float(k[-1]) - float(k[0])  # (Python floats: inf, not a numpy warning)
    if not math.isfinite(knot_range):
        raise CurveError(f"knot range {k[0]:g} .. {k[-1]:g} is wider than a double holds")
    if widths[widths > 0.0].min() < MIN_SPAN_REL * knot_range:
        narrowest = int(np.argmin(np.where(widths > 0, widths, np.inf)))
        raise CurveError(f"knot span {float(k[narrowest])!r} .. {float(k[narrowest + 1])!r} is "
                         f"{widths[narrowest] / knot_range:.1e} of the knot range; at least "
                         f"{MIN_SPAN_REL:g}")
    interior = k[order:-order]  # non-decreasing: equal knots are neighbours
    if interior.size:
        if interior.size > degree and (interior[degree:] == interior[:-degree]).any():
            values, counts = np.unique(interior, return_counts=True)
            bad = values[np.argmax(counts > degree)]
            raise CurveError(f"interior knot {bad:g} is repeated {int(counts.max())} times; at "
                             f"most {degree} (the degree) keeps the curve connected")
        if interior[0] == k[0] or interior[-1] == k[-1]:
            raise CurveError(f"an end knot is repeated more than the order {order}")


def far_control_point(points: np.ndarray) -> int | None:
    """The first control point with a coordinate beyond MAX_COORDINATE, or None: (n, d) -> index.
    (The readers call it to place the error on that point's line.)"""
    if not np.abs(points).max(initial=0.0) > MAX_COORDINATE:  # (the common case: one pass)
        return None
    return int(np.flatnonzero((np.abs(points) > MAX_COORDINATE).any(axis=1))[0])


def far_message(index: int, point: np.ndarray) -> str:
    return (f"control point {index} {np.asarray(point, dtype=float).tolist()} has a coordinate "
            f"beyond +-{MAX_COORDINATE:.0f}, the range nurbsfeed converts")
