"""The time law of a schedule (planning.schedule): where it is at every period, as the
constant-jerk pieces the interpolator reads (planning.timelaw).

Each stretch between rests runs in a whole number of periods: its duration D is stretched to
n = ceil(D slowdown / T) periods (time scaled by lambda = n T / D >= 1: v / lambda, a /
lambda^2, jerk / lambda^3, every limit kept). At every period k the schedule's own arc s_k and
speed v_k are found (the cell by its start time, then Newton's method on the cell's time: a
rest cell's in closed form, b = b_far y^(4/3) takes t = 3 h y^(1/3) / sqrt(b_far)), and one
piece joins each period to the next through s and v at both ends (a cubic Hermite in time):
the positions at the periods are the schedule's, and the law's acceleration and jerk inside a
period the cubic's, what `plan` and the trace show.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.schedule import Schedule, cell_times
from nurbsfeed.planning.timelaw import TimeLaw

NEWTON_STEPS = 30
GAUSS_X, GAUSS_W = np.polynomial.legendre.leggauss(4)
PIECES = 8  # equal parts of a cell, each timed by GAUSS_X
MIN_SHARE = 1e-6  # of a period: the shortest piece at a moving end


@jit
def _b_at(c, cells, q, x):
    """b at share x of inner cell q."""
    i0 = int(cells[q, 0])
    g0, g1, w0, h = cells[q, 1], cells[q, 2], cells[q, 3], cells[q, 4]
    xs = x * h
    s0 = (c[i0 + 1] - c[i0]) / g0
    dd = ((c[i0 + 2] - c[i0 + 1]) / g1 - s0) / h
    return max(w0 * c[i0] + (1.0 - w0) * c[i0 + 1] + s0 * xs + 0.5 * dd * xs * xs, 0.0)


@jit
def _piece_times(c, cells, q, out):
    """The time over each of the PIECES equal parts of inner cell q (Gauss-Legendre on each).
    Their sum is the cell's time as the law counts it, and `_time_to` adds up the same parts,
    so that the instants found in a cell never run out of it before its time is up (one rule
    for the whole and its parts, even where b nearly reaches 0 inside)."""
    part = 1.0 / PIECES
    for j in range(PIECES):
        out[j] = _gauss_time(c, cells, q, j * part, (j + 1) * part)


@jit
def _gauss_time(c, cells, q, x0, x1):
    half = 0.5 * (x1 - x0)
    mid = 0.5 * (x1 + x0)
    t = 0.0
    for g in range(GAUSS_X.size):
        t += GAUSS_W[g] / math.sqrt(max(_b_at(c, cells, q, mid + half * GAUSS_X[g]), 1e-300))
    return half * cells[q, 4] * t


@jit
def _time_to(c, cells, q, pieces, x):
    """The time from the start of inner cell q to share x of it, by `_piece_times`' rule."""
    j = min(int(x * PIECES), PIECES - 1)
    t = 0.0
    for i in range(j):
        t += pieces[i]
    return t + _gauss_time(c, cells, q, j / PIECES, x)


@jit
def _sample_stretch(c, cells, cell_node, q_first, q_last, s_nodes, node0, node1, times, rest_t,
                    rest_h, b_far, scale, instants, out_s, out_v):
    """s and v (n + 1,) at the n + 1 instants (schedule time) of one stretch, its time
    stretched by scale (schedule time = law time / scale). Cells q_first..q_last (inner) with
    their times (`_piece_times`), the rest cells' durations rest_t (2,), lengths rest_h (2,),
    far values b_far (2,) (at a moving end, rest_h = 0 and b_far its b); s_nodes: the nodes'
    arc, cell_node: each cell's first node, node0 and node1: the stretch's ends. The first
    instant is the start and the last the end (at their own speed). Within a cell each
    instant is found by Newton's method from the last one, safeguarded by bisection."""
    total = rest_t[0] + rest_t[1]
    for q in range(q_first, q_last + 1):
        total += times[q]
    n = instants.size - 1
    s_start = s_nodes[node0]
    s_end = s_nodes[node1]
    pieces = np.empty(PIECES)
    q = q_first
    _piece_times(c, cells, q, pieces)
    t_cell = rest_t[0]  # the schedule time at which cell q starts
    x_last = 0.0  # the share of cell q of the last instant found there
    for k in range(n + 1):
        t = instants[k]
        if k == 0 or k == n or t >= total:
            end = 0 if k == 0 else 1
            out_s[k] = s_start if end == 0 else s_end
            out_v[k] = math.sqrt(b_far[end]) / scale if rest_h[end] == 0.0 else 0.0
            continue
        # the rest cell at the start: y = (t sqrt(b) / (3 h))^3
        if rest_h[0] > 0.0 and t <= rest_t[0]:
            y = (t * math.sqrt(b_far[0]) / (3.0 * rest_h[0])) ** 3
            out_s[k] = s_start + rest_h[0] * y
            out_v[k] = math.sqrt(b_far[0] * y ** (4.0 / 3.0)) / scale
            continue
        if rest_h[1] > 0.0 and t >= total - rest_t[1]:  # the rest cell at the end
            y = ((total - t) * math.sqrt(b_far[1]) / (3.0 * rest_h[1])) ** 3
            out_s[k] = s_end - rest_h[1] * y
            out_v[k] = math.sqrt(b_far[1] * y ** (4.0 / 3.0)) / scale
            continue
        while q < q_last and t >= t_cell + times[q]:
            t_cell += times[q]
            q += 1
            _piece_times(c, cells, q, pieces)
            x_last = 0.0
        h = cells[q, 4]
        want = min(max(t - t_cell, 0.0), times[q])
        lo, hi = x_last, 1.0
        x = x_last
        for _ in range(NEWTON_STEPS):
            f = _time_to(c, cells, q, pieces, x) - want
            if f > 0.0:
                hi = x
            else:
                lo = x
            b = _b_at(c, cells, q, x)
            nx = x - f * math.sqrt(max(b, 1e-300)) / h
            if not lo <= nx <= hi:
                nx = 0.5 * (lo + hi)
            done = abs(nx - x) <= 1e-13
            x = nx
            if done:
                break
        out_s[k] = s_nodes[cell_node[q]] + x * h
        out_v[k] = math.sqrt(_b_at(c, cells, q, x)) / scale
        x_last = x


