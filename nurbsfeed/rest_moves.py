"""The moves from and into a rest merged for a controller that runs a move near rest slowly
(profile key `rest_move_s`): pipeline.convert_window hands each chunk of stepped points
through `RestMoves` on its way to the writer.
"""

from __future__ import annotations

import math

import numpy as np

from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.interpolate.stepping import PointChunk
from nurbsfeed.machine import FLOOR_MARGIN, Machine

# curve points, evenly spaced in u, on which a longer move at a rest is held to the chord
# tolerance (`RestMoves`): near a rest the arc is a few micrometres long and barely bent, its
# distance from the chord a smooth bump that 64 intervals resolve to a fraction of a nanometre
REST_CHORD_SAMPLES = 65


def rest_move_periods(machine: Machine) -> int:
    """Planned periods in a move from or into a rest: the fewest that last `rest_move_s` (1: a
    move a period, the profile asks for nothing)."""
    move_s = machine.limits.period_s
    return max(1, math.ceil(machine.rest_move_s / move_s * (1.0 - FLOOR_MARGIN)))


class RestMoves:
    """The moves from and into a rest, each made of up to `periods` planned periods, for a
    controller that runs a move near rest slowly (profile key `rest_move_s`).

    LinuxCNC runs a tangent move shorter than its ramp cutoff (1 / ARC_BLEND_RAMP_FREQ: 10 ms)
    at one constant acceleration, from the speed it enters with to the speed it leaves with, the
    smaller of its F and the next (docs/linuxcnc.md). The first move from a rest is
    entered at 0: it takes twice its planned time. A longer move is run as a trapezoid instead,
    at the machine's acceleration up to its F (at a rest F is small: reached at once). So the
    first planned periods after a rest, and the last before one, are written as one move each.

    Every written point stays a planned point and the writer's F stays |dP^| / duration: the
    points inside a merged move are handed on as copies of its start, which round onto the last
    written point, so the writer drops them and gives their periods to the move onto the
    merged move's end: the F words still add up to the planned cycle. A merged move is held to the
    chord tolerance every move meets: the curve between its ends (REST_CHORD_SAMPLES points) is
    within `chord_mm` of its chord, else it spans fewer periods (one period is the plan's own
    move, written as planned). Near a rest it fits with room to spare: from rest the arc after
    t is at most J t^3 / 6 (8.3 um in 10 ms at 50,000 mm/s^3), and an arc of length l bent by
    kappa is kappa l^2 / 8 from its chord (0.9 nm at kappa = 0.1 /mm).

    The last `periods` points given are held until the next ones (or the end) show whether a
    rest follows them: memory stays one chunk and `periods` points.
    """

    def __init__(self, curve: NurbsCurve, chord_mm: float, periods: int) -> None:
        self.curve = curve
        self.chord_mm = chord_mm
        self.periods = periods
        self.stretch: object = None  # the stretch between rests the held points belong to
        self.at_rest = True  # the next move to hand on is the first after a rest
        self.held_u = np.empty(0)
        self.held_points = np.empty((0, 3))
        self.anchor_u = 0.0  # the last point handed on
        self.anchor_point = np.zeros(3)

    def take(self, chunk: PointChunk) -> np.ndarray:
        """The points (K, 3) to hand to the writer now for the chunk's points."""
        if chunk.stretch is None:  # the curve's first point: where its first move starts
            self.anchor_u = float(chunk.u[0])
            self.anchor_point = chunk.points[0]
            return np.empty((0, 3))
        done = []
        if self.stretch is not None and chunk.stretch is not self.stretch:
            done.append(self.finish())  # the held stretch ended at a rest
        self.stretch = chunk.stretch
        u = np.concatenate([self.held_u, chunk.u])
        points = np.concatenate([self.held_points, chunk.points])
        if self.at_rest:
            if len(u) < self.periods:
                self.held_u, self.held_points = u, points
                return np.concatenate(done) if done else np.empty((0, 3))
            first, u, points = self._first_move(u, points)
            done.append(first)
        ready = len(u) - min(len(u), self.periods)
        if ready:
            done.append(points[:ready])
            self.anchor_u, self.anchor_point = float(u[ready - 1]), points[ready - 1]
        self.held_u, self.held_points = u[ready:], points[ready:]
        return np.concatenate(done) if done else np.empty((0, 3))

    def hand_on(self) -> np.ndarray:
        """The held points as they are: the motion runs on into the next window of a chain
        (nurbsfeed.windowed), so no rest follows them, and its first move is not one from a
        rest."""
        points = self.held_points
        if len(points):
            self.anchor_u, self.anchor_point = float(self.held_u[-1]), points[-1]
        self.held_u, self.held_points = np.empty(0), np.empty((0, 3))
        self.stretch = None
        self.at_rest = False
        return points

    def finish(self) -> np.ndarray:
        """The held points, which end at a rest: the last move into it merged."""
        u, points = self.held_u, self.held_points
        done = []
        if self.at_rest and len(u):
            first, u, points = self._first_move(u, points)
            done.append(first)
        if len(u):
            spans = next((n for n in range(len(u), 1, -1)
                          if self._fits(*self._point_before_last(u, points, n), u[-1],
                                        points[-1])), 1)
            last = points.copy()
            last[len(u) - spans:-1] = self._point_before_last(u, points, spans)[1]
            done.append(last)
            self.anchor_u, self.anchor_point = float(u[-1]), points[-1]
        self.held_u, self.held_points = np.empty(0), np.empty((0, 3))
        self.at_rest = True
        return np.concatenate(done) if done else np.empty((0, 3))

    def _first_move(self, u: np.ndarray, points: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The first move after a rest, as points to hand on, and the points after it."""
        spans = next((n for n in range(min(len(u), self.periods), 1, -1)
                      if self._fits(self.anchor_u, self.anchor_point, u[n - 1], points[n - 1])),
                     1)
        first = points[:spans].copy()
        first[:spans - 1] = self.anchor_point
        self.anchor_u, self.anchor_point = float(u[spans - 1]), points[spans - 1]
        self.at_rest = False
        return first, u[spans:], points[spans:]

    def _point_before_last(self, u: np.ndarray, points: np.ndarray, spans: int
                           ) -> tuple[float, np.ndarray]:
        """Where a last move spanning `spans` of the held points starts."""
        if spans == len(u):
            return self.anchor_u, self.anchor_point
        return float(u[-1 - spans]), points[-1 - spans]

    def _fits(self, u_a: float, point_a: np.ndarray, u_b: float, point_b: np.ndarray) -> bool:
        """Whether the curve from u_a to u_b is within the chord tolerance of the chord from
        point_a to point_b."""
        arc = self.curve.point(np.linspace(u_a, u_b, REST_CHORD_SAMPLES))
        chord = point_b - point_a
        length2 = float(chord @ chord)
        along = np.clip((arc - point_a) @ chord / length2, 0.0, 1.0) if length2 else 0.0
        off = arc - point_a - np.multiply.outer(along, chord)
        return bool(np.max(np.sqrt(np.einsum("ij,ij->i", off, off))) <= self.chord_mm)

