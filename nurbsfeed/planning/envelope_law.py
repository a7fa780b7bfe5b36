"""The envelope planner's time law (planning.envelope, design §2e): the schedule's own s, v and a
sampled and joined in time, so that the positions at the periods are the schedule's."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.planning.optimal import (
    SAMPLES_PER_PERIOD,
    _arc_at,
    _cell_times,
    _hermite_basis,
    _Nodes,
)
from nurbsfeed.planning.timelaw import TimeLaw

LAW_CHUNK = 1 << 14  # samples `sampled_law` finds the arc length of at once


def _b_at(nodes: _Nodes, b: np.ndarray, d: np.ndarray, s_mm: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray]:
    """b and b' (N,) at arc lengths s_mm (N,) of the schedule: the cubic Hermite cell through
    the nodes' b and d, b_far y^(4/3) in a cell beside a rest."""
    h, rest = nodes.h_mm, nodes.rest
    cell = np.clip(np.searchsorted(nodes.s_mm, s_mm, side="right") - 1, 0, h.size - 1)
    hc = h[cell]
    x = np.clip((s_mm - nodes.s_mm[cell]) / hc, 0.0, 1.0)
    h00, h10, h01, h11 = _hermite_basis(x)
    value = h00 * b[cell] + h10 * hc * d[cell] + h01 * b[cell + 1] + h11 * hc * d[cell + 1]
    slope = ((6 * x**2 - 6 * x) * b[cell] / hc + (3 * x**2 - 4 * x + 1) * d[cell]
             + (-6 * x**2 + 6 * x) * b[cell + 1] / hc + (3 * x**2 - 2 * x) * d[cell + 1])
    from_rest, to_rest = rest[cell], rest[cell + 1]
    y = np.where(from_rest, x, 1.0 - x)
    far = np.where(from_rest, b[np.minimum(cell + 1, b.size - 1)], b[cell])
    value = np.where(from_rest | to_rest, far * y ** (4.0 / 3.0), value)
    slope = np.where(from_rest, 4.0 / 3.0 * far * np.cbrt(y) / hc,
                     np.where(to_rest, -4.0 / 3.0 * far * np.cbrt(y) / hc, slope))
    return np.maximum(value, 0.0), slope


def sampled_law(nodes: _Nodes, b: np.ndarray, d: np.ndarray, period_s: float,
                slowdown: float = 1.0) -> TimeLaw:
    """The time law of the schedule b, d (M,) at the nodes, each stretch between rests slowed
    by `slowdown` and stretched to whole periods: the schedule's own s, v and a at
    SAMPLES_PER_PERIOD instants a period, joined by constant-jerk pieces through s and v at
    both ends of each (a cubic Hermite in time). The positions at the periods are the
    schedule's exactly; a spline through them instead rang where b'' changes from cell to cell
    (its jerk 2x the schedule's beside such a cell)."""
    cell_t = _cell_times(nodes, b, d)
    t_node = np.concatenate([[0.0], np.cumsum(cell_t)])
    rests = np.flatnonzero(nodes.rest)
    pieces: list[list[np.ndarray]] = [[] for _ in range(5)]
    key_t = [0.0]
    step = period_s / SAMPLES_PER_PERIOD
    for first, last in zip(rests[:-1], rests[1:]):
        duration = t_node[last] - t_node[first]
        periods = max(2, math.ceil(duration * slowdown / period_s * (1.0 - 1e-12)))
        t = np.arange(periods * SAMPLES_PER_PERIOD + 1) * step
        stretch = duration / t[-1]  # schedule time per law time (<= 1)
        # in chunks: _arc_at holds a few dozen numbers a sample (a 140 s stretch took 233 MB
        # at once)
        s = np.concatenate([_arc_at(nodes, b, d, t_node, cell_t,
                                    t_node[first] + t[k:k + LAW_CHUNK] * stretch)
                            for k in range(0, t.size, LAW_CHUNK)])
        s[0], s[-1] = nodes.s_mm[first], nodes.s_mm[last]
        s = np.maximum.accumulate(s)
        value, slope = _b_at(nodes, b, d, s)
        v = np.sqrt(value) * stretch
        v[0] = v[-1] = 0.0
        gain = np.diff(s)
        c2 = (3.0 * gain - step * (2.0 * v[:-1] + v[1:])) / step**2
        c3 = (-2.0 * gain + step * (v[:-1] + v[1:])) / step**3
        start = key_t[-1]
        for out, value_ in zip(pieces, (start + t[:-1], s[:-1], v[:-1], 2.0 * c2, 6.0 * c3)):
            out.append(value_)
        key_t.append(start + t[-1])
    times = np.array(key_t)
    t0, s0, v0, a0, jk = (np.concatenate(p) for p in pieces)
    return TimeLaw.from_pieces(t0, s0, v0, a0, jk, times, float(times[-1]))
