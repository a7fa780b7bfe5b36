"""`nurbsfeed check`: a converted program verified against its source, without running the
planner; every definition and tolerance is in the comment that opens this module's body."""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nurbsfeed.analysis.geometry import (
    arc_length_mm,
    chord_errors_mm,
    curvature_1_mm,
    curve_length_mm,
)
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.kernel import eval_d1, find_span
from nurbsfeed.jit import jit
from nurbsfeed.machine import MM_PER_INCH, Machine
from nurbsfeed.pipeline import read_program, read_text
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.planner import feed_at
from nurbsfeed.program import CurveBlock, PassThrough

#
# Reference: only the source's curves and the machine profile; the planner is never run. Each
# emitted point is mapped back to its curve by projection (`_project_kernel`): a search that
# moves forward from the previous point's parameter (so a self-intersecting curve is followed
# branch by branch), brackets the foot point on g(u) = C'(u).(C(u) - P) and refines it by
# safeguarded Gauss-Newton. A point farther than ANCHOR_ROUNDINGS * (r + delta) from the curve does
# not move the search on, so one bad point does not derail the ones after it.
#
# Times: a move covering n periods ends n T after the previous one; n comes from its segment time
# |dP^| / (F/60) (P^ the written coordinates), which must be a whole number of periods.
#
# r = 0.5 10^-d sqrt(3) is the farthest a point rounded to d decimals can be from the true point.
# The projection keeps only the tangential part of that error: the arc position s_i of a point is
# known to e_i = r (1 + kappa_i r). Quantised coordinates make finite differences noisy (at d = 4,
# T = 1 ms, a per-period second difference has up to 350 mm/s^2 of rounding noise), so the
# kinematics are estimated from the projected arc lengths over wider baselines, with the noise
# bound as the allowance:
#
#   path deviation   |P^_i - C(u_i)| <= r.
#   chord error      farthest point of the arc C([u_i, u_i+1]) from the written chord <= delta + r
#                    (each chord end may be r off).
#   segment time     t = |dP^| / (F/60) within SEGMENT_TIME_REL_TOL of n T, n = round(t/T) >= 1.
#   skipped periods  n > 1 only where points rounded onto the previous one were dropped: two such
#                    points are <= 2r apart and a step grows by at most A_t T^2 per period (its
#                    second difference is a mean of a), so |dP^| <= 4r + A_t T^2.
#   period total     the moves' periods add up to at most the comment's point count - 1; fewer
#                    when the last points round onto the end point and are not written (a note).
#   feed             (s_i+1 - s_i) / (t_i+1 - t_i), the mean speed over the move (never above the
#                    true maximum), <= v_m(u) + (e_i + e_i+1) / dt.
#   tangential a, j  2 f[t0, t1, t2] and 6 f[t0, t1, t2, t3], divided differences of s(t) on
#                    points about h apart. k! times a k-th divided difference is a B-spline
#                    weighted mean of the k-th derivative over the nodes' span (Peano kernel,
#                    Hermite-Genocchi), so it never exceeds the true max |a| or |j|; rounding adds
#                    at most k! sum_q |w_q| e_q (w_q: the difference's weights): the allowance.
#                    h is the smallest multiple of T that keeps that bound under NOISE_SHARE of
#                    the limit for evenly spaced points.
#   normal a, j      v_i^2 kappa_i <= A_n, v_i^3 kappa_i^2 <= J_n, v_i the mean speed over the
#                    neighbouring points, kappa_i the smallest curvature within e_i of the point;
#                    allowance from the uncertainty of v_i: rounding noise, J_t dt^2 / 24 (mean vs
#                    centre value) and A_t |skew| / 2 (uneven neighbours).
#   structure        every non-NURBS source line present, byte-identical and in order; every curve
#                    once; every X/Y/Z/F value with a decimal point, no negative zero, no F0, no
#                    zero-length move, F on the first move; G90 ... G91 around the moves of a G91
#                    block and its F restored; moves for every curve that has a length; the last
#                    point is the curve end (within r). The
#                    first point is the position before the block, the curve start (the readers
#                    require it; JSON programs rapid there), taken as written at d decimals.

SEGMENT_TIME_REL_TOL = 0.005
NOISE_SHARE = 0.1
ANCHOR_ROUNDINGS = 10.0
NUMERIC_REL_TOL = 1e-6  # float slack on the exact bounds (coordinates carry ~1e-16 relative error)
PROJECT_ITERATIONS = 100
PROJECT_SEED_REL = 1e-9  # first bracket step (of the knot range) where |C'| = 0
SHOWN_PER_CHECK = 5

