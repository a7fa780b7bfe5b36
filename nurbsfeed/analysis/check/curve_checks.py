"""One curve's moves checked against the curve and the machine profile: geometry, coverage,
timing and kinematics. Every definition and tolerance is in the comment below."""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.analysis.check.estimates import (
    acceleration_xyz,
    baseline_s,
    derivative_estimate,
    divided_difference_weights,
    stencils,
    turning_rad,
)
from nurbsfeed.analysis.check.output_program import Section, decode_moves
from nurbsfeed.analysis.check.projection import (
    feet_ahead_of_behind,
    project_points_and_others,
)
from nurbsfeed.analysis.check.report import Estimation, Findings
from nurbsfeed.analysis.geometry import (
    arc_length_mm,
    chord_errors_mm,
    curvature_1_mm,
    curve_length_mm,
)
from nurbsfeed.gcode.writer import round_ticks, written_decimals
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import FLOOR_MARGIN, Machine
from nurbsfeed.planning.limits import Limits
from nurbsfeed.program import MM_PER_UNIT, CurveBlock

#
# Reference: only the source's curves and the machine profile; the planner is never run. Each
# emitted point is mapped back to its curve by projection (`projection.py`): a search that moves
# forward from the previous point's parameter (so a self-intersecting curve is followed branch by
# branch) over the local minima of |C(u) - P|, brackets each on g(u) = C'(u).(C(u) - P) and
# bisects it. Where C' = 0 (a corner, cusp or reversal, coincident control points) g = 0 without
# a minimum: the search goes on past it. Of the minima within r it takes the one nearest the
# parameter's own pace; with none within r, the nearest; a point it leaves far from the curve is
# looked for again over the rest of the curve. A point farther than ANCHOR_ROUNDINGS * (r + delta)
# from the curve does not move the search on, so one bad point does not derail the ones after it.
# At a turn of nearly 180 degrees (a cusp, a corner, a hairpin) both legs can lie within r of the
# points beside the tip, so geometry alone cannot say which leg a point is on; the order of the
# points does, as the motion's parameter never runs back: (1) the search's anchor never moves
# back, so no leg is walked backwards; (2) a foot more than 2 r of chord behind the anchor is
# the leg before the turn (rounding puts a foot at most that far back) and counts only as the
# nearest so far; (3) the motion rests on a corner and the stepping writes a point there: once
# the anchor is past a corner or written within r of it, the points after it are past it too.
# Left ambiguous are only feet up to 2 r of chord behind the anchor; e_i below does not widen
# for them (no case of the fuzzer needs it: the outputs it found pass within e_i).
#
# Times: a move covering n periods ends n T after the previous one; n comes from its segment time
# |dP^| / (F/60) (P^ the written coordinates), which must be a whole number of periods.
#
# r = 0.5 10^-d sqrt(3) is the farthest a point rounded to d decimals can be from the true point.
# The projection keeps only the tangential part of that error: the arc position s_i of a point is
# known to e_i = r (1 + min(kappa_i r, 1)) (beyond kappa r = 1 the bend is smaller than the
# rounding, and two feet within 2 r of each other are at most about 2 r apart along the curve).
# Quantised coordinates make finite differences noisy (at d = 4, T = 1 ms, a per-period second
# difference has up to 350 mm/s^2 of rounding noise), so derivatives are estimated over baselines
# of several periods (`estimates.py`), with the noise bound as the allowance. Every allowance is
# bounded: by its baseline (>= T) and by r; the scalar normal estimates, whose allowance grows
# with kappa, are left to the vector estimate where their allowance would exceed the limit.
#
#   path deviation   |P^_i - C(u_i)| <= r.
#   chord error      farthest point of the arc C([u_i, u_i+1]) from the written chord <= delta + r
#                    (each chord end may be r off).
#   coverage         between consecutive points on the curve (within r), the projected arc
#                    advance s_j - s_i <= v_m (t_j - t_i) + e_i + e_j: no stretch of the curve is
#                    skipped (the first point is the curve start, the last its end: see below).
#   cycle time       sum of the moves' durations from their F words >= the least time any
#                    schedule needs (`least_time_s`: length over the feed cap span by span, and
#                    the rest-to-rest trapezoid at A_t), less SEGMENT_TIME_REL_TOL of the sum
#                    (the F words' own tolerance) and 2 r / v_max.
#   segment time     t = |dP^| / (F/60) within SEGMENT_TIME_REL_TOL of n T, n = round(t/T) >= 1
#                    (a move that arrives early or late).
#   skipped periods  n > 1 only where points rounded onto the previous one were dropped: two such
#                    points are <= 2r apart and a step grows by at most A_t T^2 per period (its
#                    second difference is a mean of a), so |dP^| <= 4r + A_t T^2; or, with the
#                    profile's rest_move_s, a move from or into a rest of n <= its periods
#                    (ceil(rest_move_s / T)): from rest under the jerk limit a <= J_t t, v <=
#                    J_t t^2 / 2, s <= J_t t^3 / 6, so |dP^| <= J_t (n T)^3 / 6 + 2r (by time
#                    symmetry into a rest too). A move that skips periods at speed covers v n T,
#                    far more: it stays caught.
#   period total     the moves' periods add up to the comment's point count - 1: more is a
#                    violation, one fewer a note (the last point rounds onto the end point), more
#                    than one fewer a violation (moves missing).
#   feed             |dP^| / (t_i+1 - t_i), the chord speed of a move (a chord is never longer
#                    than its arc) <= v_m(u) + 2 r / dt.
#   tangential a, j  2 f[t0, t1, t2] and 6 f[t0, t1, t2, t3], divided differences of s(t) on
#                    points about h apart; allowance k! sum_q |w_q| e_q. h is the smallest
#                    multiple of T that keeps that bound under NOISE_SHARE of the limit for evenly
#                    spaced points.
#   normal a, j      v_i^2 kappa_i <= A_n, v_i^3 kappa_i^2 <= J_n, v_i the mean speed over the
#                    neighbouring points, kappa_i the smallest curvature within e_i of the point;
#                    allowance from the uncertainty of v_i: rounding noise, J_t dt^2 / 24 (mean vs
#                    centre value) and A_t |skew| / 2 (uneven neighbours).
#   acceleration     a^ = 2 P^[t0, t1, t2], the second divided difference of the written points
#   from positions   on nodes about h apart (h: as for the tangential a, with min(A_t, A_n)): a
#                    weighted mean of P''(t) = a_t T + v^2 kappa N. It sees what s(t) cannot: a
#                    corner or a turn-back taken at speed (|dv| ~ v sqrt 2 or 2 v over h).
#                    Noise: r sum |w_q| (r is a length: it bounds every component).
#                    acc-xyz / corner: |a^| <= sqrt(A_t^2 + A_n^2) + noise; named a corner where
#                    the tangent turns more than CORNER_TURN_RAD over the stencil.
#                    Split on the unit tangent T1 at the middle point, away from corners, where
#                    the tangent turns by theta over the stencil: |a^.T1| <= A_t + A_n sin(theta) +
#                    noise, |a^ - (a^.T1) T1| <= A_n + A_t sin(theta) + noise.
#   reversal         where the mean velocities over the two halves of a stencil point apart
#                    (v1.v2 < 0), |v2 - v1| >= max(|v1|, |v2|), and v2 - v1 = a^ (t2 - t0) / 2:
#                    so max(|v1|, |v2|) <= sqrt(A_t^2 + A_n^2) (t2 - t0) / 2 + 2 r / (t1 - t0)
#                    + 2 r / (t2 - t1).
#   path model       under `jerk_model: path` (design §2b) neither the proxy v^3 kappa^2 nor the
#                    law's own j is checked (the machine feels j - kappa^2 v^3 along the path:
#                    where the speed is lowest at a curvature peak, j may follow kappa^2 v^3);
#                    instead j^ = 6 P^[t0..t3], the third divided difference of the written
#                    points on nodes about h apart (h: as for the tangential jerk, with
#                    min(J_t, J_n)), split on the unit tangent at the stencil's middle like a^:
#                    |j^.T1| <= J_t + J_n sin(theta) + noise, across it <= J_n + J_t sin(theta) +
#                    noise; and per axis with a limit of its own, the chord's mean velocity, a^
#                    and j^ (h from that axis kind's lowest limit, noise from the coordinate's
#                    own rounding r / sqrt 3) within the axis limit + noise. A divided difference
#                    is a weighted mean of the true derivative, never above its peak: these rows
#                    can read a short peak low, never a correct motion high.
#   structure        every non-NURBS source line present, byte-identical and in order; every curve
#                    once; every X/Y/Z/F value with a decimal point, no negative zero, no F0, no
#                    zero-length move, F on the first move; G90 ... G91 around the moves of a G91
#                    block and its F restored; moves for every curve that has a length; the last
#                    point is the curve end (within r). The first point is the position before the
#                    block, the curve start (the readers require it; JSON programs rapid there),
#                    taken as written at d decimals.

