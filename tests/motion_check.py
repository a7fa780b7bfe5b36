"""What the machine would do, measured from positions over time (tests only).

The planner's own quantities (the time law's v, a, j) are not used: the interpolation points
P_k are taken as positions at t_k = k T, and speed and acceleration come from their divided
differences, as a controller executing one move per period would produce them:

    v_k = |P_k+1 - P_k| / T                                   (the move's feed)
    a_k = (P_k+1 - 2 P_k + P_k-1) / T^2                       (second difference)
    tangential a = a_k . t_k, normal a = |a_k - (a_k . t_k) t_k|, t_k = unit(P_k+1 - P_k-1)

The second difference of a smooth motion is its acceleration to O(T^2 j'), and the chordal
normal part is v^2 kappa to O((kappa v T)^2): both within FD_REL of the truth here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tests.gcode_parse import moves

FD_REL = 0.02  # finite differences at one period: within 2 % of the continuous quantity


@dataclass(frozen=True)
class Motion:
    speed_mm_s: np.ndarray  # (N-1,) per move
    tangential_acc_mm_s2: np.ndarray  # (N-2,) at the inner points
    normal_acc_mm_s2: np.ndarray  # (N-2,)


def motion(points: np.ndarray, period_s: float) -> Motion:
    """points (N, 3) one period apart -> speeds and accelerations from positions."""
    step = np.diff(points, axis=0)
    speed = np.linalg.norm(step, axis=1) / period_s
    acc = (step[1:] - step[:-1]) / period_s**2
    across = points[2:] - points[:-2]
    norm = np.linalg.norm(across, axis=1)
    tangent = np.divide(across, norm[:, None], out=np.zeros_like(across),
                        where=norm[:, None] > 0)
    along = np.einsum("ij,ij->i", acc, tangent)
    normal = np.linalg.norm(acc - along[:, None] * tangent, axis=1)
    return Motion(speed, np.abs(along), normal)


def written_moves(text: str, start: np.ndarray, period_s: float,
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The G1 moves of one replaced block in `text` (our own output: comments, G90/G91 and F
    restores skipped): written points (M, 3) and the period index each arrives at (M,), from
    the move lengths and F words (a move of length d at F lasts d / (F / 60))."""
    points, feeds, _ = moves(text, start)
    previous = np.vstack([np.asarray(start, dtype=float)[None, :], points[:-1]])
    duration_s = np.linalg.norm(points - previous, axis=1) / (feeds / 60.0)
    return points, np.rint(np.cumsum(duration_s) / period_s).astype(int)
