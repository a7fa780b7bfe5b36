"""What the NURBS block readers (fanuc, linuxcnc) share: checks on a block's words, the curve they
leave behind, and the programmed feed as a step function of u (design §3a).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from nurbsfeed.errors import CurveError, InputError, Location
from nurbsfeed.gcode.modal import (
    AXES,
    GROUP1_MOVES,
    PROBES,
    SPLINES,
    AxisPos,
    FeedWord,
    ModalState,
    format_value,
)
from nurbsfeed.gcode.tokenizer import Block, Word, param_label
from nurbsfeed.geometry import NurbsCurve
from nurbsfeed.geometry.nurbs import MAX_DEGREE, far_control_point, far_message

MAX_ORDER = MAX_DEGREE + 1  # the highest P / L accepted (docs/refusals.md "Input envelope")


@dataclass(frozen=True)
class FinishedCurve:
    """A complete NURBS block: the curve, its feed steps, and the modal state it leaves."""

    curve: NurbsCurve
    location: Location
    feed_u: np.ndarray  # (k,) u where each programmed feed starts; feed_u[0] == curve.u_min
    feed_mm_s: np.ndarray  # (k,) program units per second, inf where no F is in force
    end: dict[str, AxisPos]  # the tool position after the curve
    feed: FeedWord | None  # the modal F after the curve
    motion: int | None  # the motion mode after the curve (G6.2 is modal, G5.3 ends the mode)


@dataclass(frozen=True)
class FeedChange:
    """An F word inside a NURBS block, taking effect from parameter u on."""

    u: float
    feed: FeedWord
    word: Word


def curve_name(block: Block, start: Word) -> str:
    """"line 12", or "N120 line 12" when the block has a sequence number."""
    number = block.first("N")
    return (f"N{number.text} " if number else "") + f"line {start.line}"


def first_word(block: Block) -> Word:
    """The first word that is not a sequence number (blocks passed here are not inert)."""
    return next(word for word in block.words if word.letter != "N")


def motion_words(block: Block) -> list[Word]:
    """The block's group-1 motion words other than the NURBS codes (G0 G1 G2 G3 G33 ...)."""
    axes = any(word.letter in AXES for word in block.words)
    return [word for word in block.words if word.letter == "G"
            and (word.code in GROUP1_MOVES or word.code in PROBES
                 or (word.code in SPLINES and axes))]


def check_no_assignments(block: Block, state: ModalState) -> None:
    """A NURBS block is replaced by G1 moves, so an assignment inside it would be lost."""
    if block.assignments:
        raise InputError(f"{param_label(block.assignments[0].key)}= inside a NURBS block: the "
                         "block is replaced by G1 moves, so assign parameters before it",
                         Location(state.path, block.line, block.assignments[0].col))


def check_block(block: Block, state: ModalState, allowed_letters: str, allowed_g: Iterable[int],
                what: str) -> None:
    """One message per rule: no assignments, no repeated word, only the allowed words.

    `what` names the block kind in messages ("a G06.2 control-point block (K X Y Z R F)").
    """
    check_no_assignments(block, state)
    seen: set[str] = set()
    codes: set[tuple[str, int]] = set()
    for word in block.words:
        if word.letter in "GM":
            if (word.letter, word.code) in codes:
                raise InputError(f"{word.name} appears twice in one block", state.where(word))
            codes.add((word.letter, word.code))
        elif word.letter in seen:
            raise InputError(f"{word.letter} appears twice in one block", state.where(word))
        seen.add(word.letter)
    allowed_g = set(allowed_g)
    for word in block.words:
        if word.letter not in allowed_letters or (word.letter == "G"
                                                   and word.code not in allowed_g):
            raise InputError(f"{word.name} does not belong in {what}", state.where(word))


def feed_steps(curve: NurbsCurve, initial: FeedWord | None, changes: list[FeedChange],
               state: ModalState, start: Location) -> tuple[np.ndarray, np.ndarray]:
    """The programmed feed as a step function of the curve's u: ((k,) u starts, (k,) program
    units / s).

    The feed in force when the block starts holds from u_min; each change holds from its knot on
    (the input's u, mapped as the curve maps its knots; clamped to u_min; a change at or after
    u_max only sets the modal F after the curve). A feed of zero is an error (LinuxCNC: "Cannot
    make a NURBS with 0 feedrate"; Fanuc alarm PS0011), and so is no F at all at the curve's
    start: a controller starts a program at F0, and the curve must not silently run at the
    machine's maximum (a JSON curve without "feed" does, by design §4).
    """
    u_min, u_max = curve.u_min, curve.u_max
    if initial is not None and initial.per_min == 0.0 and not (changes and changes[0].u <= u_min):
        raise InputError("the feed in force is F0: a NURBS curve needs a feed above zero", start)
    if initial is None and not (changes and changes[0].u <= u_min):
        raise InputError("no feed is in force: program an F (e.g. F600) before or in the NURBS "
                         "block; without one the curve would run at the machine's maximum", start)
    starts = [u_min]
    values = [math.inf if initial is None else initial.per_min / 60.0]
    for change in changes:
        u = max(curve.unit_u(change.u), u_min)
        if u >= u_max:
            continue
        if change.feed.per_min == 0.0:
            raise InputError(f"{change.word.name}: a NURBS curve needs a feed above zero",
                             state.where(change.word))
        if u == starts[-1]:
            values[-1] = change.feed.per_min / 60.0
        elif change.feed.per_min / 60.0 != values[-1]:
            starts.append(u)
            values.append(change.feed.per_min / 60.0)
    return np.array(starts), np.array(values)


def build_curve(degree: int, knots: list[float], points: list[tuple[float, float, float]],
                weights: list[float], name: str, start: Location) -> NurbsCurve:
    """NurbsCurve.build, its CurveError placed at the block start."""
    try:
        return NurbsCurve.build(degree, knots, points, weights, name)
    except CurveError as exc:
        raise exc.at(start) from None


def check_coordinates(points: list[tuple[float, float, float]], lines: list[int],
                      start: Location) -> None:
    """NurbsCurve.build's coordinate check, its CurveError placed on the control point's line
    (lines[i]; point 0, the curve's start, at the block start)."""
    far = far_control_point(np.array(points))
    if far is not None:
        where = start if far == 0 else Location(start.file, lines[far], 1)
        raise CurveError(far_message(far, np.array(points[far])), where)


def count(n: int, noun: str) -> str:
    """ "1 control point is", "3 control points are" """
    return f"{n} {noun} is" if n == 1 else f"{n} {noun}s are"


def point_text(axis: str, value: float) -> str:
    return f"{axis}{format_value(value)}"