SEGMENT_TIME_REL_TOL = 0.005
LEAST_TIME_SAMPLES = 4097  # points of the polygon under each programmed-feed piece of a curve
ANCHOR_ROUNDINGS = 10.0
NUMERIC_REL_TOL = 1e-6  # float slack on the exact bounds (coordinates carry ~1e-16 relative error)
CORNER_TURN_RAD = math.radians(30.0)
FOOT_ARC_PIECES = 1024


def feed_cap_mm_s(block: CurveBlock, u: np.ndarray) -> np.ndarray:
    """The programmed feed in force at each u (a step function of u): (M,) -> (M,); inf where
    none is programmed."""
    table = np.concatenate(([np.inf], block.feed_mm_s))
    return table[np.searchsorted(block.feed_u, u, side="right")]


def least_time_s(block: CurveBlock, feed_mm_s: float, acc_mm_s2: float) -> float:
    """No schedule along the curve from rest to rest is faster: the larger of its length over the
    feed cap span by programmed span, and the trapezoid from rest to rest at the highest cap and
    A_t (s'' = a_t, so |s''| <= A_t): L / v + v / A_t, or 2 sqrt(L / A_t) when v is not reached."""
    curve = block.curve
    breaks = np.clip(np.concatenate(([curve.u_min], block.feed_u, [curve.u_max])),
                     curve.u_min, curve.u_max)
    # each piece's length as a polygon: a chord is never longer than its arc, so the bound
    # stays a bound however the speed |C'| behaves (a Gauss rule over whole knot spans put a
    # near-cusp curve 0.7 % long and the bound above the plan, a false alarm)
    lengths = np.array([
        np.linalg.norm(np.diff(curve.point(np.linspace(a, b, LEAST_TIME_SAMPLES)), axis=0),
                       axis=1).sum() for a, b in zip(breaks[:-1], breaks[1:])])
    caps = np.minimum(feed_mm_s, feed_cap_mm_s(block, breaks[:-1]))
    length, v = float(lengths.sum()), float(caps.max())
    trapezoid = (length / v + v / acc_mm_s2 if length >= v * v / acc_mm_s2
                 else 2.0 * math.sqrt(length / acc_mm_s2))
    return max(float(np.sum(lengths / caps)), trapezoid)