COMMENT_RE = re.compile(r"\(nurbsfeed: curve (\d+) (.*), (\d+) points, period ([0-9.eE+-]+) ms, "
                        r"(\w+), length ([0-9.]+) (mm|in), planned cycle ([0-9.]+) s\)$")
ZERO_LENGTH_LINE = "(nurbsfeed: zero-length curve, no move written)"  # pipeline.convert_block
MOVE_LINE_RE = re.compile(r"(?:G0*1(?![0-9.])\s*)?(?:[XYZF]\s*[-+]?[0-9.]*\s*)+")
WORD_RE = re.compile(r"([A-Z])\s*([-+]?[0-9.]*)")

# name: (title, unit of the values, message)
CHECKS: dict[str, tuple[str, str, str]] = {
    "path-deviation": ("path deviation", "mm",
                       "point is {value:.4g} mm from the curve; rounding allows {allowance:.4g} mm"),
    "chord-error": ("chord error", "mm", "chord error {value:.4g} mm > {limit:.4g} mm "
                    "+ {allowance:.4g} mm rounding"),
    "segment-time": ("segment time off whole periods", "%",
                     "move lasts {value:.4g} % off a whole number of periods at its F "
                     "(allowed {limit:g} %): wrong F or moved point"),
    "skipped-periods": ("multi-period move length", "mm",
                        "move spans several periods but is {value:.4g} mm long (> {limit:.4g} mm, "
                        "the most a move over dropped sub-resolution points can be): a line is "
                        "missing or F is wrong"),
    "feed": ("feed", "mm/s", "feed {value:.6g} mm/s > {limit:.6g} mm/s + {allowance:.3g} mm/s "
             "rounding noise"),
    "tangential-acc": ("tangential acceleration", "mm/s^2",
                       "tangential acceleration {value:.6g} mm/s^2 > {limit:.6g} "
                       "+ {allowance:.3g} mm/s^2 rounding noise"),
    "tangential-jerk": ("tangential jerk", "mm/s^3",
                        "tangential jerk {value:.6g} mm/s^3 > {limit:.6g} + {allowance:.3g} "
                        "mm/s^3 rounding noise"),
    "normal-acc": ("normal acceleration v^2 kappa", "mm/s^2",
                   "normal acceleration {value:.6g} mm/s^2 > {limit:.6g} + {allowance:.3g} mm/s^2"),
    "normal-jerk": ("normal jerk v^3 kappa^2", "mm/s^3",
                    "normal jerk {value:.6g} mm/s^3 > {limit:.6g} + {allowance:.3g} mm/s^3"),
}
STRUCTURE_CHECKS = ("pass-through", "curve-missing", "curve-extra", "comment", "no-moves",
                    "end-point", "period-total", "decimal-point", "number", "negative-zero",
                    "zero-feed", "zero-length", "feed-word", "g90-g91", "feed-restore")


G90_G91_MESSAGE = ("the moves of a G91 block must be bracketed by G90 and G91 lines (the "
                   "moves are absolute)")


@dataclass(frozen=True)
class Violation:
    check: str
    where: str  # OUTPUT:LINE
    message: str

    def __str__(self) -> str:
        return f"{self.where}: {self.check}: {self.message}"


@dataclass(frozen=True)
class Measure:
    """One quantitative check over every curve: its worst point and how many points broke it."""

    name: str
    title: str
    unit: str
    n_checked: int
    n_violations: int
    worst: float  # value at the worst point (largest value / (limit + allowance))
    limit: float
    allowance: float
    where: str

    @property
    def ratio(self) -> float:
        total = self.limit + self.allowance
        return self.worst / total if total > 0 else (0.0 if self.worst == 0 else math.inf)


@dataclass(frozen=True)
class Estimation:
    """How one curve's kinematics were estimated (lengths in mm)."""

    curve: int
    rounding_mm: float  # r
    acc_baseline_s: float  # h for the tangential acceleration
    jerk_baseline_s: float  # h for the tangential jerk


