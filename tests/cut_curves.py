"""Curves cut at knots into chains, by knot insertion (Boehm), and written as chained programs:
the reference the chain tests compare with the whole curve. Lives only in the tests.

Inserting a knot until its multiplicity is the degree makes the curve pass through one control
point there and splits it into two clamped curves that are the same path exactly (the same
rational curve on each side); the homogeneous control points w P are what the insertion mixes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nurbsfeed.planning.chain import insert_knot


@dataclass(frozen=True)
class Piece:
    degree: int
    knots: np.ndarray  # (n + degree + 2,)
    points: np.ndarray  # (n + 1, 3), Cartesian
    weights: np.ndarray  # (n + 1,)


def cut(degree: int, knots: np.ndarray, points: np.ndarray, weights: np.ndarray,
        cuts: list[float]) -> list[Piece]:
    """The curve cut at the interior parameters `cuts` (ascending) into len(cuts) + 1 pieces."""
    knots = np.asarray(knots, dtype=float)
    pts = np.asarray(points, dtype=float)
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    w = np.asarray(weights, dtype=float)
    pw = np.column_stack([pts * w[:, None], w])
    for u in cuts:
        while np.count_nonzero(knots == u) < degree:
            knots, pw = insert_knot(degree, knots, pw, u)
    pieces = []
    bounds = [float(knots[0])] + list(cuts) + [float(knots[-1])]
    for a, b in zip(bounds[:-1], bounds[1:]):
        inner = knots[(knots > a) & (knots < b)]
        first = int(np.flatnonzero(knots >= a)[0]) if a > knots[0] else 0
        # the piece's control points: from the one at its start (the one the cut passes
        # through) on, as many as its knots ask
        piece_knots = np.concatenate([[a] * (degree + 1), inner, [b] * (degree + 1)])
        n = len(piece_knots) - degree - 1
        start = 0 if a == knots[0] else first - 1
        hw = pw[start:start + n]
        pieces.append(Piece(degree, piece_knots, hw[:, :3] / hw[:, 3:], hw[:, 3].copy()))
    return pieces


def interior_knots(knots: np.ndarray, degree: int) -> np.ndarray:
    inner = np.asarray(knots, dtype=float)[degree + 1:-degree - 1]
    return np.unique(inner)


def cuts_for(knots: np.ndarray, degree: int, n_pieces: int) -> list[float]:
    """n_pieces - 1 interior knots spread evenly over the curve's distinct interior knots; on
    a curve with fewer, parameters spread evenly over its range (a cut by knot insertion is
    exact anywhere)."""
    inner = interior_knots(knots, degree)
    if inner.size < n_pieces - 1:
        return np.linspace(knots[0], knots[-1], n_pieces + 1)[1:-1].tolist()
    pick = np.rint(np.linspace(0, inner.size - 1, n_pieces - 1)).astype(int)
    return [float(u) for u in inner[pick]]


def _num(value: float, decimals: int = 9) -> str:
    text = f"{value:.{decimals}f}".rstrip("0")
    return "0." if text in ("-0.", "0.", "-0") else text


def gcode_chain(pieces: list[Piece], feed: float, dialect: str = "fanuc",
                between: list[list[str]] | None = None, decimals: int = 9) -> str:
    """A program: a G0 to the first piece's start, then the pieces as G06.2 (Fanuc) or G6.2
    (LinuxCNC) blocks one after the other, with the lines between[j] (each without its ending)
    written between piece j and piece j + 1."""
    lines = ["G21 G90 G17 G94", "G0 X{} Y{} Z{}".format(*(_num(c, decimals)
                                                         for c in pieces[0].points[0]))]
    for i, piece in enumerate(pieces):
        if i and between:
            lines.extend(between[i - 1])
        for j, (k, p, w) in enumerate(zip(piece.knots, piece.points, piece.weights)):
            xyz = " ".join(f"{axis}{_num(c, decimals)}" for axis, c in zip("XYZ", p))
            if j == 0:
                head = "G06.2" if dialect == "fanuc" else "G6.2"
                q = " Q1" if dialect == "linuxcnc" else ""
                lines.append(f"{head} P{piece.degree + 1}{q} K{_num(k)} {xyz} R{_num(w)} "
                             f"F{_num(feed)}")
            else:
                lines.append(f"K{_num(k)} {xyz} R{_num(w)}")
        closing = "K" if dialect == "fanuc" else "G6.2 K"
        for k in piece.knots[len(piece.points):]:
            lines.append(f"{closing}{_num(k)}")
    lines.append("M30")
    return "\n".join(lines) + "\n"