@jit
def _law_times(c, cells, times):
    """Each inner cell's time (Q,) as the law counts it (`_piece_times`)."""
    pieces = np.empty(PIECES)
    for q in range(cells.shape[0]):
        _piece_times(c, cells, q, pieces)
        times[q] = pieces.sum()


def law_instants(duration: float, period_s: float, slowdown: float, open_start: bool,
                 open_end: bool) -> tuple[np.ndarray, float]:
    """A stretch's law instants (n + 1,) from 0 and the time scale (law time over schedule
    time): whole periods, its duration stretched to the next whole one (module docstring). A
    moving end keeps its speed, so a stretch that has one is not stretched (nor slowed:
    path_plan refuses a slowdown there): where it ends moving, its last instant is its end (a
    share of a period); where it starts moving and ends at rest, it holds the rest up to the
    next whole period (a piece of its own: no motion in it)."""
    if not (open_start or open_end):
        n = max(2, math.ceil(duration * slowdown / period_s * (1.0 - 1e-12)))
        return np.arange(n + 1) * period_s, n * period_s / duration
    n = max(1, math.ceil(duration / period_s * (1.0 - 1e-12)))
    law_t = np.arange(n + 1) * period_s
    if open_end:
        # a last share far below a period joins the period before it
        if n > 1 and duration - (n - 1) * period_s < MIN_SHARE * period_s:
            law_t = law_t[:-1]
        law_t[-1] = duration
    elif law_t[-1] - duration > MIN_SHARE * period_s:
        law_t = np.concatenate([law_t[:-1], [duration], law_t[-1:]])
    return law_t, 1.0


def schedule_law(schedule: Schedule, period_s: float, extra_slowdown: float = 1.0
                 ) -> tuple[TimeLaw, np.ndarray]:
    """The law (module docstring), and the time (R,) it passes each rest."""
    lay = schedule.layout
    times = np.empty(lay.cells.shape[0] + 2 * lay.first.size)
    cell_times(np.array(schedule.c), lay.cells, lay.first, lay.last, lay.rest_h, times)
    q_n = lay.cells.shape[0]
    _law_times(schedule.c, lay.cells, times)
    rests = np.flatnonzero(lay.rest)
    slow = schedule.slowdown * extra_slowdown
    parts: list[list[np.ndarray]] = [[] for _ in range(5)]
    key_t = [0.0]
    q0 = 0
    for s in range(lay.first.size):
        n_cells = lay.last[s] - lay.first[s] - 1
        q1 = q0 + n_cells - 1
        rest_t = times[q_n + 2 * s:q_n + 2 * s + 2].copy()
        duration = float(rest_t.sum() + times[q0:q1 + 1].sum())
        law_t, scale = law_instants(duration, period_s, slow, lay.is_open(s, 0),
                                    lay.is_open(s, 1))
        instants = np.minimum(law_t / scale, duration)
        n = law_t.size - 1
        s_k = np.empty(n + 1)
        v_k = np.empty(n + 1)
        b_far = np.array([schedule.c[lay.first[s]], schedule.c[lay.last[s]]])
        _sample_stretch(schedule.c, lay.cells, lay.cell_node, q0, q1, lay.s_mm, rests[s],
                        rests[s + 1], times, rest_t, lay.rest_h[s].copy(), b_far, scale,
                        instants, s_k, v_k)
        if not lay.is_open(s, 1):  # the rest held (the sampler's sum of times may round below)
            done = instants >= duration
            s_k[done], v_k[done] = lay.s_mm[rests[s + 1]], 0.0
        s_k = np.maximum.accumulate(s_k)
        gain = np.diff(s_k)
        dt = np.diff(law_t)
        c2 = (3.0 * gain - dt * (2.0 * v_k[:-1] + v_k[1:])) / dt**2
        c3 = (-2.0 * gain + dt * (v_k[:-1] + v_k[1:])) / dt**3
        start = key_t[-1]
        t0 = start + law_t[:-1]
        for out, value in zip(parts, (t0, s_k[:-1], v_k[:-1], 2.0 * c2, 6.0 * c3)):
            out.append(value)
        key_t.append(start + float(law_t[-1]))
        q0 = q1 + 1
    key = np.array(key_t)
    t0, s0, v0, a0, jerk = (np.concatenate(p) for p in parts)
    law = TimeLaw.from_pieces(t0, s0, v0, a0, jerk, key, float(key[-1]))
    return law, key
