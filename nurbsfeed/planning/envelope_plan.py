"""The envelope planner's plan of one curve, made without the S-curve plan (design §2e).

The grid, its rests and the pointwise limit are all the envelope needs from planning: the rests
are the curve's ends, its stops (corners, cusps, reversals: the grid's) and any node whose limit
is 0; the pointwise limit (the paper's caps and the path model's static terms at every node)
says where cells must be cut finer before the first profile, and the first profile where they
must be cut again. `planner.plan_curve` plans the S-curve too, and keeps the faster plan, only
where the envelope gives way (`plan_envelope` returns None), where the curve stops inside, or
where the envelope's plan needs a uniform slowdown above FALLBACK_SLOWDOWN: beside a stop the
envelope can crawl where the S-curve's shoulders do not (a hairpin's 1.51 s against 0.61 s, a
near cusp beside repeated points 12.0 s against 0.69 s, tests/data), while on the 60 curves of
tests/data and samples without a stop it was at most 1.1 % slower (58 of them no slower).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from nurbsfeed.geometry.nurbs import NurbsCurve
from nurbsfeed.planning.envelope import envelope_schedule
from nurbsfeed.planning.grid import Grid
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.optimal import Schedule
from nurbsfeed.planning.plan import KIND_CORNER, KIND_CUSP, KIND_END

# an envelope plan slowed uniformly by more than this is compared with the S-curve plan
FALLBACK_SLOWDOWN = 1.05


def rest_nodes(grid: Grid, limit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nodes (R,) where every plan of this grid rests, ascending, and their kinds (R,):
    the ends, the grid's stops (a corner or, where the tangent turns back, a cusp), nodes of
    infinite curvature and nodes whose pointwise limit limit (M,) is 0."""
    last = grid.u.size - 1
    kind = np.full(grid.u.size, -1, dtype=np.int64)
    kind[~(limit > 0.0)] = KIND_CORNER
    kind[np.isinf(grid.kappa_1_mm)] = KIND_CORNER
    stops = np.asarray(grid.stop_index, dtype=np.int64)
    kind[stops] = np.where(np.asarray(grid.stop_cos) < 0.0, KIND_CUSP, KIND_CORNER)
    kind[[0, last]] = KIND_END
    nodes = np.flatnonzero(kind >= 0)
    return nodes, kind[nodes]


def plan_envelope(curve: NurbsCurve, grid: Grid, lim: Limits, limit: np.ndarray,
                  feed_at_u: Callable[[np.ndarray], np.ndarray],
                  slowdown: float = 1.0) -> tuple[Schedule, np.ndarray] | None:
    """The envelope's schedule of `curve` on `grid` under `lim`, and the kinds (R,) of the
    schedule's rests; None where it cannot plan (`envelope.envelope_schedule`). limit (M,):
    the pointwise speed limit at the grid's nodes; feed_at_u: parameters (N,) -> programmed
    feed (N,); slowdown: a uniform slowdown on top of the one the law needs."""
    rests, kinds = rest_nodes(grid, limit)
    if rests.size < 2:
        return None
    v_limit = np.where(np.isfinite(limit), limit, lim.feed_mm_s)
    schedule = envelope_schedule(curve, grid, lim, rests, v_limit, feed_at_u, slowdown)
    if schedule is None:
        return None
    kept = np.searchsorted(rests, schedule.rest_nodes)
    return schedule, kinds[kept]
