"""What the schedule's cells and their checks share (design §2d): where a cell's limits are read,
how one point's geometry is laid out, and the spline's weights at a share of a cell.

b on an inner cell is a quadratic in arc length fixed by three consecutive coefficients
(planning.cells: at the Greville abscissae, g0 and g1 apart, the knot between the first two
at weight w0): b, b' and b'' anywhere on the cell are linear in them (`point_weights`).
"""

from __future__ import annotations

from dataclasses import dataclass

from nurbsfeed.jit import jit

# the geometry of one point, as the rows read it (`cells.Layout.geo`, (Q, 3, G_SIZE)): kappa,
# T (3), K = kappa N (3), K_s = dK/ds (3), the jump D of kappa N at a knot (3), the cap on b
G_KAPPA, G_T, G_K, G_KS, G_D, G_CAP = 0, 1, 4, 7, 10, 13
G_SIZE = 14
POINTS = (0.0, 0.5, 1.0)  # where a cell's limits are read: its start, middle and end
BETWEEN = (0.25, 0.75)  # ... and checked once planned (`nodes.cut_cells`)


@jit
def point_weights(g0, g1, w0, h, x, out):
    """The weights (3, 3) of an inner cell's three coefficients in b (row 0), b' (row 1) and
    b'' (row 2) at share x of the cell (planning.cells, module docstring)."""
    xs = x * h
    for j in range(3):
        s0 = -1.0 / g0 if j == 0 else (1.0 / g0 if j == 1 else 0.0)
        s1 = 0.0 if j == 0 else (-1.0 / g1 if j == 1 else 1.0 / g1)
        dd = (s1 - s0) / h
        b0 = w0 if j == 0 else (1.0 - w0 if j == 1 else 0.0)
        out[0, j] = b0 + s0 * xs + 0.5 * dd * xs * xs
        out[1, j] = s0 + dd * xs
        out[2, j] = dd


@dataclass(frozen=True)
class EndState:
    """The motion's state at one end of a chain it does not rest at: the path speed (> 0)
    and the tangential acceleration, d v / dt (planning.path_plan: the chain's look-ahead
    runs on across its ends, design §3b)."""

    speed_mm_s: float
    acc_mm_s2: float

    @property
    def b(self) -> float:
        """b = v^2 there."""
        return self.speed_mm_s**2

    @property
    def db_ds(self) -> float:
        """b' = db / ds = 2 a there."""
        return 2.0 * self.acc_mm_s2


@dataclass(frozen=True)
class ChainEnds:
    """How a chain starts and ends: at rest (None), as every curve alone does, or moving."""

    start: EndState | None = None
    end: EndState | None = None

    @property
    def moving(self) -> tuple[bool, bool]:
        return self.start is not None, self.end is not None

    def side(self, i: int) -> EndState | None:
        return self.start if i == 0 else self.end


AT_REST = ChainEnds()
