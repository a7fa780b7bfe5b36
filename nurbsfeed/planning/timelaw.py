"""The time law s(t) of a whole curve: closed-form constant-jerk pieces, evaluated at absolute time.

Piece i starts at t0[i] in state (s0, v0, a0) and runs with constant jerk j[i]:
    s(t) = s0 + v0 tau + a0 tau^2/2 + j tau^3/6,  tau = t - t0[i]
so any time is evaluated from the integer period index directly (t_k = k T), never by summing dt.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbsfeed.planning.scurve import transition_phases

ARC_BISECTIONS = 60


@dataclass(frozen=True, eq=False)
class TimeLaw:
    """(P,) arrays, one entry per constant-jerk piece; duration and length of the whole law."""

    t0_s: np.ndarray
    s0_mm: np.ndarray
    v0_mm_s: np.ndarray
    a0_mm_s2: np.ndarray
    jerk_mm_s3: np.ndarray
    key_t_s: np.ndarray  # (K,) time at which the law passes each key point
    duration_s: float
    length_mm: float

    @classmethod
    def from_segments(cls, s_key_mm: np.ndarray, v_key_mm_s: np.ndarray,
                      v_peak_mm_s: np.ndarray, hold_start_mm: np.ndarray,
                      hold_end_mm: np.ndarray, acc_mm_s2: float, jerk_mm_s3: float) -> "TimeLaw":
        """Chain the segments: hold at v_start, accelerate to v_peak, cruise, decelerate, hold.

        s_key, v_key: (K,); the others (K-1,). Each segment ends exactly at s_key[i+1]: the cruise
        takes up whatever distance the transitions leave, and the state is reset at every key.
        """
        t0, s0, v0, a0, jk = [], [], [], [], []
        key_t = np.zeros(len(s_key_mm))
        t = 0.0
        for i in range(len(s_key_mm) - 1):
            key_t[i] = t
            va, vb, vp = float(v_key_mm_s[i]), float(v_key_mm_s[i + 1]), float(v_peak_mm_s[i])
            length = float(s_key_mm[i + 1] - s_key_mm[i])
            if length <= 0.0:
                continue
            up = transition_phases(va, vp, acc_mm_s2, jerk_mm_s3)
            down = transition_phases(vp, vb, acc_mm_s2, jerk_mm_s3)
            d_up = 0.5 * (va + vp) * sum(d for d, _ in up)
            d_down = 0.5 * (vp + vb) * sum(d for d, _ in down)
            cruise = max(length - hold_start_mm[i] - hold_end_mm[i] - d_up - d_down, 0.0)
            phases: list[tuple[float, float]] = []
            if hold_start_mm[i] > 0.0 and va > 0.0:
                phases.append((hold_start_mm[i] / va, 0.0))
            phases += up
            if cruise > 0.0 and vp > 0.0:
                phases.append((cruise / vp, 0.0))
            phases += down
            if hold_end_mm[i] > 0.0 and vb > 0.0:
                phases.append((hold_end_mm[i] / vb, 0.0))
            s, v, a = float(s_key_mm[i]), va, 0.0
            for dur, j in phases:
                if dur <= 0.0:
                    continue
                t0.append(t), s0.append(s), v0.append(v), a0.append(a), jk.append(j)
                s += v * dur + a * dur**2 / 2.0 + j * dur**3 / 6.0
                v += a * dur + j * dur**2 / 2.0
                a += j * dur
                t += dur
        key_t[-1] = t
        arrays = [np.array(x, dtype=float) for x in (t0, s0, v0, a0, jk)] + [key_t]
        for arr in arrays:
            arr.setflags(write=False)
        return cls(*arrays, duration_s=t, length_mm=float(s_key_mm[-1]))

    @property
    def is_empty(self) -> bool:
        """A law of zero length (a curve whose control points are all equal)."""
        return self.t0_s.size == 0

    def _piece(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i = np.clip(np.searchsorted(self.t0_s, t_s, side="right") - 1, 0, len(self.t0_s) - 1)
        return i, t_s - self.t0_s[i]

    def at(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """s, v, a, j at absolute times (N,) -> four (N,) arrays."""
        if self.is_empty:
            zero = np.zeros(np.shape(t_s))
            return zero, zero, zero, zero
        i, tau = self._piece(np.asarray(t_s, dtype=float))
        v0, a0, j = self.v0_mm_s[i], self.a0_mm_s2[i], self.jerk_mm_s3[i]
        s = self.s0_mm[i] + tau * (v0 + tau * (a0 / 2.0 + tau * j / 6.0))
        v = v0 + tau * (a0 + tau * j / 2.0)
        return s, v, a0 + j * tau, j

    def increments(self, t_s: np.ndarray) -> np.ndarray:
        """s(t[k+1]) - s(t[k]) for sorted times (N+1,) -> (N,), computed piece-locally so that a
        tiny step far along the curve keeps its relative precision."""
        i, tau = self._piece(np.asarray(t_s, dtype=float))
        v0, a0, j = self.v0_mm_s[i], self.a0_mm_s2[i], self.jerk_mm_s3[i]
        local = tau * (v0 + tau * (a0 / 2.0 + tau * j / 6.0))
        return (self.s0_mm[i[1:]] - self.s0_mm[i[:-1]]) + (local[1:] - local[:-1])

    def speed_at_arc(self, s_mm: np.ndarray) -> np.ndarray:
        """v where the law passes arc length s: (M,) -> (M,), by bisection in each piece."""
        s_mm = np.asarray(s_mm, dtype=float)
        if self.is_empty:
            return np.zeros_like(s_mm)
        i = np.clip(np.searchsorted(self.s0_mm, s_mm, side="right") - 1, 0, len(self.s0_mm) - 1)
        end = np.append(self.t0_s[1:], self.duration_s)
        low = np.zeros_like(s_mm)
        high = end[i] - self.t0_s[i]
        v0, a0, j, s0 = self.v0_mm_s[i], self.a0_mm_s2[i], self.jerk_mm_s3[i], self.s0_mm[i]
        for _ in range(ARC_BISECTIONS):
            mid = 0.5 * (low + high)
            below = s0 + mid * (v0 + mid * (a0 / 2.0 + mid * j / 6.0)) < s_mm
            low = np.where(below, mid, low)
            high = np.where(below, high, mid)
        tau = 0.5 * (low + high)
        return v0 + tau * (a0 + tau * j / 2.0)