@dataclass(frozen=True)
class CheckReport:
    source: str
    output: str
    n_curves: int
    n_moves: int
    n_pass_through: int
    estimation: tuple[Estimation, ...]
    measures: tuple[Measure, ...]
    structure: dict[str, int]  # violations of each of STRUCTURE_CHECKS
    violations: tuple[Violation, ...]  # at most SHOWN_PER_CHECK per check
    n_violations: int  # all of them
    notes: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return self.n_violations == 0

    def as_dict(self) -> dict[str, Any]:
        return {"source": self.source, "output": self.output, "ok": self.ok,
                "curves": self.n_curves, "moves": self.n_moves,
                "pass_through_lines": self.n_pass_through, "units": "mm, s",
                "estimation": [vars(e) for e in self.estimation],
                "checks": [dict(vars(m), ratio=m.ratio) for m in self.measures],
                "structure": self.structure,
                "violation_count": self.n_violations,
                "violations": [vars(v) for v in self.violations], "notes": list(self.notes)}


@jit
def _project_kernel(knots, cw, degree, targets, u_first, u_last, back_mm, anchor_mm, u_out,
                    dist_out):
    """Foot parameters of targets (N, 3), in order: u_out (N,), distances dist_out (N,).

    Each search starts back_mm of arc behind the last anchored point (rounding may put a point
    slightly behind the one before) and brackets g(u) = C'(u).(C(u) - P) < 0 <= g by doubling
    steps; a target beyond the end projects to u_last. A point within anchor_mm becomes the anchor.
    """
    n_ctrl = cw.shape[0]
    basis = np.empty(degree + 1)
    dbasis = np.empty(degree + 1)
    left = np.empty(degree + 1)
    right = np.empty(degree + 1)
    p = np.empty(3)
    d = np.empty(3)
    seed = (u_last - u_first) * PROJECT_SEED_REL
    anchor = u_first
    span = find_span(knots, degree, n_ctrl, u_first, degree)
    for i in range(targets.shape[0]):
        tx = targets[i, 0]
        ty = targets[i, 1]
        tz = targets[i, 2]
        span = find_span(knots, degree, n_ctrl, anchor, span)
        eval_d1(knots, cw, degree, anchor, span, basis, dbasis, left, right, p, d)
        speed = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        chord = math.sqrt((tx - p[0]) ** 2 + (ty - p[1]) ** 2 + (tz - p[2]) ** 2)
        origin = anchor
        step = seed
        if speed > 0.0:
            origin = max(u_first, anchor - back_mm / speed)
            step = max(seed, (chord + back_mm) / speed)
        lo = origin
        hi = origin
        found = False
        while True:
            hi = min(origin + step, u_last)
            span = find_span(knots, degree, n_ctrl, hi, span)
            eval_d1(knots, cw, degree, hi, span, basis, dbasis, left, right, p, d)
            g = d[0] * (p[0] - tx) + d[1] * (p[1] - ty) + d[2] * (p[2] - tz)
            if g >= 0.0:
                found = True
                break
            lo = hi
            if hi >= u_last:
                break
            step *= 2.0
        u = u_last
        if found:
            u = hi
            for _ in range(PROJECT_ITERATIONS):
                span = find_span(knots, degree, n_ctrl, u, span)
                eval_d1(knots, cw, degree, u, span, basis, dbasis, left, right, p, d)
                g = d[0] * (p[0] - tx) + d[1] * (p[1] - ty) + d[2] * (p[2] - tz)
                if g > 0.0:
                    hi = u
                elif g < 0.0:
                    lo = u
                else:
                    break
                gp = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]  # Gauss-Newton: |C'|^2
                nu = u - g / gp if gp > 0.0 else 0.5 * (lo + hi)
                if not lo < nu < hi:
                    nu = 0.5 * (lo + hi)
                if abs(nu - u) <= 1e-16 * (abs(u) + u_last - u_first) or hi - lo <= 0.0:
                    u = nu
                    break
                u = nu
        span = find_span(knots, degree, n_ctrl, u, span)
        eval_d1(knots, cw, degree, u, span, basis, dbasis, left, right, p, d)
        dist = math.sqrt((tx - p[0]) ** 2 + (ty - p[1]) ** 2 + (tz - p[2]) ** 2)
        u_out[i] = u
        dist_out[i] = dist
        if dist <= anchor_mm:
            anchor = u


