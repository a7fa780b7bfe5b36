"""The --trace CSV (design §5): a row per interpolation point at full precision, written chunk
by chunk beside the G-code (pipeline.convert_window, windowed.convert_windows).
"""

from __future__ import annotations

from typing import BinaryIO

import numpy as np

from nurbsfeed.interpolate.stepping import PointChunk
from nurbsfeed.planning.chain import Chain

TRACE_HEADER = "curve,k,t,u,s,v,a,j,x,y,z\n"
TRACE_ROW = ",".join(["%d", "%d"] + ["%.17g"] * 9) + "\n"


def write_trace_rows(out: BinaryIO, curve_index: int, chunk: PointChunk, period_s: float,
                     s_mm: float, chain: Chain) -> float:
    """Trace rows (design §5) of one chunk of points at full precision; s_mm: the arc at the
    point before the chunk (0 before the first). Across a chain (design §3b) k, t and s run on
    from the chain's start and each row names the curve its point lies in (curve_index is the
    chain's first), with u in that curve's own knot range (`NurbsCurve.input_u`). Returns the
    arc at its last point."""
    n = chunk.u.size
    s = np.cumsum(np.concatenate(([s_mm], chunk.ds_mm)))[1:]
    v, a, j = chunk.kinematics()
    piece = chain.piece_of(chunk.u)
    u_input = np.empty(n)
    for p in np.unique(piece):
        at = piece == p
        curve = chain.pieces[p]
        u_input[at] = curve.input_u(chain.piece_u(chunk.u[at], piece[at])
                                    if len(chain.pieces) > 1 else chunk.u[at])
    table = np.column_stack([curve_index + piece, np.arange(chunk.k0, chunk.k0 + n),
                             np.arange(chunk.k0, chunk.k0 + n, dtype=float) * period_s,
                             u_input, s, v, a, j, chunk.points])
    # the rows as np.savetxt writes them, which builds a class per call: garbage that only the
    # cyclic collector frees, a call per chunk
    for row in table:
        out.write((TRACE_ROW % tuple(row)).encode("ascii"))
    return float(s[-1])

