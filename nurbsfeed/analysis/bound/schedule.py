"""The reference schedule as found (analysis.bound.solve): `BoundSchedule`, b(s) at the grid's
nodes with the time law that follows from it, sampled at any time (`arc_at`, `points_at`), and
`cell_times`, the time each cell takes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nurbsfeed.analysis.bound.frames import derivatives3
from nurbsfeed.analysis.bound.grid import GAUSS_POINTS, gauss_length
from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.limits import Limits


def cell_times(b0: np.ndarray, b1: np.ndarray, d0: np.ndarray, d1: np.ndarray, h: np.ndarray,
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
            ahead = cell_times(b0, b1, d0, d1, h, rl, rr, mid) < target
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
            have = gauss_length(self.curve, u0, u, spans)
            speed = np.linalg.norm(derivatives3(self.curve, u, spans)[1], axis=1)
            u = np.clip(u - (have - want) / speed, u0, u1)
        return derivatives3(self.curve, u, spans)[0]