def foot_arcs(curve: NurbsCurve, u: np.ndarray, other: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """The arc length at each foot u (N,), and the arc between it and its other foot as near
    (N,; 0 where other is NaN). Between two feet lies the cusp where |C'| has a kink, which
    Gauss-Legendre integrates only to a few per cent of the interval holding it, so each such
    arc is summed over FOOT_ARC_PIECES pieces (once one interval from the other foot's
    neighbour, it was understated by two thirds: fuzz seed 42)."""
    s = arc_length_mm(curve, u)
    between = np.zeros(u.size)
    for k in np.flatnonzero(np.isfinite(other)):
        pieces = np.linspace(min(u[k], other[k]), max(u[k], other[k]), FOOT_ARC_PIECES + 1)
        arcs = arc_length_mm(curve, pieces)
        between[k] = arcs[-1] - arcs[0]
    return s, between


def check_section(section: Section, block: CurveBlock, machine: Machine,
                  findings: Findings) -> None:
    """Geometry, coverage, timing and kinematics of one curve's moves. `block` is in mm
    (`CurveBlock.in_mm`); the section's words, in the program's unit, are converted to mm as
    they are decoded, so every measure and every limit is in mm (and so is the report)."""
    lim = machine.limits
    curve = block.curve
    mm_per_unit = MM_PER_UNIT[block.units]
    decimals = written_decimals(machine.decimals, block.units)
    period = lim.period_s
    r = 0.5 * 10.0**-decimals * math.sqrt(3.0) * mm_per_unit
    acc_total = math.hypot(lim.acc_mm_s2, lim.normal_acc_mm_s2)
    h_a = baseline_s(period, 2, r, lim.acc_mm_s2)
    h_j = baseline_s(period, 3, r, lim.jerk_mm_s3)
    h_x = baseline_s(period, 2, r, min(lim.acc_mm_s2, lim.normal_acc_mm_s2))
    path = lim.jerk_model == "path"
    h_p = baseline_s(period, 3, r, min(lim.jerk_mm_s3, lim.normal_jerk_mm_s3)) if path else 0.0
    findings.estimation.append(Estimation(section.index, r, h_a, h_j, h_x, h_p))
    if abs(section.period_ms * 1e-3 - period) > 1e-9 * period:
        findings.add("comment", section.comment_line,
                     f"the comment announces a {section.period_ms:g} ms period, the machine "
                     f"profile has {period * 1e3:g} ms: check with the profile used to convert")
    if section.zero_length or not section.moves:
        length = curve_length_mm(curve)
        if length > r:
            findings.add("no-moves", section.comment_line,
                         f"no move written but the curve is {length:.4g} mm long")
        return

    axes, feed_words, feed_unit_mm_min, lines = decode_moves(section, findings)
    axes *= mm_per_unit
    feed_words *= mm_per_unit
    feed_unit_mm_min *= mm_per_unit
    if np.isnan(feed_words[0]):
        findings.add("feed-word", int(lines[0]), "the first move has no F word (it would run at "
                     "the program's modal feed)")
    pos = np.empty((len(lines) + 1, 3))
    # the start as the writer rounds it
    pos[0] = (round_ticks(curve.points[:1], decimals, 1.0 / mm_per_unit)[0] * 10.0**-decimals
              * mm_per_unit)
    for k in range(len(lines)):
        pos[k + 1] = np.where(np.isnan(axes[k]), pos[k], axes[k])
    feed_mm_min = feed_words.copy()
    for k in range(1, feed_mm_min.size):
        if np.isnan(feed_mm_min[k]):
            feed_mm_min[k] = feed_mm_min[k - 1]
            feed_unit_mm_min[k] = feed_unit_mm_min[k - 1]
    step_mm = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    for still in np.flatnonzero(step_mm == 0.0):
        findings.add("zero-length", int(lines[still]), "move does not move (same point as the "
                     "one before, as written)")

    # the periods a move from or into a rest may span (profile key rest_move_s), as the
    # pipeline counts them
    rest_periods = max(1, math.ceil(machine.rest_move_s / period * (1.0 - FLOOR_MARGIN)))
    t_s = _check_timing(section, block, lim, r, step_mm, feed_mm_min, feed_unit_mm_min, lines,
                        rest_periods, findings)
    point_lines = np.concatenate([[section.comment_line], lines])

    # ---- geometry: project every point, deviation, ends, chord error, coverage ----
    dev_allow = r * (1.0 + NUMERIC_REL_TOL)
    u, dist, other = project_points_and_others(curve, pos, 2.0 * r, dev_allow,
                                               ANCHOR_ROUNDINGS * (r + lim.chord_mm))
    other = feet_ahead_of_behind(curve, pos, u, other, dev_allow)
    findings.measure("path-deviation", dist[1:], 0.0, dev_allow, lines)
    end_gap = float(np.linalg.norm(pos[-1] - curve.points[-1]))
    if end_gap > dev_allow:
        findings.add("end-point", int(lines[-1]),
                     f"the last point is {end_gap:.4g} mm from the curve end "
                     f"{_xyz(curve.points[-1])} (rounding allows {r:.4g} mm)")
    good = dist <= dev_allow
    pair = good[:-1] & good[1:]
    err = chord_errors_mm(curve, u[:-1][pair], u[1:][pair], pos[:-1][pair], pos[1:][pair])
    findings.measure("chord-error", err, lim.chord_mm, r * (1.0 + NUMERIC_REL_TOL),
                     lines[pair])
    cap = np.minimum(lim.feed_mm_s, np.maximum(feed_cap_mm_s(block, u[:-1]),
                                                 feed_cap_mm_s(block, u[1:])))
    dt = np.diff(t_s)
    findings.measure("feed", step_mm / dt, cap, 2.0 * r / dt, lines)

    ug, tg, pl = u[good], t_s[good], point_lines[good]
    if ug.size >= 2:
        kappa = curvature_1_mm(curve, ug)
        e = r * (1.0 + np.minimum(kappa * r, 1.0))
        # a point as near another foot (a curve that retraces itself through a cusp, within
        # rounding of it) is where either foot could be: its arc is known only that well
        s, between = foot_arcs(curve, ug, other[good])
        e += between
        cap_g = np.minimum(lim.feed_mm_s, np.maximum(feed_cap_mm_s(block, ug[:-1]),
                                                       feed_cap_mm_s(block, ug[1:])))
        findings.measure("coverage", np.diff(s), cap_g * np.diff(tg), e[:-1] + e[1:], pl[1:])
        _check_arc_kinematics(curve, lim, ug, tg, pl, s, e, kappa, h_a, h_j, findings)
    _check_xyz_kinematics(curve, lim, pos, t_s, u, point_lines, r, acc_total, h_x, findings)
    if path:
        _check_path_kinematics(curve, lim, pos, t_s, u, point_lines, r, h_p, findings)


def _check_timing(section: Section, block: CurveBlock, lim: Limits, r: float,
                  step_mm: np.ndarray, feed_mm_min: np.ndarray, feed_unit_mm_min: np.ndarray,
                  lines: np.ndarray, rest_periods: int, findings: Findings) -> np.ndarray:
    """Segment times, multi-period moves, period total and cycle time; returns the time of every
    point (M+1,) on the period grid.

    An F word is its feed to within half a unit of its last decimal (feed_unit_mm_min). Where F
    keeps few significant digits (a crawl at micrometres a minute, at the writer's cap on
    decimals) a move of thousands of periods is timed by it only to a few periods: the period
    total holds if some count each move's F allows adds up to the announced one."""
    period = lim.period_s
    half_unit = 0.5 * np.nan_to_num(feed_unit_mm_min)
    with np.errstate(divide="ignore", invalid="ignore"):
        seconds = step_mm / (feed_mm_min / 60.0)
        seconds_least = step_mm / ((feed_mm_min + half_unit) / 60.0)
        # a positive F word is at least one unit of its last decimal, so above half of one
        seconds_most = step_mm / ((feed_mm_min - half_unit) / 60.0)
        usable = np.isfinite(seconds) & (seconds > 0.0)
        n_periods, n_least, n_most = (
            np.where(usable, np.maximum(1, np.rint(t / period)), 1).astype(np.int64)
            for t in (seconds, seconds_least, seconds_most))
    off_pct = np.where(usable, 100.0 * np.abs(seconds - n_periods * period)
                       / (n_periods * period), 0.0)
    findings.measure("segment-time", off_pct[usable], 100.0 * SEGMENT_TIME_REL_TOL, 0.0,
                     lines[usable])
    multi = n_periods > 1
    skipped_cap = np.full(n_periods.shape, 4.0 * r + lim.acc_mm_s2 * period**2)
    at_rest = n_periods <= rest_periods
    skipped_cap[at_rest] = np.maximum(
        skipped_cap[at_rest], lim.jerk_mm_s3 * (n_periods[at_rest] * period) ** 3 / 6.0 + 2.0 * r)
    findings.measure("skipped-periods", step_mm[multi], skipped_cap[multi], 0.0, lines[multi])
    total = int(n_periods.sum())
    least, most = int(n_least.sum()), int(n_most.sum())
    span = "" if least == most else f" ({least} to {most} as their F words are rounded)"
    announced = section.n_points - 1
    if least > announced:
        findings.add("period-total", int(lines[-1]),
                     f"the moves cover {total} periods{span}, the comment announces "
                     f"{section.n_points} points ({announced} periods)")
    elif most < announced - 1:
        findings.add("period-total", int(lines[-1]),
                     f"the moves cover {total} periods{span}, the comment announces "
                     f"{section.n_points} points ({announced} periods): moves are missing")
    elif not announced - 1 <= total <= announced:
        findings.notes.append(f"curve {section.index}: the moves cover {total} periods as their "
                              f"F words read, {least} to {most} as they are rounded; the "
                              f"comment announces {announced}")
    elif total < announced:
        findings.notes.append(f"curve {section.index}: the moves cover {total} of the "
                              f"{announced} announced periods: the last point rounds onto the "
                              f"end point and is not written")
    written_s = float(np.sum(seconds[usable]))
    least_s = least_time_s(block, lim.feed_mm_s, lim.acc_mm_s2)
    findings.measure("cycle-time", least_s, written_s,
                     SEGMENT_TIME_REL_TOL * written_s + 2.0 * r / lim.feed_mm_s,
                     int(lines[-1]))
    return period * np.concatenate([[0], np.cumsum(n_periods)])


def _check_arc_kinematics(curve: NurbsCurve, lim: Limits, ug: np.ndarray, tg: np.ndarray,
                          pl: np.ndarray, s: np.ndarray, e: np.ndarray, kappa: np.ndarray,
                          h_a: float, h_j: float, findings: Findings) -> None:
    """Tangential a, j and normal a, j from the projected arc lengths s(t) (G,) of the points
    that lie on the curve."""
    rows = [("tangential-acc", 2, h_a, lim.acc_mm_s2)]
    if lim.jerk_model == "paper":  # under `path` the law's j is no limit: j - kappa^2 v^3 is,
        rows.append(("tangential-jerk", 3, h_j, lim.jerk_mm_s3))  # from positions
    for name, order, h, limit in rows:
        idx = stencils(tg, order, h)
        value, noise = derivative_estimate(tg, s, e, idx)
        findings.measure(name, np.abs(value), limit, noise * (1.0 + NUMERIC_REL_TOL),
                         pl[idx[:, 1]])

    # speed at each point: mean over its neighbours (one-sided at the ends)
    before = np.concatenate([[0], np.arange(ug.size - 1)])
    after = np.concatenate([np.arange(1, ug.size), [ug.size - 1]])
    span_s = tg[after] - tg[before]
    v = np.abs(s[after] - s[before]) / span_s
    skew = np.abs(tg[after] + tg[before] - 2.0 * tg)
    du = e / np.maximum(curve.speed(ug), 1e-300)
    k_before = curvature_1_mm(curve, np.maximum(ug - du, curve.u_min))
    k_after = curvature_1_mm(curve, np.minimum(ug + du, curve.u_max))
    k_low = np.minimum(kappa, np.minimum(k_before, k_after))
    # the central difference of s over two periods is v to within the law's jerk j span^2 / 24:
    # under the paper model |j| <= J_t; under the path model only j - kappa^2 v^3 is held to
    # J_t, and at a narrow peak passed at its limit j follows kappa^2 v^3, many times J_t
    jerk_bound = np.full(ug.size, lim.jerk_mm_s3)
    if lim.jerk_model == "path":
        k_high = np.maximum(kappa, np.maximum(k_before, k_after))
        jerk_bound = jerk_bound + k_high**2 * v**3
    e_v = ((e[after] + e[before]) / span_s + jerk_bound * span_s**2 / 24.0
           + lim.acc_mm_s2 * skew / 2.0)
    proxies = [("normal-acc", 2, lim.normal_acc_mm_s2)]
    if lim.jerk_model == "paper":  # under `path` the jerk vector from positions stands instead
        proxies.append(("normal-jerk", 3, lim.normal_jerk_mm_s3))
    for name, power, limit in proxies:
        kk = k_low ** (power - 1)
        value = v**power * kk
        allowance = ((v + e_v) ** power - v**power) * kk * (1.0 + NUMERIC_REL_TOL)
        informative = allowance <= limit  # elsewhere the vector estimate stands in
        findings.measure(name, value[informative], limit, allowance[informative],
                         pl[informative])


def _check_xyz_kinematics(curve: NurbsCurve, lim: Limits, pos: np.ndarray, t_s: np.ndarray,
                          u: np.ndarray, point_lines: np.ndarray, r: float, acc_total: float,
                          h_x: float, findings: Findings) -> None:
    """Acceleration vectors from the written points (N, 3): total, corner, split on the
    tangent, and reversals."""
    idx = stencils(t_s, 2, h_x)
    if idx.size == 0:
        return
    acc, noise = acceleration_xyz(t_s, pos, r, idx)
    noise = noise * (1.0 + NUMERIC_REL_TOL)
    line = point_lines[idx[:, 1]]
    size = np.linalg.norm(acc, axis=1)
    tangent, theta = turning_rad(curve, u[idx[:, 0]], u[idx[:, 1]], u[idx[:, 2]])
    corner = theta > CORNER_TURN_RAD
    findings.measure("acc-xyz", size[~corner], acc_total, noise[~corner], line[~corner])
    findings.measure("corner", size[corner], acc_total, noise[corner], line[corner])

    split = ~np.isnan(tangent[:, 0]) & ~corner  # at a corner the split says nothing more
    along = np.sum(acc[split] * tangent[split], axis=1)
    across = np.linalg.norm(acc[split] - along[:, None] * tangent[split], axis=1)
    sin_turn = np.sin(np.minimum(theta[split], 0.5 * np.pi))
    findings.measure("tangential-acc-xyz", np.abs(along), lim.acc_mm_s2,
                     lim.normal_acc_mm_s2 * sin_turn + noise[split], line[split])
    findings.measure("normal-acc-xyz", across, lim.normal_acc_mm_s2,
                     lim.acc_mm_s2 * sin_turn + noise[split], line[split])

    t = t_s[idx]
    d1, d2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 1]
    v1 = (pos[idx[:, 1]] - pos[idx[:, 0]]) / d1[:, None]
    v2 = (pos[idx[:, 2]] - pos[idx[:, 1]]) / d2[:, None]
    flip = np.sum(v1 * v2, axis=1) < 0.0
    speed = np.maximum(np.linalg.norm(v1, axis=1), np.linalg.norm(v2, axis=1))
    findings.measure("reversal", speed[flip], acc_total * (t[flip, 2] - t[flip, 0]) / 2.0,
                     (2.0 * r / d1[flip] + 2.0 * r / d2[flip]) * (1.0 + NUMERIC_REL_TOL),
                     line[flip])


