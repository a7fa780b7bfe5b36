"""Chains: consecutive joined curves merged into one NURBS curve, planned as one path (design §3b).

A chain of curves C_0 .. C_{N-1} of one degree p, each starting where the last ended, is the
single curve whose knot vector puts the pieces one after the other, the knot of each joint
repeated p times (`merge_curves`):

    knots   = K_0[:-1] ++ (K_1[p+1:] shifted) ++ ... (each piece's range laid after the last)
    points  = P_0 ++ P_1[1:] ++ ...          (a joint's control point is shared)
    weights = w_0 ++ c_1 w_1[1:] ++ ...      (c_i makes the shared weight agree)

With multiplicity p at a joint the curve passes through the shared control point there, and the
spans on either side use only their own piece's control points with its own clamped basis: the
merged curve is each piece exactly (a rational curve does not change when all its weights are
multiplied by one constant, so rescaling a piece's weights to agree at the joint keeps it). The
curve is C0 at a joint, and whatever the pieces make of it: a knot of multiplicity >= degree
where the tangent jumps is a corner the planner rests at (planning.grid), a curvature jump is
capped by the path model's jerk rule (path_model.jump_speeds), and a piece's programmed feed is
a step of the merged feed at its range. What the planner does not see is a turn below its
corner tolerance (1.4e-4 rad): `joint_caps` turns it into a feed step around the joint.

Each piece gets the share of the parameter range that keeps |C'| continuous at its joints, and
each joint's knot is then removed as far as the curve does not move (`remove_knot`): a chain cut
from one curve is that curve again. A piece of a lower degree is raised to the chain's
(`elevate`); pieces whose weights would break the input envelope end a chain (`can_follow`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbsfeed.geometry.nurbs import MAX_WEIGHT_RATIO, NurbsCurve
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.path_model import jump_speeds, kappa_n_jumps

# a piece's share of the chain's parameter range is at least this share of the mean: a piece of
# almost no length still gets spans the knot check accepts
MIN_RANGE_SHARE = 1e-6
# the shares of the parameter range (`_piece_ranges`) spread at most this much
MAX_RANGE_SPREAD = 1e9
# a joint's knot is removed where that moves the curve by no more than this (`remove_knot`):
# a thousandth of the default output digit (1e-5 mm), far above what a knot inserted and removed
# again moves by rounding (a butterfly joint: 1e-9 mm did not always hold)
REMOVAL_TOL_MM = 1e-8
# half-width of the feed step that caps a near-tangent joint, as a share of the chain's
# parameter range: the planner adds a node at each step, so the cap holds at the joint itself
JOINT_CAP_HALF_WIDTH = 1e-9


@dataclass(frozen=True, eq=False)
class Chain:
    """Curves merged into one (`merge_curves`): the merged curve, and per piece (N,) its start
    in the merged parameter (u_start[0] = 0) and its own curve; joint_u (N-1,) = u_start[1:]."""

    curve: NurbsCurve
    pieces: tuple[NurbsCurve, ...]
    u_start: np.ndarray  # (N,)
    u_range: np.ndarray  # (N,) share of [0, 1] each piece occupies

    @property
    def joint_u(self) -> np.ndarray:
        return self.u_start[1:]

    def piece_of(self, u: np.ndarray) -> np.ndarray:
        """The piece (M,) each merged parameter u (M,) lies in; a joint belongs to the piece it
        ends."""
        return np.searchsorted(self.joint_u, u, side="left")

    def piece_u(self, u: np.ndarray, piece: np.ndarray) -> np.ndarray:
        """Merged u (M,) -> each piece's own stored u (M,) (its knots in [0, 1])."""
        local = (u - self.u_start[piece]) / self.u_range[piece]
        return np.clip(local, 0.0, 1.0)

    def merged_u(self, piece: int, u: np.ndarray) -> np.ndarray:
        """A piece's own stored u (M,) -> merged u (M,)."""
        return self.u_start[piece] + np.asarray(u, dtype=float) * self.u_range[piece]


def chain_weights(curve: NurbsCurve) -> tuple[float, float, float]:
    """A chain of one curve's weights: (lowest, highest, last), the state `can_follow` takes."""
    return float(curve.weights.min()), float(curve.weights.max()), float(curve.weights[-1])


