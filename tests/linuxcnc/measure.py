"""How the simulated machine ran a converted program: cycle and path of each curve.

The written moves give the planned time of every point on the written polyline: move k ends
Σ |ΔP|/F after the curve start (one period per move, or several where points were merged).
Each servo sample is mapped to its nearest place on the polyline, walking forward, so every
sample carries the planned time at which the plan would be where the machine is. The machine's
time between two planned instants (the ends of the first and the second-to-last move; the
crossing found between samples) divided by the planned time between them is the cycle ratio:
1 means the machine followed the planned feed. The path error is the largest distance of a
sample in that stretch from the exact curve (nurbsfeed's own projection, the one `check` uses).
The first and the last move are left out of that ratio because the machine's departure and
arrival are only known to a servo period; the rest-to-rest ratio takes them in (the machine's
time from the last sample at the start to the first at the end over the planned cycle), to a
servo period: it shows what a move from or into rest costs (docs/linuxcnc.md). It
means that only where the machine stands at the curve start and end: LinuxCNC blends a tangent
move before or after a curve into it, and a curve entered or left in motion shows less.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nurbsfeed.analysis.check.projection import project_points
from nurbsfeed.chains import ChainWindow, chain_items
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import chain_block
from nurbsfeed.program import MM_PER_INCH, CurveBlock
from nurbsfeed.readers import read_program
from tests.linuxcnc.programs import LINUXCNC_PROFILE, WrittenCurve, written_curves
from tests.linuxcnc.run_sim import SERVO_PERIOD_S

ARRIVAL_MM = 0.01  # a sample this near the curve start: the machine has arrived there
LEFT_MM = 0.1  # a sample this far from the polyline: the machine has left the curve
WALK_WINDOW = 64  # moves looked at ahead of the last sample's move
PROJECTION_BACK_MM = 1e-3
PROJECTION_ACCEPT_MM = 1e-4
REST_TIME_S = 1e-9  # planned time from the start, and to the end, that counts as being there


class MeasurementError(ValueError):
    """The recorded positions do not run along the curve from its start to its end."""


@dataclass(frozen=True)
class CurveRun:
    planned_s: float  # between the ends of the first and the second-to-last written move
    measured_s: float  # the machine's time between the same two places
    path_error_mm: float  # farthest sample of that stretch from the exact curve
    # servo periods in that stretch without motion: LinuxCNC's queue ran empty (its task did
    # not keep up in real time) or a move ended in a full stop
    standstill_periods: int
    planned_cycle_s: float  # the whole curve, rest to rest (the F words' sum)
    rest_to_rest_s: float  # the machine's time from leaving the start to reaching the end

    @property
    def cycle_ratio(self) -> float:
        return self.measured_s / self.planned_s

    @property
    def rest_to_rest_ratio(self) -> float:
        return self.rest_to_rest_s / self.planned_cycle_s


def curve_blocks(source: Path) -> list[CurveBlock]:
    """The curves of `source` as converted, in the program's unit (the written moves' unit):
    curves that join as one chain (design §3b; gathered as the linuxcnc profile's output
    decimals gather them), each chain one block."""
    machine = load_machine(LINUXCNC_PROFILE)
    blocks = []
    for item in chain_items(read_program(source), machine):
        if isinstance(item, ChainWindow):
            block = chain_block(item, machine.limits)[0]
            curve = block.curve
            if block.units == "in":  # chain_block works in mm
                points = curve.points / MM_PER_INCH
                curve = NurbsCurve(curve.degree, curve.knots, points, curve.weights,
                                   curve.name, curve.u_origin, curve.u_scale)
            blocks.append(dataclasses.replace(block, curve=curve))
    return blocks


def measure(source: Path, program: Path, samples_mm: np.ndarray) -> list[CurveRun]:
    """Each curve of `source` as the machine ran `program` (its conversion), in order."""
    runs = []
    first_sample = 0
    for block, written in zip(curve_blocks(source), written_curves(program.read_text()),
                              strict=True):
        scale = MM_PER_INCH if block.units == "in" else 1.0
        run, first_sample = _measure_curve(block, written, samples_mm / scale, scale,
                                           first_sample)
        runs.append(run)
    return runs


def _measure_curve(block: CurveBlock, written: WrittenCurve, samples: np.ndarray, scale: float,
                   first_sample: int) -> tuple[CurveRun, int]:
    start = block.curve.points[0]
    # an axis not written since the curve comment holds the value it had at the curve start
    ends = np.where(np.isnan(written.ends), start, written.ends)
    vertices = np.vstack([start, ends])
    lengths = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
    times = np.concatenate([[0.0], np.cumsum(lengths / written.feeds_per_min * 60.0)])

    arrived = np.nonzero(np.linalg.norm(samples[first_sample:] - start, axis=1) * scale
                         <= ARRIVAL_MM)[0]
    if len(arrived) == 0:
        raise MeasurementError("the machine never reached the start of the curve at "
                               f"{block.location}")
    sample_times, sample_index = _walk(samples, first_sample + int(arrived[0]), vertices, times,
                                       scale)
    planned_from, planned_to = times[1], times[-2]
    measured_from = _crossing(sample_times, sample_index, planned_from)
    measured_to = _crossing(sample_times, sample_index, planned_to)
    inside = (sample_times >= planned_from) & (sample_times <= planned_to)
    inside_samples = samples[sample_index[inside]]
    _, distance = project_points(block.curve, inside_samples, PROJECTION_BACK_MM / scale,
                                 PROJECTION_ACCEPT_MM / scale, PROJECTION_BACK_MM / scale)
    standing = np.all(inside_samples[1:] == inside_samples[:-1], axis=1)
    left = _departure(sample_times, sample_index, times[1])
    reached = _crossing(sample_times, sample_index, times[-1] - REST_TIME_S)
    run = CurveRun(planned_s=planned_to - planned_from,
                   measured_s=(measured_to - measured_from) * SERVO_PERIOD_S,
                   path_error_mm=float(np.max(distance)) * scale,
                   standstill_periods=int(np.count_nonzero(standing)),
                   planned_cycle_s=float(times[-1]),
                   rest_to_rest_s=float(reached - left) * SERVO_PERIOD_S)
    return run, int(sample_index[-1]) + 1


def _walk(samples: np.ndarray, first: int, vertices: np.ndarray, times: np.ndarray,
          scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The planned time of each sample from `first` on, (K,), and the samples' indices, (K,):
    the time of its nearest place on the written moves (vertices (M + 1, 3), passed at `times`),
    looked for from the last sample's move on. Ends when the machine reaches the last vertex
    or leaves the moves."""
    moves = np.diff(vertices, axis=0)
    lengths = np.linalg.norm(moves, axis=1)
    k = 0
    sample_times, sample_index = [], []
    for i in range(first, len(samples)):
        window = slice(k, min(k + WALK_WINDOW, len(moves)))
        offsets = samples[i] - vertices[window]
        fraction = np.clip(np.einsum("ij,ij->i", offsets, moves[window])
                           / lengths[window] ** 2, 0.0, 1.0)
        distance = np.linalg.norm(offsets - fraction[:, None] * moves[window], axis=1)
        nearest = int(np.argmin(distance))
        if distance[nearest] * scale > LEFT_MM:
            break
        k += nearest
        sample_times.append(times[k] + fraction[nearest] * (times[k + 1] - times[k]))
        sample_index.append(i)
        if k == len(moves) - 1 and fraction[nearest] >= 1.0:
            break
    return np.array(sample_times), np.array(sample_index)


def _departure(sample_times: np.ndarray, sample_index: np.ndarray, first_end_s: float) -> float:
    """The servo period at which the machine left the curve start: the last sample at the start
    (planned time 0) before the end of the first move. Samples coming in to the start map to
    small times on the first move too; a machine that did not stop there (it ran on from the
    curve before) left where it first passed the start."""
    before_first_end = int(np.argmax(sample_times >= first_end_s))
    at_start = np.flatnonzero(sample_times[:before_first_end] <= REST_TIME_S)
    if at_start.size == 0:
        return _crossing(sample_times, sample_index, REST_TIME_S)
    return float(sample_index[at_start[-1]])


def _crossing(sample_times: np.ndarray, sample_index: np.ndarray, planned_s: float) -> float:
    """The servo period (fractional) at which the machine first reached planned time planned_s."""
    after = int(np.argmax(sample_times >= planned_s))
    if sample_times[after] < planned_s:
        raise MeasurementError("the machine never reached the place planned at "
                               f"{planned_s:.4f} s")
    before = max(after - 1, 0)
    span = sample_times[after] - sample_times[before]
    share = 0.0 if span <= 0.0 else (planned_s - sample_times[before]) / span
    return sample_index[before] + share * (sample_index[after] - sample_index[before])