def _check_path_kinematics(curve: NurbsCurve, lim: Limits, pos: np.ndarray, t_s: np.ndarray,
                           u: np.ndarray, point_lines: np.ndarray, r: float, h_p: float,
                           findings: Findings) -> None:
    """Under the jerk model `path`: the jerk vector from the written points split on the path,
    and every axis with a limit of its own (velocity, acceleration, jerk)."""
    idx = stencils(t_s, 3, h_p)
    if idx.size:
        w = divided_difference_weights(t_s, idx)
        jerk = np.einsum("sq,sqc->sc", w, pos[idx])
        noise = r * np.sum(np.abs(w), axis=1) * (1.0 + NUMERIC_REL_TOL)
        tangent, theta = turning_rad(curve, u[idx[:, 0]], 0.5 * (u[idx[:, 1]] + u[idx[:, 2]]),
                                     u[idx[:, 3]])
        split = ~np.isnan(tangent[:, 0])
        along = np.sum(jerk[split] * tangent[split], axis=1)
        across = np.linalg.norm(jerk[split] - along[:, None] * tangent[split], axis=1)
        sin_turn = np.sin(np.minimum(theta[split], 0.5 * np.pi))
        line = point_lines[idx[split, 1]]
        findings.measure("tangential-jerk-xyz", np.abs(along), lim.jerk_mm_s3,
                         lim.normal_jerk_mm_s3 * sin_turn + noise[split], line)
        findings.measure("normal-jerk-xyz", across, lim.normal_jerk_mm_s3,
                         lim.jerk_mm_s3 * sin_turn + noise[split], line)
    r_axis = r / math.sqrt(3.0)  # each coordinate is rounded on its own
    for kind, order, limits in (("axis-vel", 1, lim.axis_vel_mm_s),
                                ("axis-acc", 2, lim.axis_acc_mm_s2),
                                ("axis-jerk", 3, lim.axis_jerk_mm_s3)):
        bound = np.asarray(limits, dtype=float)
        if not np.isfinite(bound).any():
            continue
        if order == 1:  # a chord's mean velocity, between consecutive points
            idx = np.column_stack([np.arange(t_s.size - 1), np.arange(1, t_s.size)])
        else:
            idx = stencils(t_s, order, baseline_s(lim.period_s, order, r_axis,
                                                  float(bound[np.isfinite(bound)].min())))
        if idx.size == 0:
            continue
        w = divided_difference_weights(t_s, idx)
        value = np.abs(np.einsum("sq,sqc->sc", w, pos[idx]))
        noise = r_axis * np.sum(np.abs(w), axis=1) * (1.0 + NUMERIC_REL_TOL)
        line = point_lines[idx[:, order // 2]]
        for a, axis in enumerate("xyz"):
            if math.isfinite(bound[a]):
                findings.measure(f"{kind}-{axis}", value[:, a], bound[a], noise, line)


def _xyz(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.6g}" for c in p) + ")"