def can_follow(last: NurbsCurve, nxt: NurbsCurve, weights: tuple[float, float, float]
               ) -> tuple[float, float, float] | None:
    """Whether `nxt` may be merged after `last`, the chain's last piece, given the chain's
    weights so far (lowest, highest, last, as the merged curve holds them): the chain's weights
    with `nxt` merged (a piece of a lower degree than the chain's is raised to it, `elevate`:
    its weights stay within its own), or None when a piece has no length (it is written as
    such, alone) or the merged weights would spread beyond MAX_WEIGHT_RATIO."""
    if nxt.is_degenerate or last.is_degenerate:
        return None
    factor = weights[2] / float(nxt.weights[0])
    lo = min(weights[0], float(nxt.weights.min()) * factor)
    hi = max(weights[1], float(nxt.weights.max()) * factor)
    if hi / lo > MAX_WEIGHT_RATIO:
        return None
    return lo, hi, float(nxt.weights[-1]) * factor


def merge_curves(curves: list[NurbsCurve], name: str = "") -> Chain:
    """The chain of `curves` (module docstring), each starting at the last one's end; the
    shared control point of a joint is the end of the piece before it.

    curves: N >= 1 curves of one degree (`can_follow`). The merged curve is built unchecked
    (each piece was checked when read; a span of the merged curve is a span of a piece, scaled).
    """
    if len(curves) == 1:  # the curve itself, its input parameter kept
        one = np.array([0.0])
        whole = np.array([1.0])
        for arr in (one, whole):
            arr.setflags(write=False)
        return Chain(curves[0], (curves[0],), one, whole)
    p = max(c.degree for c in curves)
    curves = [c if c.degree == p else elevate(c, p) for c in curves]
    ranges = _piece_ranges(curves)
    starts = np.concatenate(([0.0], np.cumsum(ranges)[:-1]))
    knots = [curves[0].knots[:-1] * ranges[0]]
    homogeneous = [curves[0].homogeneous]
    for i in range(1, len(curves)):
        c = curves[i]
        tail = c.knots[p + 1:] * ranges[i] + starts[i]
        knots.append(tail if i == len(curves) - 1 else tail[:-1])
        # the piece's weights scaled so that its first equals the last one before it
        homogeneous.append(c.homogeneous[1:] * (homogeneous[-1][-1, 3] / c.homogeneous[0, 3]))
    all_knots = np.concatenate(knots)
    all_knots[-p - 1:] = 1.0  # exactly 1, whatever the sum of the shares rounded to
    pw = np.concatenate(homogeneous)
    # a joint's parameter is the merged curve's knot there, exactly
    index = len(curves[0].knots) - 1 - p
    u_start = np.zeros(len(curves))
    for i in range(1, len(curves)):
        u_start[i] = all_knots[index]
        index += len(curves[i].knots) - p - 2
    tol = _removal_tolerance(pw)
    for u in u_start[1:]:
        all_knots, pw = _remove_valid(p, all_knots, pw, float(u), p, tol)
    weights = pw[:, 3] * 2.0 ** -np.floor(np.log2(pw[:, 3].max()))  # the largest in [1, 2), as
    # NurbsCurve.build keeps it (a power of two: exact)
    points = pw[:, :3] / pw[:, 3:]
    for arr in (all_knots, weights, points):
        arr.setflags(write=False)
    merged = NurbsCurve(p, all_knots, points, weights, name or curves[0].name)
    ranges = np.diff(np.concatenate((u_start, [1.0])))
    for arr in (u_start, ranges):
        arr.setflags(write=False)
    return Chain(merged, tuple(curves), u_start, ranges)


