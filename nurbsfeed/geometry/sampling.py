"""The planning grid's nodes (planning.grid, steps 1 and 4): samples evenly spaced per span,
the union with extra parameters, and the refinement where kappa jumps or the tangent turns more
than kappa explains. Compiled kernels, written once in numba's subset; every node carries u,
kappa, |C'| (M,) and C, C', the unit tangent (M, 3), each from one `point_d2` at its parameter
(geometry.kernel), so that later steps and the path model read them instead of evaluating the
curve there again."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry.kernel import curvature, find_span, point_d1, point_d2
from nurbsfeed.jit import jit

KAPPA_STEP_REL = 0.1  # refine where kappa changes by more than 10 % between nodes
REFINE_ROUNDS = 6  # ... down to 1/64 of the base spacing
TURN_REFINE_ROUNDS = 24  # where the tangent turns more than kappa explains: down to 1/2^24
TURN_EXPLAINED = 2.0  # a turn up to this times max(kappa) x chord needs no node between
TURN_SLACK_RAD = 1e-3
REFINE_GROWTH_MAX = 8  # the refinement stops before the grid grows beyond this factor
MIN_NODES_PER_SPAN = 8
CHORD_PROBES = 16  # chords per span for the node count
# |C'| at or below this fraction of the mean |C'| is zero: the curve stops there (grid step 3).
# A true zero of a polynomial C' refines to ~1e-12 of the mean or below; one that does not is a
# near cusp whose curvature the limits already handle.
ZERO_SPEED_REL = 1e-7


@jit
def node_values(c, pts, d1, tan, q):
    """C, C' and the unit tangent from point_d2's c into pts[q], d1[q], tan[q] (tangent 0 where
    C' = 0)."""
    pts[q, 0] = c[0]
    pts[q, 1] = c[1]
    pts[q, 2] = c[2]
    d1[q, 0] = c[3]
    d1[q, 1] = c[4]
    d1[q, 2] = c[5]
    norm = math.sqrt(c[3] * c[3] + c[4] * c[4] + c[5] * c[5])
    inv = 1.0 / norm if norm > 0.0 else 0.0
    tan[q, 0] = c[3] * inv
    tan[q, 1] = c[4] * inv
    tan[q, 2] = c[5] * inv


@jit
def samples(knots, coef, degree, breaks, spacing_mm):
    """Step 1: nodes evenly spaced in u per span, at most spacing_mm apart (the span's length
    estimated by CHORD_PROBES chords, plus 5 %), at least MIN_NODES_PER_SPAN; the last break
    closes the list. Returns u, kappa, |C'| at the nodes (M,), C, C' and the unit tangent there
    (M, 3; C' and the tangent from the span after a knot, the tangent 0 where C' = 0), and the
    mean of |C'| over the nodes (summed in order). At an interior knot kappa is the higher of
    its limits from the two sides (it jumps where the curve is only C1), so that no node
    understates the curvature around it; a side where |C'| is below ZERO_SPEED_REL of the
    other's does not count (its kappa is rounding noise). Where |C'| is at most ZERO_SPEED_REL
    of its mean, C' = 0 and kappa is its limit from inside (`fill_singular`)."""
    n_ctrl = coef.shape[0]
    n_spans = breaks.size - 1
    counts = np.empty(n_spans, dtype=np.int64)
    n_nodes = 1  # the last break
    span = degree
    for i in range(n_spans):
        width = breaks[i + 1] - breaks[i]
        chord = 0.0
        span = find_span(knots, degree, n_ctrl, breaks[i], span)
        px, py, pz, _, _, _ = point_d1(knots, coef, degree, span, breaks[i])
        for j in range(1, CHORD_PROBES + 1):
            u = breaks[i] + width * (j / CHORD_PROBES)
            span = find_span(knots, degree, n_ctrl, u, span)
            qx, qy, qz, _, _, _ = point_d1(knots, coef, degree, span, u)
            chord += math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
            px, py, pz = qx, qy, qz
        counts[i] = max(MIN_NODES_PER_SPAN, math.ceil(1.05 * chord / spacing_mm))
        n_nodes += counts[i]
    u_nodes = np.empty(n_nodes)
    q = 0
    for i in range(n_spans):
        step = (breaks[i + 1] - breaks[i]) / counts[i]
        for j in range(counts[i]):
            u_nodes[q] = breaks[i] + j * step
            q += 1
    u_nodes[q] = breaks[n_spans]
    kappa = np.empty(u_nodes.size)
    speed = np.empty(u_nodes.size)
    pts = np.empty((u_nodes.size, 3))
    d1 = np.empty((u_nodes.size, 3))
    tan = np.empty((u_nodes.size, 3))
    span = degree
    for q in range(u_nodes.size):
        before = span
        span = find_span(knots, degree, n_ctrl, u_nodes[q], span)
        c = point_d2(knots, coef, degree, span, u_nodes[q])
        kappa[q], speed[q] = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
        node_values(c, pts, d1, tan, q)
        if span != before and q > 0:  # a knot: kappa may jump there, take the higher side
            c = point_d2(knots, coef, degree, before, u_nodes[q])
            left, left_speed = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            # ... where the side before moves: after a span of no length (coincident control
            # points) its kappa is rounding noise (7e13 at a knot where the curve starts
            # moving, filled back over the still span: 2.8e-11 mm/s, 65 hours planned)
            moves = left_speed > ZERO_SPEED_REL * speed[q] if speed[q] == speed[q] else True
            if moves and (left > kappa[q] or kappa[q] != kappa[q]):
                kappa[q] = left
    total_speed = 0.0
    for q in range(speed.size):
        total_speed += speed[q]
    mean_speed = total_speed / speed.size
    for q in range(speed.size):
        if speed[q] <= ZERO_SPEED_REL * mean_speed:
            kappa[q] = math.nan
    fill_singular(kappa)
    return u_nodes, kappa, speed, pts, d1, tan, mean_speed


@jit
def fill_singular(kappa):
    """Where C' = 0 (repeated control points) kappa is NaN (or overflows): use the next finite
    value along the curve (the last one past the final finite node), the limit of kappa from
    inside the curve (design §3a). None finite: 0. In place."""
    last_good = -1
    for q in range(kappa.size - 1, -1, -1):
        if math.isfinite(kappa[q]):
            last_good = q
            break
    if last_good < 0:
        kappa[:] = 0.0
        return
    following = kappa[last_good]
    for q in range(kappa.size - 1, -1, -1):
        if math.isfinite(kappa[q]):
            following = kappa[q]
        else:
            kappa[q] = following


@jit
def merge(knots, coef, degree, u, kappa, speed, pts, d1, tan, extra, zero_speed):
    """Step 4a: the sorted union of the nodes and the sorted extra parameters, with kappa,
    |C'|, C, C' and the unit tangent (a parameter that is already a node keeps the node's
    values; where |C'| is at most zero_speed, kappa is its limit from inside, `fill_singular`)."""
    n_ctrl = coef.shape[0]
    size = u.size + extra.size
    u_out = np.empty(size)
    k_out = np.empty(size)
    s_out = np.empty(size)
    p_out = np.empty((size, 3))
    d_out = np.empty((size, 3))
    t_out = np.empty((size, 3))
    i = 0
    j = 0
    n = np.int64(0)  # not a literal 0: node_values(..., n) would compile for Literal[int](0) too
    span = degree
    while i < u.size or j < extra.size:
        if j >= extra.size or (i < u.size and u[i] <= extra[j]):
            if i < u.size and j < extra.size and u[i] == extra[j]:
                j += 1
                continue
            u_out[n] = u[i]
            k_out[n] = kappa[i]
            s_out[n] = speed[i]
            for d in range(3):
                p_out[n, d] = pts[i, d]
                d_out[n, d] = d1[i, d]
                t_out[n, d] = tan[i, d]
            i += 1
        else:
            if n > 0 and u_out[n - 1] == extra[j]:
                j += 1
                continue
            u_out[n] = extra[j]
            span = find_span(knots, degree, n_ctrl, extra[j], span)
            c = point_d2(knots, coef, degree, span, extra[j])
            k_out[n], s_out[n] = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            if s_out[n] <= zero_speed:
                k_out[n] = math.nan
            node_values(c, p_out, d_out, t_out, n)
            j += 1
        n += 1
    fill_singular(k_out[:n])
    return u_out[:n], k_out[:n], s_out[:n], p_out[:n], d_out[:n], t_out[:n]


@jit
def _tangent_chord_cos(tan, pts, moving, q, r, chord):
    """The cosine between the unit tangent at node `moving` and the chord from node q to r."""
    return ((tan[moving, 0] * (pts[r, 0] - pts[q, 0])
             + tan[moving, 1] * (pts[r, 1] - pts[q, 1])
             + tan[moving, 2] * (pts[r, 2] - pts[q, 2])) / chord)


@jit
def _hidden_bump(knots, coef, degree, low, high_u, high_kappa, kappa_floor, zero_speed, span):
    """Whether kappa at the middle of [low, high_u] is above kappa_floor and more than
    KAPPA_STEP_REL above the higher of its ends: a maximum the ends do not show (fuzz seed 45:
    kappa 14.7 and 14.6 at the ends of the first interval after a knot, 23.1 between them).
    Also |C'| there, and its span (span: the one to try first)."""
    mid = 0.5 * (low + high_u)
    span = find_span(knots, degree, coef.shape[0], mid, span)
    c = point_d2(knots, coef, degree, span, mid)
    k_mid, s_mid = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
    return (s_mid > zero_speed and math.isfinite(k_mid) and k_mid > kappa_floor
            and k_mid > (1.0 + KAPPA_STEP_REL) * high_kappa), s_mid, span


@jit
def refine_where_kappa_jumps_or_turns(knots, coef, degree, u, kappa, speed, pts, d1, tan,
                                      kappa_floor, zero_speed, floor_mm):
    """Step 4b: halve every interval across which kappa (above kappa_floor) changes by more than
    KAPPA_STEP_REL, or whose middle hides a bump of kappa (`_hidden_bump`), up to REFINE_ROUNDS
    times, and every interval across which the tangent turns by more than its end nodes' kappa
    explains, up to TURN_REFINE_ROUNDS times.

    The planner bounds the limit between two nodes by the lower of their limits; near a sharp
    curvature peak that bound is only tight when the nodes are close, so the grid is made dense
    exactly there. A spike of kappa narrower than the node spacing (a near cusp: |C'| dips
    between two nodes) shows in neither node's kappa, but in the turn of the tangent between
    them: more than TURN_EXPLAINED times max(kappa) times the chord, plus TURN_SLACK_RAD, where
    that turn over the chord is a curvature above kappa_floor (not where C' = 0 at a node, or
    the chord is shorter than floor_mm). A midpoint where C' = 0 (|C'| at most zero_speed) takes
    the kappa of the interval's start. The grid grows at most REFINE_GROWTH_MAX-fold: what a
    refinement stopped there misses, the motion guard (nurbsfeed/safety.py) refuses.

    Each round looks only at the intervals the last one made (the others' ends are unchanged):
    the nodes are kept in the order they are made, linked in the order of u by `after`, and
    laid out in that order once at the end. Returns the nodes' u, kappa, |C'| (M,), C, C', unit
    tangent (M, 3), and |C'| at the middle of each node's interval to the next where the bump
    check took it (NaN elsewhere): the arc length's quadrature starts there."""
    n_ctrl = coef.shape[0]
    most = REFINE_GROWTH_MAX * u.size
    # room for the most nodes the grid may grow to: pages never written take no memory (a grid
    # grows ~1.4-fold), and growing the arrays when needed cost a third more to compile
    all_u = np.empty(most)
    all_k = np.empty(most)
    all_s = np.empty(most)
    all_m = np.empty(most)  # |C'| at the middle of the interval a node starts, NaN: not known
    all_p = np.empty((most, 3))
    all_d = np.empty((most, 3))
    all_t = np.empty((most, 3))
    after = np.empty(most, dtype=np.int64)
    fresh = np.empty(most, dtype=np.int64)  # the first nodes of the intervals to look at
    split = np.empty(most, dtype=np.int64)
    for q in range(u.size):
        all_u[q] = u[q]
        all_k[q] = kappa[q]
        all_s[q] = speed[q]
        for i in range(3):  # element by element: a row copy costs numba a slice
            all_p[q, i] = pts[q, i]
            all_d[q, i] = d1[q, i]
            all_t[q, i] = tan[q, i]
        all_m[q] = math.nan
        after[q] = q + 1
        fresh[q] = q
    size = u.size
    n_fresh = u.size - 1
    span = degree
    for rounds in range(TURN_REFINE_ROUNDS):
        n_split = 0
        for f in range(n_fresh):
            q = fresh[f]
            r = after[q]
            high = max(all_k[q], all_k[r])
            if (rounds < REFINE_ROUNDS and high > kappa_floor
                    and abs(all_k[r] - all_k[q]) > KAPPA_STEP_REL * high):
                split[n_split] = q
                n_split += 1
                continue
            if rounds < REFINE_ROUNDS:
                bump, all_m[q], span = _hidden_bump(knots, coef, degree, all_u[q], all_u[r], high,
                                                    kappa_floor, zero_speed, span)
                if bump:
                    split[n_split] = q
                    n_split += 1
                    continue
            still_q = all_s[q] <= zero_speed
            still_r = all_s[r] <= zero_speed
            if still_q and still_r:
                continue  # C' = 0 at both ends of the interval: no tangent
            chord = math.sqrt((all_p[r, 0] - all_p[q, 0]) ** 2 + (all_p[r, 1] - all_p[q, 1]) ** 2
                              + (all_p[r, 2] - all_p[q, 2]) ** 2)
            if chord <= floor_mm:
                continue  # no length: nothing between the nodes to plan for
            if still_q or still_r:
                # C' = 0 at one end (a stop, a curve end): the tangent at the other against the
                # chord (a hook of 0.14 um between the last node and a still end once hid a
                # kappa of 5e6 from the grid)
                cos = _tangent_chord_cos(all_t, all_p, r if still_q else q, q, r, chord)
            else:
                cos = (all_t[q, 0] * all_t[r, 0] + all_t[q, 1] * all_t[r, 1]
                       + all_t[q, 2] * all_t[r, 2])
            explained = TURN_EXPLAINED * high * chord + TURN_SLACK_RAD
            # 1 - cos x >= x^2/2 - x^4/24: below that the turn is explained, without an acos
            if 1.0 - cos <= explained * explained * (0.5 - explained * explained / 24.0):
                continue
            turn = math.acos(min(1.0, max(-1.0, cos)))
            if turn > explained and turn > kappa_floor * chord:
                split[n_split] = q
                n_split += 1
        if n_split == 0 or size + n_split > most:
            break
        n_fresh = 0
        for i in range(n_split):
            q = split[i]
            r = after[q]
            mid = 0.5 * (all_u[q] + all_u[r])
            span = find_span(knots, degree, n_ctrl, mid, span)
            c = point_d2(knots, coef, degree, span, mid)
            k_mid, s_mid = curvature(c[3], c[4], c[5], c[6], c[7], c[8])
            all_u[size] = mid
            all_k[size] = k_mid if math.isfinite(k_mid) and s_mid > zero_speed else all_k[q]
            all_s[size] = s_mid
            node_values(c, all_p, all_d, all_t, size)
            all_m[q] = math.nan
            all_m[size] = math.nan
            after[q] = size
            after[size] = r
            fresh[n_fresh] = q
            fresh[n_fresh + 1] = size
            n_fresh += 2
            size += 1
    u_out = np.empty(size)
    k_out = np.empty(size)
    s_out = np.empty(size)
    m_out = np.empty(size)
    p_out = np.empty((size, 3))
    d_out = np.empty((size, 3))
    t_out = np.empty((size, 3))
    q = 0
    for n in range(size):
        u_out[n] = all_u[q]
        k_out[n] = all_k[q]
        s_out[n] = all_s[q]
        m_out[n] = all_m[q]
        for i in range(3):
            p_out[n, i] = all_p[q, i]
            d_out[n, i] = all_d[q, i]
            t_out[n, i] = all_t[q, i]
        q = after[q]
    return u_out, k_out, s_out, p_out, d_out, t_out, m_out
