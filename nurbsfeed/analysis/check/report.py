"""What `check` found: the checks' names and messages, violations, one Measure per check, the
report and its rendering as a table."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

SHOWN_PER_CHECK = 5

# name: (title, unit of the values, message)
CHECKS: dict[str, tuple[str, str, str]] = {
    "path-deviation": ("path deviation", "mm",
                       "point is {value:.4g} mm from the curve; rounding allows "
                       "{allowance:.4g} mm"),
    "chord-error": ("chord error", "mm", "chord error {value:.4g} mm > {limit:.4g} mm "
                    "+ {allowance:.4g} mm rounding"),
    "coverage": ("curve covered per move", "mm",
                 "the move advances {value:.6g} mm along the curve, more than the maximum feed "
                 "covers in its time ({limit:.6g} mm + {allowance:.3g} mm rounding): part of the "
                 "curve is skipped"),
    "cycle-time": ("least time along the curve", "s",
                   "the curve needs at least {value:.6g} s from rest to rest (maximum feed, "
                   "tangential acceleration), its moves take "
                   "{limit:.6g} s (+ {allowance:.3g} s rounding): the curve is cut short or its "
                   "F words are too high"),
    "segment-time": ("segment time off whole periods", "%",
                     "move lasts {value:.4g} % off a whole number of periods at its F "
                     "(allowed {limit:g} %): wrong F (the move arrives early or late) or "
                     "moved point"),
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
    "acc-xyz": ("acceleration from positions", "mm/s^2",
                "acceleration from the positions {value:.6g} mm/s^2 > {limit:.6g} (tangential "
                "and normal limits combined) + {allowance:.3g} mm/s^2 rounding noise"),
    "tangential-acc-xyz": ("tangential acc. from positions", "mm/s^2",
                           "tangential acceleration from the positions {value:.6g} mm/s^2 > "
                           "{limit:.6g} + {allowance:.3g} mm/s^2 (rounding noise and turning)"),
    "normal-acc-xyz": ("normal acc. from positions", "mm/s^2",
                       "normal acceleration from the positions {value:.6g} mm/s^2 > {limit:.6g} "
                       "+ {allowance:.3g} mm/s^2 (rounding noise and turning)"),
    "corner": ("corner: acc. from positions", "mm/s^2",
               "corner taken at speed: the path turns sharply here and the acceleration from the "
               "positions is {value:.6g} mm/s^2 > {limit:.6g} + {allowance:.3g} mm/s^2 rounding "
               "noise (the feed must come down to rest at a corner)"),
    "tangential-jerk-xyz": ("tangential jerk from positions", "mm/s^3",
                            "jerk along the path from the positions {value:.6g} mm/s^3 > "
                            "{limit:.6g} + {allowance:.3g} mm/s^3 (rounding noise and turning)"),
    "normal-jerk-xyz": ("normal jerk from positions", "mm/s^3",
                        "jerk across the path from the positions {value:.6g} mm/s^3 > "
                        "{limit:.6g} + {allowance:.3g} mm/s^3 (rounding noise and turning)"),
    **{f"{kind}-{axis}": (f"{axis.upper()} {title} from positions", unit,
                          f"{axis.upper()} {title} from the positions {{value:.6g}} {unit} > "
                          f"{{limit:.6g}} + {{allowance:.3g}} {unit} rounding noise")
       for kind, title, unit in (("axis-vel", "velocity", "mm/s"),
                                 ("axis-acc", "acceleration", "mm/s^2"),
                                 ("axis-jerk", "jerk", "mm/s^3"))
       for axis in "xyz"},
    "reversal": ("speed where velocity flips", "mm/s",
                 "reversal taken at speed: the velocity turns back at {value:.6g} mm/s, while "
                 "the acceleration limits allow a turn-back over this baseline only below "
                 "{limit:.6g} mm/s + {allowance:.3g} mm/s rounding noise"),
}
# rows of one jerk model only (design §2b): the proxy v^3 kappa^2 under `paper`; the jerk vector
# split on the path, and each axis with a limit of its own, under `path`. A row measured nowhere
# is left out of the table; so is the law's own j under `path` (no limit there: j - kappa^2 v^3
# is), while under `paper` it shows empty where too few moves estimate it.
PATH_UNMEASURED = frozenset({"tangential-jerk"})
MODEL_CHECKS = frozenset({"normal-jerk", "tangential-jerk-xyz", "normal-jerk-xyz"} | {
    f"{kind}-{axis}" for kind in ("axis-vel", "axis-acc", "axis-jerk") for axis in "xyz"})
STRUCTURE_CHECKS = ("pass-through", "curve-missing", "curve-extra", "comment", "no-moves",
                    "end-point", "period-total", "decimal-point", "number", "negative-zero",
                    "zero-feed", "zero-length", "feed-word", "g90-g91", "feed-restore")


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
    xyz_baseline_s: float  # h for the acceleration vector from positions
    path_baseline_s: float = 0.0  # h for the jerk vector (jerk model `path`; 0: not measured)


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
    jerk_model: str = "paper"

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


@dataclass
class Findings:
    """Violations and per-check arrays, filled curve by curve."""

    output: str
    violations: list[Violation] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    estimation: list[Estimation] = field(default_factory=list)
    arrays: dict[str, list[tuple[np.ndarray, ...]]] = field(default_factory=dict)

    def add(self, check: str, line: int, message: str) -> None:
        self.violations.append(Violation(check, f"{self.output}:{line}", message))

    def measure(self, check: str, value: np.ndarray | float, limit: np.ndarray | float,
                allowance: np.ndarray | float, line: np.ndarray | int) -> None:
        """Record one check's values at points (all (M,)), in mm and s."""
        value = np.atleast_1d(np.asarray(value, dtype=float))
        shape = value.shape
        self.arrays.setdefault(check, []).append(
            (value, np.broadcast_to(np.asarray(limit, dtype=float), shape),
             np.broadcast_to(np.asarray(allowance, dtype=float), shape),
             np.broadcast_to(np.asarray(line), shape)))


def reduce_check(name: str, parts: list[tuple[np.ndarray, ...]],
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


def first_per_check(violations: list[Violation]) -> list[Violation]:
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
        if m.n_checked == 0 and (m.name in MODEL_CHECKS or (
                report.jerk_model == "path" and m.name in PATH_UNMEASURED)):
            continue
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
    for r_mm, h_a, h_j, h_x, h_p in sorted({(e.rounding_mm, e.acc_baseline_s,
                                             e.jerk_baseline_s, e.xyz_baseline_s,
                                             e.path_baseline_s) for e in report.estimation}):
        path = (f"; jerk from positions: third divided differences over {h_p * 1e3:g} ms"
                if h_p else "")
        lines.append(f"ratio = worst / (limit + allowance); output rounding r = {r_mm:.3g} mm; "
                     f"tangential a, j: divided differences of the projected arc length over "
                     f"{h_a * 1e3:g} ms, {h_j * 1e3:g} ms; acceleration from positions: second "
                     f"divided differences of the written points over {h_x * 1e3:g} ms{path}; "
                     f"allowance: their rounding-noise bound")
    lines += [f"note: {note}" for note in report.notes]
    lines += [str(v) for v in report.violations]
    hidden = report.n_violations - len(report.violations)
    if hidden > 0:
        lines.append(f"... and {hidden} more")
    lines.append(f"result: {'OK' if report.ok else 'FAILED'}: {report.n_violations} violation(s)")
    return "\n".join(lines)