def insert_knot(degree: int, knots: np.ndarray, pw: np.ndarray, u: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """u inserted once into the curve (knots (m,), homogeneous points (n, 4)) -> (m + 1,),
    (n + 1, 4): the same curve (Boehm; Piegl & Tiller A5.1 with r = 1)."""
    k = int(np.searchsorted(knots, u, side="right")) - 1
    out = np.empty((len(pw) + 1, pw.shape[1]))
    out[:k - degree + 1] = pw[:k - degree + 1]
    out[k + 1:] = pw[k:]
    for i in range(k - degree + 1, k + 1):
        alpha = (u - knots[i]) / (knots[i + degree] - knots[i])
        out[i] = alpha * pw[i] + (1.0 - alpha) * pw[i - 1]
    return np.insert(knots, k + 1, u), out


def curve_after(curve: NurbsCurve, u: float) -> NurbsCurve:
    """The part of `curve` after its parameter u (u_min < u < u_max): u inserted until its
    multiplicity is the degree (the curve then passes through one control point there, and the
    spans after it use only the points from it on), the spans before it dropped. The same path
    from C(u) on; its parameter the curve's own over [u, u_max] (kept as u_origin, u_scale, so
    that a trace names the input's u)."""
    p = curve.degree
    knots, pw = curve.knots.copy(), curve.homogeneous.copy()
    while np.count_nonzero(knots == u) < p:
        knots, pw = insert_knot(p, knots, pw, u)
    first = int(np.searchsorted(knots, u, side="left"))  # the first copy of u
    tail_knots = np.concatenate([[u], knots[first:]])
    tail = pw[first - 1:]
    span = float(tail_knots[-1] - u)
    unit = (tail_knots - u) / span
    unit[:p + 1], unit[-p - 1:] = 0.0, 1.0
    weights = tail[:, 3] * 2.0 ** -np.floor(np.log2(tail[:, 3].max()))
    points = tail[:, :3] / tail[:, 3:]
    for arr in (unit, points, weights):
        arr.setflags(write=False)
    return NurbsCurve(p, unit, points, weights, curve.name, float(curve.input_u(u)),
                      curve.u_scale * span)


def elevate(curve: NurbsCurve, degree: int) -> NurbsCurve:
    """The same curve of a higher `degree` (design §3b: a chain's pieces share one degree): cut
    into Bézier spans by knot insertion, each span raised one degree at a time (Q_i = i/(p+1)
    P_i-1 + (1 - i/(p+1)) P_i, in homogeneous coordinates), then each interior knot removed
    as far as the curve does not move (`remove_knot`): back to the continuity it had."""
    p = curve.degree
    knots, pw = curve.knots.copy(), curve.homogeneous.copy()
    breaks = curve.span_breaks[1:-1]
    for u in breaks:
        while np.count_nonzero(knots == u) < p:
            knots, pw = insert_knot(p, knots, pw, float(u))
    spans = np.concatenate(([curve.u_min], breaks, [curve.u_max]))
    for q in range(p, degree):
        n_spans = spans.size - 1
        raised = np.empty((n_spans * (q + 1) + 1, 4))
        for k in range(n_spans):
            bez = pw[k * q:k * q + q + 1]
            i = np.arange(1, q + 1)[:, None] / (q + 1)
            raised[k * (q + 1)] = bez[0]
            raised[k * (q + 1) + 1:k * (q + 1) + q + 1] = i * bez[:-1] + (1.0 - i) * bez[1:]
        raised[-1] = pw[-1]
        pw = raised
    knots = np.concatenate(([spans[0]] * (degree + 1),
                            np.repeat(spans[1:-1], degree), [spans[-1]] * (degree + 1)))
    tol = _removal_tolerance(pw)
    for u in spans[1:-1]:
        knots, pw = _remove_valid(degree, knots, pw, float(u), degree, tol)
    weights = pw[:, 3]
    points = pw[:, :3] / weights[:, None]
    for arr in (knots, points, weights):
        arr.setflags(write=False)
    return NurbsCurve(degree, knots, points, weights, curve.name, curve.u_origin, curve.u_scale)


def _remove_valid(degree: int, knots: np.ndarray, pw: np.ndarray, u: float, num: int,
                  tol: float) -> tuple[np.ndarray, np.ndarray]:
    """`remove_knot`, as many times (up to num) as leave the weights positive and within the
    input envelope (a semicircle is one quadratic span whose middle weight is 0: exact, and
    refused)."""
    for times in range(num, 0, -1):
        knots_left, pw_left = remove_knot(degree, knots, pw, u, times, tol)
        w = pw_left[:, 3]
        if w.min() > 0.0 and w.max() <= MAX_WEIGHT_RATIO * w.min():
            return knots_left, pw_left
    return knots, pw


def _piece_ranges(curves: list[NurbsCurve]) -> np.ndarray:
    """Each piece's share (N,) of the merged parameter range [0, 1]: chosen so that |C'| is
    continuous at every joint (piece i + 1's range is piece i's times the ratio of its speeds
    |C'| in its own stored u, at its start and at the end of piece i). A chain cut from one
    curve then has that curve's own parameterization, and where its joints are smooth the knot
    removal after the merge gives that curve back (`remove_knot`). Where a speed is 0 at a
    joint (a repeated control point), the ratio of the pieces' control polygon lengths is taken
    instead; shares spread wider than MAX_RANGE_SPREAD are all taken from the lengths."""
    lengths = np.array([float(np.sum(np.linalg.norm(np.diff(c.points, axis=0), axis=1)))
                        for c in curves])
    mean = float(lengths.mean()) if lengths.size else 0.0
    by_length = (np.maximum(lengths, MIN_RANGE_SHARE * mean) if mean > 0.0
                 else np.ones(len(curves)))
    ranges = np.ones(len(curves))
    for i in range(1, len(curves)):
        end = curves[i - 1].speed(np.array([np.nextafter(curves[i - 1].u_max, -np.inf)]))[0]
        start = curves[i].speed(np.array([curves[i].u_min]))[0]
        ratio = start / end if end > 0.0 and start > 0.0 else by_length[i] / by_length[i - 1]
        ranges[i] = ranges[i - 1] * ratio
    if not (np.all(np.isfinite(ranges))
            and ranges.max() <= MAX_RANGE_SPREAD * ranges.min()):
        ranges = by_length
    return ranges / ranges.sum()


def _removal_tolerance(pw: np.ndarray) -> float:
    """The bound on the homogeneous points' moves that keeps every point of the curve within
    REMOVAL_TOL_MM (Piegl & Tiller eq. 5.30: d w_min / (1 + max |P|))."""
    weights = pw[:, 3]
    size = float(np.max(np.linalg.norm(pw[:, :3] / weights[:, None], axis=1)))
    return REMOVAL_TOL_MM * float(weights.min()) / (1.0 + size)


def remove_knot(degree: int, knots: np.ndarray, pw: np.ndarray, u: float, num: int,
                tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The knot u removed up to `num` times from the curve (knots (m,), homogeneous points
    (n, 4)) while the curve moves by no more than `tol` in homogeneous space (Piegl & Tiller,
    The NURBS Book, A5.8): (knots (m - t,), points (n - t, 4)), t the removals made. At a
    joint where the chain is as smooth as the pieces' own spans the knot goes down to the
    multiplicity the pieces' curve had there (a chain cut from one curve is that curve again);
    at a corner nothing moves within tol and nothing is removed."""
    p = degree
    r = int(np.searchsorted(knots, u, side="right")) - 1  # the last copy of u
    s = int(np.count_nonzero(knots == u))
    if knots[r] != u or s == 0:
        return knots, pw
    num = min(num, s)
    out = pw.copy()
    order = p + 1
    first, last = r - p, r - s
    t = 0
    temp = np.empty((2 * p + 1, pw.shape[1]))
    while t < num:
        off = first - 1
        temp[0] = out[off]
        temp[last + 1 - off] = out[last + 1]
        i, j = first, last
        ii, jj = 1, last - off
        while j - i > t:
            alfi = (u - knots[i]) / (knots[i + order + t] - knots[i])
            alfj = (u - knots[j - t]) / (knots[j + order] - knots[j - t])
            temp[ii] = (out[i] - (1.0 - alfi) * temp[ii - 1]) / alfi
            temp[jj] = (out[j] - alfj * temp[jj + 1]) / (1.0 - alfj)
            i += 1
            ii += 1
            j -= 1
            jj -= 1
        if j - i < t:
            removable = np.linalg.norm(temp[ii - 1] - temp[jj + 1]) <= tol
        else:
            alfi = (u - knots[i]) / (knots[i + order + t] - knots[i])
            removable = np.linalg.norm(
                out[i] - (alfi * temp[ii + t + 1] + (1.0 - alfi) * temp[ii - 1])) <= tol
        if not removable:
            break
        i, j = first, last
        while j - i > t:
            out[i] = temp[i - off]
            out[j] = temp[j - off]
            i += 1
            j -= 1
        first -= 1
        last += 1
        t += 1
    if t == 0:
        return knots, pw
    new_knots = np.delete(knots, np.arange(r - t + 1, r + 1))
    fout = (2 * r - s - p) // 2
    j = i = fout
    for k in range(1, t):
        if k % 2 == 1:
            i += 1
        else:
            j -= 1
    keep = np.concatenate((out[:j], out[i + 1:]))
    return new_knots, keep


def chain_feed(chain: Chain, feeds: list[tuple[np.ndarray, np.ndarray]]
               ) -> tuple[np.ndarray, np.ndarray]:
    """The pieces' programmed feeds (feed_u, feed_mm_s) in their own u, as one step function of
    the merged u (CurveBlock.feed_u's form; empty arrays when no piece has one)."""
    u_breaks: list[float] = []
    values: list[float] = []
    for i, (feed_u, feed_mm_s) in enumerate(feeds):
        if feed_u.size == 0 or feed_u[0] > chain.pieces[i].u_min:
            u_breaks.append(float(chain.u_start[i]))
            values.append(np.inf)
        u_breaks.extend(chain.merged_u(i, feed_u).tolist())
        values.extend(feed_mm_s.tolist())
    if all(v == np.inf for v in values):
        return np.empty(0), np.empty(0)
    keep = [k for k in range(len(values)) if k == 0 or values[k] != values[k - 1]]
    return np.array([u_breaks[k] for k in keep]), np.array([values[k] for k in keep])


@dataclass(frozen=True)
class Joints:
    """The joints of a chain, (J,) each: the turn of the unit tangent (rad), the jump of the
    curvature vector kappa N (1/mm), and the highest speed the period rule allows there
    (mm/s; inf: no cap, 0: a corner, at rest)."""

    u: np.ndarray
    turn_rad: np.ndarray
    kappa_jump_1_mm: np.ndarray
    cap_mm_s: np.ndarray


# a turn above this is a corner to the planner (planning.grid: CORNER_COS_TOL = 1e-8 of the
# cosine), and the motion rests there
CORNER_TURN_RAD = float(np.sqrt(2e-8))


def joints(chain: Chain, lim: Limits) -> Joints:
    """Turn, curvature jump and speed cap at each joint of the chain (design §3b).

    A turn of the unit tangent by |t+ - t-| is a velocity jump v |t+ - t-| per period: per axis
    x it acts as acceleration v |dt_x| / T and as jerk v |dt_x| / T^2, so the joint passes at
    v <= min_x(A_x T, J_x T^2) / |dt_x| (the tangential limits on |dt| likewise). Above the
    planner's corner tolerance the motion rests (cap 0). A curvature jump D acts as jerk v^2 |D|
    / T (path_model.jump_speeds, the rule the planner applies at every knot)."""
    u = chain.joint_u
    if u.size == 0:
        empty = np.empty(0)
        return Joints(u, empty, empty, empty)
    curve = chain.curve
    left_u = np.nextafter(u, -np.inf)
    _, d_left, _ = curve.derivatives(left_u)
    _, d_right, _ = curve.derivatives(u)
    t_left = d_left / np.linalg.norm(d_left, axis=1)[:, None]
    t_right = d_right / np.linalg.norm(d_right, axis=1)[:, None]
    dt = t_right - t_left
    turn = 2.0 * np.arcsin(np.clip(np.linalg.norm(dt, axis=1) / 2.0, 0.0, 1.0))
    t = lim.period_s
    with np.errstate(divide="ignore"):
        size = np.linalg.norm(dt, axis=1)
        cap = np.where(size > 0.0, min(lim.acc_mm_s2 * t, lim.jerk_mm_s3 * t * t)
                       / np.where(size > 0.0, size, 1.0), np.inf)
        for x in range(3):
            d = np.abs(dt[:, x])
            axis = min(lim.axis_acc_mm_s2[x] * t, lim.axis_jerk_mm_s3[x] * t * t)
            cap = np.minimum(cap, np.where(d > 0.0, axis / np.where(d > 0.0, d, 1.0), np.inf))
    jump = kappa_n_jumps(curve, u)
    cap = np.minimum(cap, jump_speeds(jump, lim))
    cap = np.where(turn > CORNER_TURN_RAD, 0.0, np.where(cap >= lim.feed_mm_s, np.inf, cap))
    return Joints(u, turn, np.linalg.norm(jump, axis=1), cap)


def joint_feed(chain: Chain, caps_mm_s: np.ndarray, feed_u: np.ndarray, feed_mm_s: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """The chain's programmed feed (a step function: breaks feed_u (F,), feeds feed_mm_s (F,),
    inf before the first break) with a step down to caps_mm_s (J,) around each joint whose cap
    is finite and above 0 (a rest is the planner's own): the joint turns by less than the
    planner sees but more than the period rule lets pass at full speed."""
    capped = np.flatnonzero(np.isfinite(caps_mm_s) & (caps_mm_s > 0.0))
    if capped.size == 0:
        return feed_u, feed_mm_s
    u_breaks = list(feed_u)
    feeds = list(feed_mm_s)

    def feed_at(u: float) -> float:
        i = int(np.searchsorted(np.asarray(u_breaks), u, side="right")) - 1
        return feeds[i] if i >= 0 else np.inf

    for j in capped:
        u = float(chain.joint_u[j])
        lo, hi = u - JOINT_CAP_HALF_WIDTH, u + JOINT_CAP_HALF_WIDTH
        after = feed_at(hi)
        inside = min(feed_at(lo), after, float(caps_mm_s[j]))
        keep = [k for k, b in enumerate(u_breaks) if not lo <= b <= hi]
        u_breaks = [u_breaks[k] for k in keep] + [lo, hi]
        feeds = [feeds[k] for k in keep] + [inside, after]
        order = np.argsort(u_breaks, kind="stable")
        u_breaks = [u_breaks[k] for k in order]
        feeds = [feeds[k] for k in order]
    return np.array(u_breaks), np.array(feeds)
