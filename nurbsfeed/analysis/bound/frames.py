"""The geometry the reference schedule's constraints read (analysis.bound): C and its first three
derivatives from the span polynomials, and at any u the frame quantities T, K = kappa N and its
arc-length derivative K_s, computed as vectors (an inflection needs no Frenet frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.kernel import eval3_on_spans
from nurbsfeed.geometry.nurbs import NurbsCurve


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

