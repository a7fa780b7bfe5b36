"""Arc length by adaptive Simpson quadrature of |C'(u)| (paper Eq. 21, with the norms it omits).

All intervals are refined together: each round evaluates the speed at the new quarter points of
every interval that has not converged, in one vectorised call. An interval is accepted when
|S(left) + S(right) - S(whole)| <= 15 tol (the classic criterion) and gets the Richardson term.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

MAX_DEPTH = 40


def simpson_lengths(speed: Callable[[np.ndarray], np.ndarray], nodes: np.ndarray,
                    speed_at_nodes: np.ndarray, tol_mm: np.ndarray) -> np.ndarray:
    """Integral of speed between consecutive nodes, each to tol_i: (M+1,), (M+1,), (M,) -> (M,).

    speed_at_nodes: |C'| at the nodes, already known to the caller (the grid computes it with
    the curvature), so the first round evaluates only the midpoints.
    """
    a = np.asarray(nodes[:-1], dtype=float)
    b = np.asarray(nodes[1:], dtype=float)
    owner = np.arange(a.size)
    m = 0.5 * (a + b)
    fa, fb = speed_at_nodes[:-1], speed_at_nodes[1:]
    fm = speed(m)
    whole = (b - a) / 6.0 * (fa + 4.0 * fm + fb)
    tol = np.broadcast_to(np.asarray(tol_mm, dtype=float), a.shape).copy()
    total = np.zeros(a.size)
    depth = 0
    while owner.size:
        m = 0.5 * (a + b)
        fl_fr = speed(np.concatenate([0.5 * (a + m), 0.5 * (m + b)]))
        flm, frm = fl_fr[: a.size], fl_fr[a.size:]
        left = (m - a) / 6.0 * (fa + 4.0 * flm + fm)
        right = (b - m) / 6.0 * (fm + 4.0 * frm + fb)
        err = left + right - whole
        done = (np.abs(err) <= 15.0 * tol) | (depth >= MAX_DEPTH)
        np.add.at(total, owner[done], (left + right + err / 15.0)[done])
        keep = ~done
        owner = np.concatenate([owner[keep], owner[keep]])
        a, b = np.concatenate([a[keep], m[keep]]), np.concatenate([m[keep], b[keep]])
        fa, fb = np.concatenate([fa[keep], fm[keep]]), np.concatenate([fm[keep], fb[keep]])
        fm = np.concatenate([flm[keep], frm[keep]])
        whole = np.concatenate([left[keep], right[keep]])
        tol = np.concatenate([tol[keep], tol[keep]]) / 2.0
        depth += 1
    return total