def project_points(curve: NurbsCurve, targets: np.ndarray, back_mm: float,
                   anchor_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Foot parameters and distances of ordered points (N, 3) on the curve: two (N,) arrays."""
    u = np.empty(len(targets))
    dist = np.empty(len(targets))
    _project_kernel(curve.knots, curve.homogeneous, curve.degree,
                    np.ascontiguousarray(targets, dtype=float), curve.u_min, curve.u_max,
                    back_mm, anchor_mm, u, dist)
    return u, dist


def _split_lines(text: str) -> list[str]:
    """Lines with their endings ("\\r\\n" stays with its line)."""
    parts = text.split("\n")
    lines = [part + "\n" for part in parts[:-1]]
    if parts[-1]:
        lines.append(parts[-1])
    return lines


def _body(line: str) -> str:
    return line.rstrip("\r\n")


def _round_written(x: np.ndarray, decimals: int) -> np.ndarray:
    """Coordinates as the writer rounds them: half away from zero, at `decimals`."""
    scale = 10.0**decimals
    return np.sign(x) * np.floor(np.abs(x) * scale + 0.5) / scale


@dataclass
class _Section:
    """The lines that replaced one curve in the output."""

    index: int
    comment_line: int  # 1-based
    n_points: int
    period_ms: float
    zero_length: bool
    moves: list[tuple[int, str]] = field(default_factory=list)  # (line number, text)


@dataclass
class _Findings:
    """Violations and per-check arrays, filled curve by curve."""

    output: str
    violations: list[Violation] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    estimation: list[Estimation] = field(default_factory=list)
    arrays: dict[str, list[tuple[np.ndarray, ...]]] = field(default_factory=dict)

    def add(self, check: str, line: int, message: str) -> None:
        self.violations.append(Violation(check, f"{self.output}:{line}", message))

    def measure(self, check: str, value: np.ndarray, limit: np.ndarray | float,
                allowance: np.ndarray | float, line: np.ndarray, scale: float = 1.0) -> None:
        """Record one check's values at points (all (M,)), in program units times `scale`."""
        value = np.asarray(value, dtype=float) * scale
        shape = value.shape
        self.arrays.setdefault(check, []).append(
            (value, np.broadcast_to(np.asarray(limit, dtype=float) * scale, shape),
             np.broadcast_to(np.asarray(allowance, dtype=float) * scale, shape),
             np.asarray(line)))


def _check_words(section: _Section, findings: _Findings) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """Decode the moves: X/Y/Z words (M, 3) as NaN where not written, F (M,) (NaN: modal), line
    numbers (M,); number-format violations are recorded on the way."""
    m = len(section.moves)
    axes = np.full((m, 3), np.nan)
    feed = np.full(m, np.nan)
    lines = np.array([line for line, _ in section.moves], dtype=np.int64)
    for k, (line, text) in enumerate(section.moves):
        for letter, value in WORD_RE.findall(_body(text)):
            if letter == "G":
                continue
            if "." not in value:
                findings.add("decimal-point", line, f"{letter}{value} has no decimal point "
                             f"(write {letter}{value or '0'}.)")
            try:
                number = float(value)
            except ValueError:
                findings.add("number", line, f"{letter}{value} is not a number")
                continue
            if number == 0.0 and value.startswith("-"):
                findings.add("negative-zero", line, f"{letter}{value} is a negative zero "
                             f"(write {letter}0.)")
            if letter == "F":
                if number <= 0.0:
                    findings.add("zero-feed", line, f"F{value}: a G1 move needs a positive feed")
                feed[k] = number
            else:
                axes[k, "XYZ".index(letter)] = number
    return axes, feed, lines


def _stencils(t_s: np.ndarray, order: int, baseline_s: float) -> np.ndarray:
    """Node indices (S, order+1): from each point, the first points at or after t + q h."""
    starts = np.arange(t_s.size)
    cols = [starts] + [np.searchsorted(t_s, t_s + q * baseline_s * (1.0 - 1e-9), side="left")
                       for q in range(1, order + 1)]
    idx = np.stack(cols, axis=1)
    ok = (idx[:, -1] < t_s.size) & np.all(np.diff(idx, axis=1) > 0, axis=1)
    return idx[ok]


def _derivative_estimate(t_s: np.ndarray, s_mm: np.ndarray, e_mm: np.ndarray,
                         idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """k! f[t_0..t_k] at the stencils idx (S, k+1), and its rounding-noise bound k! sum |w| e."""
    k = idx.shape[1] - 1
    t = t_s[idx]
    gap = t[:, :, None] - t[:, None, :]
    diag = np.arange(k + 1)
    gap[:, diag, diag] = 1.0
    w = 1.0 / np.prod(gap, axis=2)
    fact = math.factorial(k)
    return fact * np.sum(w * s_mm[idx], axis=1), fact * np.sum(np.abs(w) * e_mm[idx], axis=1)


def _baseline_s(period_s: float, order: int, noise_mm: float, limit: float) -> float:
    """Smallest multiple of T whose evenly spaced k-th difference noise (4 e / h^2 for k = 2,
    8 e / h^3 for k = 3) stays under NOISE_SHARE of the limit."""
    gain = {2: 4.0, 3: 8.0}[order]
    h = (gain * noise_mm / (NOISE_SHARE * limit)) ** (1.0 / order)
    return period_s * max(1, math.ceil(h / period_s - 1e-9))


def _check_section(section: _Section, block: CurveBlock, machine: Machine,
                   findings: _Findings) -> None:
    """Geometry, timing and kinematics of one curve's moves."""
    units_machine = machine.in_program_units(block.units)
    lim = Limits.from_machine(units_machine)
    curve = block.curve
    scale = MM_PER_INCH if block.units == "in" else 1.0
    period = lim.period_s
    r = 0.5 * 10.0**-units_machine.decimals * math.sqrt(3.0)
    h_a = _baseline_s(period, 2, r, lim.acc_mm_s2)
    h_j = _baseline_s(period, 3, r, lim.jerk_mm_s3)
    findings.estimation.append(Estimation(section.index, r * scale, h_a, h_j))
    if abs(section.period_ms * 1e-3 - period) > 1e-9 * period:
        findings.add("comment", section.comment_line,
                     f"the comment announces a {section.period_ms:g} ms period, the machine "
                     f"profile has {period * 1e3:g} ms: check with the profile used to convert")
    if section.zero_length or not section.moves:
        length = curve_length_mm(curve)
        if length > r:
            findings.add("no-moves", section.comment_line,
                         f"no move written but the curve is {length * scale:.4g} mm long")
        return

    axes, feed_words, lines = _check_words(section, findings)
    if np.isnan(feed_words[0]):
        findings.add("feed-word", int(lines[0]), "the first move has no F word (it would run at "
                     "the program's modal feed)")
    start = _round_written(curve.points[0], units_machine.decimals)
    pos = np.empty((len(lines) + 1, 3))
    pos[0] = start
    for k in range(len(lines)):
        pos[k + 1] = np.where(np.isnan(axes[k]), pos[k], axes[k])
    feed_mm_min = feed_words.copy()
    for k in range(1, feed_mm_min.size):
        if np.isnan(feed_mm_min[k]):
            feed_mm_min[k] = feed_mm_min[k - 1]
    step_mm = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    for k in np.flatnonzero(step_mm == 0.0):
        findings.add("zero-length", int(lines[k]), "move does not move (same point as the "
                     "one before, as written)")

    # ---- time of each move ----
    with np.errstate(divide="ignore", invalid="ignore"):
        seconds = step_mm / (feed_mm_min / 60.0)
    usable = np.isfinite(seconds) & (seconds > 0.0)
    n_periods = np.where(usable, np.maximum(1, np.rint(seconds / period)), 1).astype(np.int64)
    off_pct = np.where(usable, 100.0 * np.abs(seconds - n_periods * period)
                       / (n_periods * period), 0.0)
    findings.measure("segment-time", off_pct[usable], 100.0 * SEGMENT_TIME_REL_TOL, 0.0,
                     lines[usable])
    multi = n_periods > 1
    findings.measure("skipped-periods", step_mm[multi], 4.0 * r + lim.acc_mm_s2 * period**2, 0.0,
                     lines[multi], scale)
    total = int(n_periods.sum())
    announced = section.n_points - 1
    if total > announced:
        findings.add("period-total", int(lines[-1]),
                     f"the moves cover {total} periods, the comment announces "
                     f"{section.n_points} points ({announced} periods)")
    elif total < announced:
        findings.notes.append(f"curve {section.index}: the moves cover {total} of the "
                              f"{announced} announced periods: the last points round onto the "
                              f"end point and are not written")
    t_s = period * np.concatenate([[0], np.cumsum(n_periods)])

    # ---- geometry: project every point, deviation, ends, chord error ----
    u, dist = project_points(curve, pos, 2.0 * r, ANCHOR_ROUNDINGS * (r + lim.chord_mm))
    point_lines = np.concatenate([[section.comment_line], lines])
    dev_allow = r * (1.0 + NUMERIC_REL_TOL)
    findings.measure("path-deviation", dist[1:], 0.0, dev_allow, lines, scale)
    end_gap = float(np.linalg.norm(pos[-1] - curve.points[-1]))
    if end_gap > dev_allow:
        findings.add("end-point", int(lines[-1]),
                     f"the last point is {end_gap * scale:.4g} mm from the curve end "
                     f"{_xyz(curve.points[-1])} (rounding allows {r * scale:.4g} mm)")
    good = dist <= dev_allow
    pair = good[:-1] & good[1:]
    err = chord_errors_mm(curve, u[:-1][pair], u[1:][pair], pos[:-1][pair], pos[1:][pair])
    findings.measure("chord-error", err, lim.chord_mm, r * (1.0 + NUMERIC_REL_TOL), lines[pair],
                     scale)

    # ---- kinematics on the projected arc lengths of the points that lie on the curve ----
    ug, tg, pl = u[good], t_s[good], point_lines[good]
    if ug.size < 2:
        return
    kappa = curvature_1_mm(curve, ug)
    e = r * (1.0 + kappa * r)
    s = arc_length_mm(curve, ug)
    dt = np.diff(tg)
    v_move = np.diff(s) / dt
    cap = np.maximum(feed_at(ug[:-1], block.feed_u, block.feed_mm_s),
                     feed_at(ug[1:], block.feed_u, block.feed_mm_s))
    findings.measure("feed", v_move, np.minimum(lim.feed_mm_s, cap), (e[:-1] + e[1:]) / dt,
                     pl[1:], scale)
    for name, order, h, limit in (("tangential-acc", 2, h_a, lim.acc_mm_s2),
                                  ("tangential-jerk", 3, h_j, lim.jerk_mm_s3)):
        idx = _stencils(tg, order, h)
        value, noise = _derivative_estimate(tg, s, e, idx)
        findings.measure(name, np.abs(value), limit, noise * (1.0 + NUMERIC_REL_TOL),
                         pl[idx[:, 1]], scale)

    # speed at each point: mean over its neighbours (one-sided at the ends)
    before = np.concatenate([[0], np.arange(ug.size - 1)])
    after = np.concatenate([np.arange(1, ug.size), [ug.size - 1]])
    span_s = tg[after] - tg[before]
    v = (s[after] - s[before]) / span_s
    skew = np.abs(tg[after] + tg[before] - 2.0 * tg)
    e_v = ((e[after] + e[before]) / span_s + lim.jerk_mm_s3 * span_s**2 / 24.0
           + lim.acc_mm_s2 * skew / 2.0)
    v = np.abs(v)
    du = e / np.maximum(curve.speed(ug), 1e-300)
    k_low = np.minimum(kappa, np.minimum(curvature_1_mm(curve, np.maximum(ug - du, curve.u_min)),
                                         curvature_1_mm(curve, np.minimum(ug + du, curve.u_max))))
    findings.measure("normal-acc", v**2 * k_low, lim.normal_acc_mm_s2,
                     ((v + e_v) ** 2 - v**2) * k_low * (1.0 + NUMERIC_REL_TOL), pl, scale)
    findings.measure("normal-jerk", v**3 * k_low**2, lim.normal_jerk_mm_s3,
                     ((v + e_v) ** 3 - v**3) * k_low**2 * (1.0 + NUMERIC_REL_TOL), pl, scale)


def _xyz(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.6g}" for c in p) + ")"


def _parse_output(lines: list[str], blocks: list[CurveBlock],
                  following: dict[int, list[str]], findings: _Findings
                  ) -> tuple[list[tuple[str, Any]], list[int], list[_Section]]:
    """Output lines -> tokens (("line", text) or ("curve", index)), their line numbers, and the
    curve sections. A section is a nurbsfeed comment line and the moves after it."""
    tokens: list[tuple[str, Any]] = []
    token_lines: list[int] = []
    sections = []
    i = 0
    while i < len(lines):
        match = COMMENT_RE.match(_body(lines[i]))
        if match is None:
            tokens.append(("line", lines[i]))
            token_lines.append(i + 1)
            i += 1
            continue
        index = int(match[1])
        section = _Section(index, i + 1, int(match[3]), float(match[4]), False)
        tokens.append(("curve", index))
        token_lines.append(i + 1)
        sections.append(section)
        block = blocks[index] if index < len(blocks) else None
        i = _parse_section(lines, i + 1, section, block, following.get(index, []), findings)
    return tokens, token_lines, sections


def _parse_section(lines: list[str], i: int, section: _Section, block: CurveBlock | None,
                   after: list[str], findings: _Findings) -> int:
    """Read the moves of one section from line index i; return the index after the section."""
    if i < len(lines) and _body(lines[i]) == ZERO_LENGTH_LINE:
        section.zero_length = True
        return i + 1
    incremental = block is not None and block.incremental
    restore = (block.feed_word_after + block.eol
               if block is not None and block.feed_word_after else None)
    if incremental:
        if i < len(lines) and _body(lines[i]) == "G90":
            i += 1
        else:
            findings.add("g90-g91", i + 1, G90_G91_MESSAGE)
    first = i
    while i < len(lines) and MOVE_LINE_RE.fullmatch(_body(lines[i])):
        i += 1
    if not incremental:
        # a bare F or coordinate line after the block (its F restore, or the program's next
        # lines) looks like a move: give back the trailing lines that are exactly those
        expected = ([restore] if restore else []) + after
        for k in range(min(len(expected), i - first), 0, -1):
            if lines[i - k:i] == expected[:k]:
                i -= k
                break
    section.moves = [(n + 1, lines[n]) for n in range(first, i)]
    if incremental:
        if i < len(lines) and _body(lines[i]) == "G91":
            i += 1
        else:
            findings.add("g90-g91", i + 1, G90_G91_MESSAGE)
    if restore is not None:
        if i < len(lines) and lines[i] == restore:
            i += 1
        else:
            findings.add("feed-restore", i + 1, f"the program's feed must be restored after the "
                         f"moves with the line {restore.strip()!r}")
    return i


def _source_tokens(path: Path, machine: Machine, dialect: str
                   ) -> tuple[list[tuple[str, Any]], list[CurveBlock], dict[int, list[str]]]:
    """Source -> tokens, curve blocks, and the pass-through lines that follow each curve."""
    tokens: list[tuple[str, Any]] = []
    blocks: list[CurveBlock] = []
    following: dict[int, list[str]] = {}
    for item in read_program(path, read_text(path), dialect, machine.decimals):
        if isinstance(item, PassThrough):
            for line in _split_lines(item.text):
                tokens.append(("line", line))
                if blocks:
                    following[len(blocks) - 1].append(line)
        else:
            tokens.append(("curve", len(blocks)))
            following[len(blocks)] = []
            blocks.append(item)
    return tokens, blocks, following


def _compare_structure(src: list[tuple[str, Any]], out: list[tuple[str, Any]],
                       out_lines: list[int], blocks: list[CurveBlock], n_lines: int,
                       findings: _Findings) -> None:
    """Pass-through lines and curve sections of the output against the source, in order."""
    if src == out:
        return
    matcher = difflib.SequenceMatcher(None, src, out, autojunk=False)

    def line_at(j: int) -> int:
        return out_lines[j] if j < len(out_lines) else n_lines + 1

    for op, i1, i2, j1, j2 in matcher.get_opcodes():
        if op == "equal":
            continue
        gone = src[i1:i2]
        extra = out[j1:j2]
        if op == "replace":
            gone_lines = [t for t in gone if t[0] == "line"]
            extra_lines = [t for t in extra if t[0] == "line"]
            for (_, want), j in zip(gone_lines, [j for j in range(j1, j2)
                                                 if out[j][0] == "line"]):
                findings.add("pass-through", line_at(j), f"line changed: expected "
                             f"{_body(want)!r}, found {_body(out[j][1])!r}")
            gone = [t for t in gone if t[0] == "curve"] + gone_lines[len(extra_lines):]
            extra = [t for t in extra if t[0] == "curve"] + extra_lines[len(gone_lines):]
        for kind, value in gone:
            if kind == "curve":
                findings.add("curve-missing", line_at(j1), f"curve {value} "
                             f"({blocks[value].curve.name}, {blocks[value].location}) is missing "
                             f"from the output")
            else:
                findings.add("pass-through", line_at(j1), f"source line missing here: "
                             f"{_body(value)!r}")
        for kind, value in extra:
            j = j1 + out[j1:j2].index((kind, value))
            if kind == "curve":
                findings.add("curve-extra", line_at(j), f"section for curve {value} is not "
                             f"expected here (the source has {len(blocks)} curves)")
            else:
                findings.add("pass-through", line_at(j), f"line not in the source: "
                             f"{_body(value)!r}")


def check_files(source: Path, output: Path, machine: Machine,
                dialect: str = "auto") -> CheckReport:
    """Check the converted program `output` against `source` (see the notes above)."""
    src_tokens, blocks, following = _source_tokens(source, machine, dialect)
    out_lines = _split_lines(read_text(output))
    findings = _Findings(str(output))
    out_tokens, token_lines, sections = _parse_output(out_lines, blocks, following, findings)
    _compare_structure(src_tokens, out_tokens, token_lines, blocks, len(out_lines), findings)
    for section in sections:
        if section.index < len(blocks):
            _check_section(section, blocks[section.index], machine, findings)
    structural = findings.violations
    shown = _first_per_check(structural)
    measures = []
    for name in CHECKS:
        measure, listed = _reduce(name, findings.arrays.get(name, []), str(output))
        measures.append(measure)
        shown += listed
    shown.sort(key=lambda v: int(v.where.rsplit(":", 1)[1]))
    structure = {name: sum(1 for v in structural if v.check == name)
                 for name in STRUCTURE_CHECKS}
    return CheckReport(str(source), str(output), len(blocks),
                       sum(len(s.moves) for s in sections),
                       sum(1 for t in src_tokens if t[0] == "line"), tuple(findings.estimation),
                       tuple(measures), structure, tuple(shown),
                       len(structural) + sum(m.n_violations for m in measures),
                       tuple(findings.notes))


def _reduce(name: str, parts: list[tuple[np.ndarray, ...]],
            output: str) -> tuple[Measure, list[Violation]]:
    """One check's arrays over all curves -> its Measure and its first violations."""
    title, unit, template = CHECKS[name]
    if not any(p[0].size for p in parts):  # no curve long enough for this estimate
        return Measure(name, title, unit, 0, 0, 0.0, 0.0, 0.0, "-"), []
    value, limit, allowance, line = (np.concatenate([p[q] for p in parts]) for q in range(4))
    total = limit + allowance
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(total > 0, value / total, np.where(value > 0, np.inf, 0.0))
    ratio = np.where(np.isnan(ratio), np.inf, ratio)
    bad = np.flatnonzero(ratio > 1.0)
    listed = [Violation(name, f"{output}:{int(line[k])}",
                        template.format(value=value[k], limit=limit[k], allowance=allowance[k]))
              for k in bad[:SHOWN_PER_CHECK]]
    w = int(np.argmax(ratio))
    return Measure(name, title, unit, int(value.size), int(bad.size), float(value[w]),
                   float(limit[w]), float(allowance[w]), f"{output}:{int(line[w])}"), listed


def _first_per_check(violations: list[Violation]) -> list[Violation]:
    seen: dict[str, int] = {}
    kept = []
    for v in violations:
        seen[v.check] = seen.get(v.check, 0) + 1
        if seen[v.check] <= SHOWN_PER_CHECK:
            kept.append(v)
    return kept


def render_check(report: CheckReport, machine_name: str) -> str:
    """The check as a table, then how the kinematics were estimated, then the violations."""
    lines = [f"check {report.output} against {report.source} (machine {machine_name}): "
             f"{report.n_curves} curve(s), {report.n_moves:,} moves, {report.n_pass_through} "
             "pass-through lines",
             f"{'check':<31} {'unit':<7} {'worst':>11} {'limit':>11} {'allowance':>10} "
             f"{'ratio':>7} {'points':>8} {'broken':>6}  worst at"]
    for m in report.measures:
        if m.n_checked == 0:
            lines.append(f"{m.title:<31} {m.unit:<7} {'-':>11} {'-':>11} {'-':>10} {'-':>7} "
                         f"{0:>8} {0:>6}")
            continue
        lines.append(f"{m.title:<31} {m.unit:<7} {m.worst:>11.5g} {m.limit:>11.5g} "
                     f"{m.allowance:>10.3g} {m.ratio:>7.4f} {m.n_checked:>8} "
                     f"{m.n_violations:>6}  {m.where}")
    broken = [f"{name} ({count})" for name, count in report.structure.items() if count]
    lines.append("source lines, curves, number format, curve ends, G90/G91 and F restore: "
                 + ("ok" if not broken else "BROKEN: " + ", ".join(broken)))
    for r_mm, h_a, h_j in sorted({(e.rounding_mm, e.acc_baseline_s, e.jerk_baseline_s)
                                  for e in report.estimation}):
        lines.append(f"ratio = worst / (limit + allowance); output rounding r = {r_mm:.3g} mm; "
                     f"tangential a, j: divided differences of the projected arc length over "
                     f"{h_a * 1e3:g} ms, {h_j * 1e3:g} ms; allowance: their rounding-noise bound")
    lines += [f"note: {note}" for note in report.notes]
    lines += [str(v) for v in report.violations]
    hidden = report.n_violations - len(report.violations)
    if hidden > 0:
        lines.append(f"... and {hidden} more")
    lines.append(f"result: {'OK' if report.ok else 'FAILED'}: {report.n_violations} violation(s)")
    return "\n".join(lines)
