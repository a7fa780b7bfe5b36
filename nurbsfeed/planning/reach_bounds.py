"""A cell's rows (planning.reach_rows) as one knot's set reads them (design §2d, "The sets"):
bounds on the next knot's acceleration a1 = a + h u, affine in b, from above and from below;
bounds on b alone, affine in a; those another one is tighter than everywhere in the box the set
lies in dropped; and the last cell's rows with the stretch's end folded in."""

from __future__ import annotations

import numpy as np

from nurbsfeed.jit import jit

GAP_TOL_REL = 1e-9  # of the acceleration scale: a gap this far below 0 still counts as met
# a moving end is met within this share of its b: its set is a line, kept this thick
MOVING_END_REL = 1e-6
# ... or, for the reachable sets (what they give is a bound, not a motion), this much
LOOSE_END_REL = 1e-3


@jit
def split_rows(rows, n, h, up, down, bounds):
    """A cell's rows (n, 4) (cb b + ca a + cu u <= d) arranged for the levels: a row with u
    bounds a1 = a + h u by p + q a + s b, from above where its u coefficient is positive
    (into up (U, 3) as (p, q, s)), from below where negative (into down); a row without u
    bounds b by alpha + beta a (into bounds (B, 3) as (sign, alpha, beta): sign 1 above,
    -1 below) or a alone. Returns (U, D, B, a_min, a_max): the range of a the last ones
    leave (a_min > a_max: none)."""
    nu = 0
    nd = 0
    nb = 0
    a_min = -np.inf
    a_max = np.inf
    for r in range(n):
        cb, ca, cu, d = rows[r, 0], rows[r, 1], rows[r, 2], rows[r, 3]
        if cu != 0.0:
            p = h * d / cu
            q = 1.0 - h * ca / cu
            s = -h * cb / cu
            if cu > 0.0:
                up[nu, 0], up[nu, 1], up[nu, 2] = p, q, s
                nu += 1
            else:
                down[nd, 0], down[nd, 1], down[nd, 2] = p, q, s
                nd += 1
        elif cb != 0.0:
            bounds[nb, 0] = 1.0 if cb > 0.0 else -1.0
            bounds[nb, 1] = d / cb
            bounds[nb, 2] = -ca / cb
            nb += 1
        elif ca > 0.0:
            a_max = min(a_max, d / ca)
        elif ca < 0.0:
            a_min = max(a_min, d / ca)
        elif d < -GAP_TOL_REL * abs(d):
            a_min, a_max = 1.0, -1.0
    return nu, nd, nb, a_min, a_max


@jit
def prune(rows, n, sign, a_lo, a_hi, b_hi):
    """Drops the bounds on a1 (rows (n, 3) as `split_rows` gives them: from above with sign 1,
    from below with sign -1) that another one is tighter than everywhere in the box a in
    [a_lo, a_hi], b in [0, b_hi] (where this knot's set lies), keeping the order of the rest;
    returns their count. Of some 19 bounds a side a cell's set meets some 5: every level reads
    them all a few times. A bound is linear, so one tighter at the box's corners is tighter
    all over it; the bounds tried as the tighter one are those tightest at a corner or the
    middle (each of them stays). Each bound's values there are taken once, into an array of
    this function's own (a function that takes rows costs a reference count a call)."""
    if n <= 1:
        return n
    corners_a = (a_lo, a_lo, a_hi, a_hi, 0.5 * (a_lo + a_hi))
    corners_b = (0.0, b_hi, 0.0, b_hi, 0.5 * b_hi)
    # every bound's value at the four corners and the middle, sign taken (lower is tighter)
    value = np.empty((n, 5))
    for r in range(n):
        for c in range(5):
            value[r, c] = sign * (rows[r, 0] + rows[r, 1] * corners_a[c]
                                  + rows[r, 2] * corners_b[c])
    best = np.empty(5, dtype=np.int64)
    for c in range(5):
        k = 0
        for r in range(1, n):
            if value[r, c] < value[k, c]:
                k = r
        best[c] = k
    m = 0
    for r in range(n):
        dominated = False
        for c in range(5):
            if best[c] == r:
                dominated = False
                break
            if not dominated:
                tighter = True
                for e in range(4):
                    if not value[best[c], e] <= value[r, e]:
                        tighter = False
                        break
                dominated = tighter
        if not dominated:
            for i in range(3):
                rows[m, i] = rows[r, i]
            m += 1
    return m


@jit
def b_top(bounds, nb, a_lo, a_hi):
    """An upper bound on b over a in [a_lo, a_hi] from the rows without u (inf: none)."""
    top = np.inf
    for r in range(nb):
        if bounds[r, 0] > 0.0:
            top = min(top, bounds[r, 1] + max(bounds[r, 2] * a_lo, bounds[r, 2] * a_hi))
    return top


@jit
def fold_end(rows, n, h, end_kind, p1, p2, out):
    """The last cell's rows with its u fixed by the end it runs into, as rows over (b, a) alone
    (u = 0 in them) into out; returns the count. end_kind 0: a rest after a rest cell p1 long
    whose far value is at most p2 (b = b_end y^(4/3): at the knot a = -2 b / (3 p1), so
    u = -(b + (2 h + 1.5 p1) a) / (h^2 + 1.5 p1 h)); 1: a moving end in state (b, a) = (p1,
    p2) (u = (p2 - a) / h, and b = p1 - h (a + p2), two rows, MOVING_END_REL apart; 2: the
    same, LOOSE_END_REL apart)."""
    if end_kind == 0:
        den = h * h + 1.5 * p1 * h
        pb, pa, p0 = -1.0 / den, -(2.0 * h + 1.5 * p1) / den, 0.0
    else:
        pb, pa, p0 = 0.0, -1.0 / h, p2 / h
    m = 0
    for r in range(n):
        cu = rows[r, 2]
        out[m, 0] = rows[r, 0] + cu * pb
        out[m, 1] = rows[r, 1] + cu * pa
        out[m, 2] = 0.0
        out[m, 3] = rows[r, 3] - cu * p0
        m += 1
    if end_kind == 0:
        # the far value b + 2 h a + h^2 u of the rest cell: at most p2, at least 0
        for sign, bound in ((1.0, p2), (-1.0, 0.0)):
            out[m, 0] = sign * (1.0 + h * h * pb)
            out[m, 1] = sign * (2.0 * h + h * h * pa)
            out[m, 2] = 0.0
            out[m, 3] = sign * bound
            m += 1
    else:
        thick = (MOVING_END_REL if end_kind == 1 else LOOSE_END_REL) * max(abs(p1), 1e-300)
        for sign in (1.0, -1.0):
            out[m, 0] = sign
            out[m, 1] = sign * h
            out[m, 2] = 0.0
            out[m, 3] = sign * (p1 - h * p2) + thick
            m += 1
    return m
