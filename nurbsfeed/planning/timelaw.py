"""The time law s(t) of a whole curve: closed-form constant-jerk pieces, evaluated at absolute time.

Piece i starts at t0[i] in state (s0, v0, a0) and runs with constant jerk j[i]:
    s(t) = s0 + v0 tau + a0 tau^2/2 + j tau^3/6,  tau = t - t0[i]
so any time is evaluated from the integer period index directly (t_k = k T), never by summing dt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nurbsfeed.jit import jit
from nurbsfeed.planning.scurve import transition_phases

ARC_ITERATIONS = 80  # Newton converges in ~3 from a warm start; bisection fallback needs <= 60
ARC_TAU_REL_TOL = 1e-12  # tau, hence v, to 1e-12: the planner checks v to 1e-9
PHASES_PER_SEGMENT = 9  # hold, 3 up, cruise, 3 down, hold


@jit
def chain_segments(s_key, v_key, v_peak, hold_start, hold_end, acc, jerk):
    """Chain the segments into constant-jerk pieces: hold at v_key[i], accelerate to v_peak[i],
    cruise, decelerate to v_key[i+1], hold. s_key, v_key: (K,); the others (K-1,). Each segment
    ends exactly at s_key[i+1]: the cruise takes up whatever distance the transitions and holds
    leave, and the state is reset at every key. Returns the pieces' t0, s0, v0, a0, jerk (P,),
    the time at each key (K,) and the duration (`TimeLaw.from_pieces` takes them as they are)."""
    n_seg = s_key.size - 1
    cap = n_seg * PHASES_PER_SEGMENT
    t0 = np.empty(cap)
    s0 = np.empty(cap)
    v0 = np.empty(cap)
    a0 = np.empty(cap)
    jk = np.empty(cap)
    key_t = np.empty(s_key.size)  # every key's time is written below
    durations = np.empty(PHASES_PER_SEGMENT)
    jerks = np.empty(PHASES_PER_SEGMENT)
    count = 0
    t = 0.0
    for i in range(n_seg):
        key_t[i] = t
        va = v_key[i]
        vb = v_key[i + 1]
        vp = v_peak[i]
        length = s_key[i + 1] - s_key[i]
        if length <= 0.0:
            continue
        n = 0
        if hold_start[i] > 0.0 and va > 0.0:
            durations[n] = hold_start[i] / va
            jerks[n] = 0.0
            n += 1
        m = transition_phases(va, vp, acc, jerk, durations[n:], jerks[n:])
        # durations summed by loops: ndarray.sum would compile numba's own reduction
        t_up = 0.0
        for q in range(n, n + m):
            t_up += durations[q]
        d_up = 0.5 * (va + vp) * t_up
        n += m
        n_cruise = n
        n += 1
        m = transition_phases(vp, vb, acc, jerk, durations[n:], jerks[n:])
        t_down = 0.0
        for q in range(n, n + m):
            t_down += durations[q]
        d_down = 0.5 * (vp + vb) * t_down
        n += m
        if hold_end[i] > 0.0 and vb > 0.0:
            durations[n] = hold_end[i] / vb
            jerks[n] = 0.0
            n += 1
        # the cruise takes whatever distance the transitions and holds leave
        cruise = max(length - hold_start[i] - hold_end[i] - d_up - d_down, 0.0)
        durations[n_cruise] = cruise / vp if vp > 0.0 else 0.0
        jerks[n_cruise] = 0.0
        s = s_key[i]
        v = va
        a = 0.0
        for q in range(n):
            dur = durations[q]
            if dur <= 0.0:
                continue
            j = jerks[q]
            t0[count] = t
            s0[count] = s
            v0[count] = v
            a0[count] = a
            jk[count] = j
            count += 1
            s += v * dur + a * dur * dur / 2.0 + j * dur * dur * dur / 6.0
            v += a * dur + j * dur * dur / 2.0
            a += j * dur
            t += dur
    key_t[n_seg] = t
    return t0[:count].copy(), s0[:count].copy(), v0[:count].copy(), a0[:count].copy(), \
        jk[:count].copy(), key_t, t


@jit
def _last_at_or_below(starts, x, i):
    """The last index with starts[index] <= x (0 if none), for queries that mostly increase:
    walk forward from the previous answer i, binary search when x went back."""
    n = starts.size
    if x < starts[i]:
        lo = 0
        hi = n - 1
        while lo < hi:
            mid = (lo + hi + 1) // 2
            if starts[mid] <= x:
                lo = mid
            else:
                hi = mid - 1
        i = lo
    while i + 1 < n and starts[i + 1] <= x:
        i += 1
    return i


@jit
def speed_at_arc(t0, s0, v0, a0, jk, duration, s_query, floor, out):
    """v where the law passes each arc length s_query (M,) -> out (M,), wherever it could
    exceed floor (M,); 0 where it cannot (pass floor = -inf for every speed).

    The piece is found by a pointer that moves forward for increasing queries (the grid's
    nodes), by binary search otherwise. v over a piece is bounded by its values at both ends
    and at a turning point inside (the S-curve's pieces have none: the acceleration keeps its
    sign within each); at or below floor, the piece is not solved. Otherwise, within a piece
    (state v0, a0, jerk j at its start):
    - j = 0, a0 = 0 (cruise, hold): v = v0;
    - j = 0: v^2 = v0^2 + 2 a0 (s - s0), exactly;
    - otherwise s(tau) = v0 tau + a0 tau^2/2 + j tau^3/6 is solved for tau by Newton's method
      (f' = v >= 0) kept inside a shrinking bracket, bisecting when a step leaves it; the start
      is the previous query's tau in the same piece, moved on by ds / v.
    """
    n = t0.size
    # not a literal 0: numba would compile _last_at_or_below for Literal[int](0) as well, while
    # it types the loop, and never run that version
    i = np.int64(0)
    tau = 0.0
    for q in range(s_query.size):
        s = s_query[q]
        previous = i
        i = _last_at_or_below(s0, s, i)
        vi = v0[i]
        ai = a0[i]
        ji = jk[i]
        span = (t0[i + 1] if i + 1 < n else duration) - t0[i]
        bound = max(vi, vi + span * (ai + span * ji / 2.0))
        if ji != 0.0 and 0.0 < -ai / ji < span:
            bound = max(bound, vi - ai * ai / (2.0 * ji))
        if bound <= floor[q]:
            out[q] = 0.0
            continue
        target = s - s0[i]
        if ji == 0.0:
            if ai == 0.0:
                out[q] = vi
            else:
                out[q] = math.sqrt(max(vi * vi + 2.0 * ai * target, 0.0))
            continue
        if target <= 0.0:  # at the piece's start (a triple root when it starts from rest)
            out[q] = vi
            continue
        low = 0.0
        high = span
        if i == previous and 0.0 < tau < high:  # the previous tau, moved on by ds / v
            v_prev = vi + tau * (ai + tau * ji / 2.0)
            if v_prev > 0.0:
                tau += (target - tau * (vi + tau * (ai / 2.0 + tau * ji / 6.0))) / v_prev
        if not 0.0 < tau < high:
            tau = 0.5 * high
        for _ in range(ARC_ITERATIONS):
            f = tau * (vi + tau * (ai / 2.0 + tau * ji / 6.0)) - target
            if f == 0.0:
                break
            if f < 0.0:
                low = tau
            else:
                high = tau
            slope = vi + tau * (ai + tau * ji / 2.0)
            step = tau - f / slope if slope > 0.0 else -1.0
            if not low < step < high:
                step = 0.5 * (low + high)
            converged = (abs(step - tau) <= ARC_TAU_REL_TOL * tau
                         or high - low <= ARC_TAU_REL_TOL * high)
            tau = step
            if converged:
                break
        out[q] = vi + tau * (ai + tau * ji / 2.0)


@jit
def evaluate(t0, s0, v0, a0, jk, t, piece, local, v, a, j):
    """The law at times t (M,): piece index (the last piece starting at or before t, the first
    before the law starts), local arc s - s0[piece], v, a and j, each (M,).

    Increasing times are fastest: the piece is found by a pointer that moves forward, by binary
    search otherwise.
    """
    i = np.int64(0)  # not a literal 0 (see speed_at_arc)
    for q in range(t.size):
        tq = t[q]
        i = _last_at_or_below(t0, tq, i)
        tau = tq - t0[i]
        piece[q] = i
        local[q] = tau * (v0[i] + tau * (a0[i] / 2.0 + tau * jk[i] / 6.0))
        v[q] = v0[i] + tau * (a0[i] + tau * jk[i] / 2.0)
        a[q] = a0[i] + jk[i] * tau
        j[q] = jk[i]


@dataclass(frozen=True, eq=False)
class TimeLaw:
    """(P,) arrays, one entry per constant-jerk piece; the duration of the whole law."""

    t0_s: np.ndarray
    s0_mm: np.ndarray
    v0_mm_s: np.ndarray
    a0_mm_s2: np.ndarray
    jerk_mm_s3: np.ndarray
    key_t_s: np.ndarray  # (K,) time at which the law passes each key point
    duration_s: float

    @classmethod
    def from_pieces(cls, t0_s: np.ndarray, s0_mm: np.ndarray, v0_mm_s: np.ndarray,
                    a0_mm_s2: np.ndarray, jerk_mm_s3: np.ndarray, key_t_s: np.ndarray,
                    duration_s: float) -> TimeLaw:
        """The law of the pieces `chain_segments` made (the planner's compiled loop)."""
        arrays = (t0_s, s0_mm, v0_mm_s, a0_mm_s2, jerk_mm_s3, key_t_s)
        for arr in arrays:
            arr.setflags(write=False)
        return cls(*arrays, duration_s=float(duration_s))

    @cached_property
    def pieces(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """t0, s0, v0, a0 and jerk (P,) as the kernels take them: writable copies, the array type
        the planner's compiled loop passes them (`chain_segments`' own arrays). A read-only
        array is another type to numba: every kernel it reaches would compile a second time."""
        return (self.t0_s.copy(), self.s0_mm.copy(), self.v0_mm_s.copy(), self.a0_mm_s2.copy(),
                self.jerk_mm_s3.copy())

    def speed_at(self, s_mm: np.ndarray) -> np.ndarray:
        """v where the law passes each arc length s_mm (M,) -> (M,) (see `speed_at_arc`)."""
        s_query = np.array(s_mm, dtype=float)
        out = np.empty(s_query.size)
        speed_at_arc(*self.pieces, self.duration_s, s_query, np.full(s_query.size, -np.inf), out)
        return out

    def sample(self, t_s: np.ndarray) -> tuple[np.ndarray, ...]:
        """At times (N,) (increasing is fastest): piece index, arc length within the piece
        (s - s0_mm[piece]), v, a, j: five (N,) arrays (see `evaluate`)."""
        t_s = np.ascontiguousarray(t_s, dtype=float)
        piece = np.empty(t_s.size, dtype=np.int64)
        local, v, a, j = (np.empty(t_s.size) for _ in range(4))
        evaluate(*self.pieces, t_s, piece, local, v, a, j)
        return piece, local, v, a, j
