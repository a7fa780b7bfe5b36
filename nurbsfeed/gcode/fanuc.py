"""Fanuc G06.2 NURBS interpolation (also Mitsubishi), and LinuxCNC's G6.2 variant of it.

    G06.2 [P_] K_ X_ Y_ Z_ [R_] [F_]     first control point; P = order ("rank") 2..4, default 4
    K_ X_ Y_ Z_ [R_] [F_]                one block per further control point
    K_                                   then exactly `order` knot-only blocks close the curve

References: FANUC Series 15i/150i-MA Operator's Manual (B-63324EN/03) §4.17 "NURBS
interpolation" and its alarm list PS1002-PS1009; Mitsubishi M700V/M70V Programming Manual §6.15
"NURBS Interpolation" (program errors P29, P32, P33, P551). Each rule below is checked where its
block arrives; the message names the alarm a controller would raise.

- K on every control-point block (PS1002; Mitsubishi P33). Knots never decrease (P551). The first
  `order` knots are equal and so are the last `order` (clamped ends, PS1007); no value repeats more
  than `order` times in a row (PS1008), and an interior value at most `order - 1` times (nurbsfeed
  needs a connected curve; `order` equal interior knots would split it in two).
- The knot count is control points + order by construction: the curve ends after exactly `order`
  knot-only blocks; fewer before another command is PS1004 (PS1005 if the command comes before any
  knot-only block), one more is reported by the reader. Fewer control points than the order is an
  error at the first knot-only block.
- R is the weight, default 1, never modal; it must be positive. Omitted axes hold the previous
  control point's value; on the first block they hold the current position.
- The first control point must be the current position (PS1009; Mitsubishi: "command so that it
  matches the end point of the previous block"), to half a unit in the last decimal of the
  coarser of the two written values, and never closer than the controller's own resolution
  (modal.tolerance). Where the current position is unknown
  (modal.py lists what loses it), a programmed axis is taken as the start and not checked; an
  omitted axis is held where it is, never written, and stays unknown after the curve (a planar
  curve needs no third axis), unless a later control point moves it: that is an error, reported
  once the curve is read so that its lines' own errors (a decreasing knot, a bad weight) come
  first.
- G91: each control point is relative to the previous one, the first relative to the current
  position, so it must be zero travel ("G06.2 X0 Y0 Z0 K_", 15i manual). Knots and weights are
  always absolute.
- Not under G41/G42 or G93/G95 (PS1006). Other commands (M, S, T, G codes other than G06.2)
  cannot be specified inside the curve ("commands other than NURBS interpolation cannot be
  specified"), and parameter assignments are refused because the block is replaced.
- An F word on control point j holds from the span starting at knot j on (design §3a).
- G06.2 is modal (group 01): after the knot-only blocks, a block with K and axis words starts the
  next curve; G0/G1/G2/G3 end the mode.

LinuxCNC's G6.2 (`linuxcnc=True`) follows the same block structure with these differences: a Q
word (interpolation method, no effect on the geometry) on the first block, knot-only lines
written `G6.2 K_` (the G6.2 word may appear on any line of the curve), any order P from 2 to
nurbs_block.MAX_ORDER (LinuxCNC sets no maximum; nurbsfeed's input envelope does), and
incremental G91 control points refused, since their meaning is not documented for LinuxCNC.

A control point beyond the coordinate envelope (geometry.nurbs.MAX_COORDINATE) is reported on
its own line; the other envelope checks of NurbsCurve.build at the first block.
"""

from __future__ import annotations

import math
import re

from nurbsfeed.errors import CurveError, InputError
from nurbsfeed.gcode.modal import AXES, G6_2, AxisPos, ModalState, tolerance
from nurbsfeed.gcode.nurbs_block import (
    MAX_ORDER,
    FeedChange,
    FinishedCurve,
    build_curve,
    check_block,
    check_coordinates,
    check_no_assignments,
    count,
    curve_name,
    feed_steps,
    first_word,
    motion_words,
    point_text,
)
from nurbsfeed.gcode.point_lines import ProgramCodes, scan_point_lines
from nurbsfeed.gcode.tokenizer import PLAIN_NUMBER, Block, Word, decimals_written

DEFAULT_ORDER = 4
FANUC_ORDERS = range(2, 5)  # P2..P4 (15i manual: "The valid data range for P is 2 to 4")
_POINT_LETTERS = frozenset("KXYZRF")
# What CAM posts write for nearly every line of a curve (see NurbsCurveReader.take_line).
_POINT_LINE = re.compile(rf"[Kk]({PLAIN_NUMBER}) [Xx]({PLAIN_NUMBER}) [Yy]({PLAIN_NUMBER}) "
                         rf"[Zz]({PLAIN_NUMBER})(?: [Rr]({PLAIN_NUMBER}))?\r?\n?")
_KNOT_LINE = re.compile(rf"[Kk]({PLAIN_NUMBER})\r?\n?")  # ... and for the closing knots


LINEAR_MODES = frozenset({0, 10})  # G0, G1: a K word means nothing (G2/G3: arc centre)


def stray_knot(block: Block, state: ModalState) -> InputError | None:
    """A G06.2 control-point or knot-only block (K with X Y Z R F only) where no curve is open,
    under G0 or G1 (or no motion): a mistyped or deleted G06.2 (G06.3, G6, G062), whose control
    points would otherwise pass through as straight moves. None for any other block."""
    knot = block.first("K")
    if (knot is None or state.cycle is not None
            or (state.motion is not None and state.motion not in LINEAR_MODES)
            or not block.letters() <= _POINT_LETTERS | {"N"}):
        return None
    typo = state.unknown_g
    if typo is not None:
        return InputError(f"{typo.name} is a G code nurbsfeed does not know, and {knot.name} on "
                          f"line {knot.line} is a knot of a curve nothing opened: write G06.2 "
                          "to open it", state.where(typo))
    return InputError(f"{knot.name}: a NURBS knot with no G06.2 curve open (under "
                      f"{'no motion mode' if state.motion is None else 'G0/G1'} K means "
                      "nothing): write G06.2 on the curve's first block", state.where(knot))


class NurbsCurveReader:
    """One G06.2 / G6.2 curve read block by block; `take` returns True once it is complete."""

    def __init__(self, first: Block, state: ModalState, start: Word, linuxcnc: bool) -> None:
        self.state = state
        self.linuxcnc = linuxcnc
        self.start = start
        self.location = state.where(start)
        self.name = curve_name(first, start)
        self.label = "G6.2" if linuxcnc else "G06.2"
        self.knots: list[float] = []
        # the words of the knots the messages name (a run of point lines keeps no other words)
        self.first_knot: Word | None = None
        self.last_knot: Word | None = None
        self.first_closing_knot: Word | None = None
        self.points: list[tuple[float, float, float]] = []
        self.point_lines: list[int] = []  # the line of each control point, for messages
        self.weights: list[float] = []
        self.decimals: dict[str, int | None] = {}
        # the X, Y, Z texts of the last `take_line`, whose decimals are worked out only when
        # they are wanted (the last point's set the position the curve leaves)
        self.decimal_texts: tuple[str, str, str] | None = None
        self.feed_before = state.feed
        self.feed = state.feed
        self.changes: list[FeedChange] = []
        self.n_closing = 0  # knot-only blocks read so far
        self.order = DEFAULT_ORDER
        # axes omitted on the first block while the position is unknown: held at 0 internally,
        # never written; the word of a later control point that moves one (an error at finish)
        self.unknown: set[str] = set()
        self.unknown_moved: Word | None = None
        self._open(first)

    # ---- the first block -----------------------------------------------------------------------
    def _open(self, block: Block) -> None:
        state = self.state
        state.check_nurbs_allowed(self.start)
        if self.linuxcnc and state.incremental:
            raise InputError("G6.2 under G91 is not supported (LinuxCNC does not document "
                             "incremental G6.2 control points): program the curve in G90",
                             self.location)
        moves = motion_words(block)
        if moves:
            raise InputError(f"{moves[0].name} and {self.label} are both motion codes; one per "
                             "block", state.where(moves[0]))
        letters = "NGPKXYZRF" + ("Q" if self.linuxcnc else "")
        check_block(block, state, letters, {G6_2},
                    f"the first block of a {self.label} curve (P K X Y Z R F"
                    + (" Q" if self.linuxcnc else "") + ")")
        order = block.first("P")
        if order is not None:
            orders = range(2, MAX_ORDER + 1) if self.linuxcnc else FANUC_ORDERS
            valid = order.value == int(order.value) and orders[0] <= order.value <= orders[-1]
            if not valid:
                rule = f"from 2 to {MAX_ORDER}" if self.linuxcnc else "2, 3 or 4"
                raise InputError(f"{order.name}: the order P is a whole number {rule} "
                                 "(degree + 1)", state.where(order))
            self.order = int(order.value)
        if not any(word.letter in AXES for word in block.words):
            typo = state.unknown_g
            if typo is not None:
                raise InputError(f"{typo.name} is a G code nurbsfeed does not know, and the "
                                 f"{self.label} on line {block.line} has no control point: "
                                 f"write {self.label} to open the curve", state.where(typo))
            raise InputError(f"the first block of a {self.label} curve needs its first control "
                             "point (X, Y or Z)", self.location)
        self._control_point(block)

    # ---- every further block -------------------------------------------------------------------
    def take_line(self, line_text: str, line: int) -> bool:
        """`take` for the commonest line of a curve, read straight from its text without words
        and blocks: "K_ X_ Y_ Z_ [R_]", one space apart, before the knot-only blocks. Reads it
        exactly as `take` would read its block (same checks, same errors) and returns True;
        returns False, having read nothing, for any other line or a weight `take` rejects."""
        if self.n_closing or self.unknown:
            return False
        match = _POINT_LINE.fullmatch(line_text)
        if match is None:
            return False
        k_text, x_text, y_text, z_text, r_text = match.groups()
        k, x, y, z = float(k_text), float(x_text), float(y_text), float(z_text)
        weight = 1.0 if r_text is None else float(r_text)
        if not (math.isfinite(k + x + y + z + weight) and weight > 0.0):
            return False
        knot = Word("K", k, k_text, decimals_written(k_text), line, 1)
        if k > self.knots[-1] and len(self.knots) >= self.order:
            self.knots.append(k)  # past the clamped start and increasing: _knot has no check
            self.last_knot = knot
        else:
            self._knot(knot, closing=False)
        if self.state.incremental:
            previous = self.points[-1]
            x, y, z = previous[0] + x, previous[1] + y, previous[2] + z
        self.decimal_texts = (x_text, y_text, z_text)
        self.points.append((x, y, z))
        self.point_lines.append(line)
        self.weights.append(weight)
        return True

    def take_knot_line(self, line_text: str, line: int) -> bool | None:
        """`take` for a knot-only line "K_" (the closing knots), read straight from its text:
        the same checks and errors, and what `take` returns (True once the curve is complete);
        None, having read nothing, for any other line."""
        match = _KNOT_LINE.fullmatch(line_text)
        if match is None:
            return None
        text = match.group(1)
        return self._closing_knot(Word("K", float(text), text, decimals_written(text), line, 1))

    @property
    def takes_runs(self) -> bool:
        """Whether `take_run` can read a line now: past the clamped start, before the closing
        knots, no unknown axis."""
        return not (self.n_closing or self.unknown or len(self.knots) < self.order)

    def take_run(self, program: ProgramCodes, pos: int, line: int) -> tuple[int, int]:
        """`take_line` for the run of lines from text position `pos` (line number `line`) on,
        scanned at once in compiled code (point_lines.py). Reads the lines `take_line` would
        read without a check of `_knot`: past the clamped start, knots increasing, weights
        positive; the first line the scan refuses is left to `take_line` or `take`.
        Returns (lines read, text position after them); (0, pos) when it read none."""
        if not self.takes_runs:
            return 0, pos
        n, last_start, end = scan_point_lines(program.codes, pos, self.knots[-1], program.values)
        if not n:
            return 0, pos
        knots, xs, ys, zs, weights = program.values[:n].T.tolist()
        self.knots.extend(knots)
        if self.state.incremental:  # take_line's additions, in its order
            x, y, z = self.points[-1]
            for dx, dy, dz in zip(xs, ys, zs):
                x, y, z = x + dx, y + dy, z + dz
                self.points.append((x, y, z))
        else:
            self.points.extend(zip(xs, ys, zs))
        self.point_lines.extend(range(line, line + n))
        self.weights.extend(weights)
        match = _POINT_LINE.fullmatch(program.text, last_start, end)
        assert match is not None, "scan_point_lines reads only _POINT_LINE lines"
        k_text, x_text, y_text, z_text, _ = match.groups()
        self.last_knot = Word("K", self.knots[-1], k_text, decimals_written(k_text),
                              line + n - 1, 1)
        self.decimal_texts = (x_text, y_text, z_text)
        return n, end

    def take(self, block: Block) -> bool:
        """Read the next block of the curve; True when it was the last knot-only block."""
        words = block.words
        if not self.n_closing and not block.assignments and words:
            # The bulk of a curve: control-point blocks of K, X, Y, Z, R, F words, each at most
            # once, and the knot-only blocks. Every check below passes for them.
            letters = {word.letter for word in words}
            if len(letters) == len(words) and letters <= _POINT_LETTERS and "K" in letters:
                if not letters.isdisjoint(AXES):
                    self._control_point(block)
                    return False
                if len(words) == 1:
                    return self._closing_knot(words[0])
        if block.is_inert:
            return False
        state = self.state
        check_no_assignments(block, state)
        moves = motion_words(block)
        if moves or (G6_2 in block.codes("G") and not self.linuxcnc):
            word = moves[0] if moves else block.codes("G")[G6_2]
            raise InputError(self._ended_early(word), state.where(word))
        axes = [word for word in block.words if word.letter in AXES]
        knot = block.first("K")
        if self.n_closing and knot is None:
            word = first_word(block)
            raise InputError(self._ended_early(word), state.where(word))
        if self.n_closing and axes:
            raise InputError(f"control point after the knot-only blocks: all control points of a "
                             f"curve come before its {self.order} closing K blocks",
                             state.where(axes[0]))
        if knot is not None and not axes:
            check_block(block, state, "NK" + ("G" if self.linuxcnc else ""),
                        {G6_2} if self.linuxcnc else set(),
                        f"a knot-only block of a {self.label} curve (K)")
            return self._closing_knot(knot)
        check_block(block, state, "NKXYZRF" + ("G" if self.linuxcnc else ""), {G6_2},
                    f"a {self.label} control-point block (K X Y Z R F)")
        self._control_point(block)
        return False

    def _ended_early(self, word: Word) -> str:
        does = "starts a new curve" if word.letter == "G" and word.code == G6_2 else \
            "ends the NURBS mode"
        if self.n_closing:
            return (f"{word.name} comes after only {self.n_closing} of the {self.order} knot-only "
                    f"blocks that close a {self.label} curve of order {self.order} (Fanuc alarm "
                    "PS1004)")
        return (f"{word.name} {does} before the curve's {self.order} knot-only K blocks (Fanuc "
                "alarm PS1005)")

    # ---- control points and knots ----------------------------------------------------------------
    def _flush_decimal_texts(self) -> None:
        if self.decimal_texts is not None:
            for axis, text in zip(AXES, self.decimal_texts):
                self.decimals[axis] = decimals_written(text)
            self.decimal_texts = None

    def _control_point(self, block: Block) -> None:
        state = self.state
        self._flush_decimal_texts()
        first: dict[str, Word] = {}
        for word in reversed(block.words):
            first[word.letter] = word
        knot = first.get("K")
        if knot is None:
            word = next((word for word in block.words if word.letter in AXES + ("R", "F")),
                        first_word(block))
            raise InputError(f"control point without a knot: every control-point block of a "
                             f"{self.label} curve carries K (Fanuc alarm PS1002)",
                             state.where(word))
        self._knot(knot, closing=False)
        weight = first.get("R")
        if weight is not None and weight.value <= 0:
            raise CurveError(f"{weight.name}: a weight R must be positive", state.where(weight))
        x = self._coordinate("X", first.get("X"))
        y = self._coordinate("Y", first.get("Y"))
        z = self._coordinate("Z", first.get("Z"))
        feed = first.get("F")
        if feed is not None:
            self.feed = state.apply_feed(feed)
            self.changes.append(FeedChange(knot.value, self.feed, feed))
        self.points.append((x, y, z))
        self.point_lines.append(block.line)
        self.weights.append(1.0 if weight is None else weight.value)

    def _coordinate(self, axis: str, word: Word | None) -> float:
        """This control point's coordinate on `axis` (checked against the start on the first)."""
        state = self.state
        if self.points:
            previous = self.points[-1][AXES.index(axis)]
            if word is None:
                return previous
            if axis in self.unknown and self.unknown_moved is None:
                self.unknown_moved = word
            self.decimals[axis] = word.decimals
            return previous + word.value if state.incremental else word.value
        current = state.pos[axis]
        if word is None:
            self.decimals[axis] = current.decimals
            if current.value is None:  # fine while no control point moves it (finish)
                self.unknown.add(axis)
                return 0.0
            return current.value
        value = word.value
        if state.incremental:
            value += state.known(axis, word, "a G91 first control point is relative to it")
        self.decimals[axis] = word.decimals
        if current.value is not None:
            tol = tolerance(state.units, current.decimals, word.decimals)
            if abs(value - current.value) > tol:
                raise InputError(f"first control point {point_text(axis, value)} is not the "
                                 f"current position {point_text(axis, current.value)} (tolerance "
                                 f"{tol:g}): a {self.label} curve starts where the tool is "
                                 "(Fanuc alarm PS1009)", state.where(word))
        return value

    def _knot(self, word: Word, closing: bool) -> None:
        """Append a knot, checking order, clamped start and repetition as it arrives."""
        state = self.state
        value = word.value
        before = self.last_knot
        if before is not None and value < before.value:
            raise CurveError(f"{word.name}: knots must not decrease ({before.name} on line "
                             f"{before.line} before it) (Mitsubishi error P551)",
                             state.where(word))
        run = 1
        while run <= len(self.knots) and self.knots[-run] == value:
            run += 1
        if run > self.order:
            raise CurveError(f"{word.name}: knot {value:g} repeated {run} times in a row; at most "
                             f"the order {self.order} (Fanuc alarm PS1008)", state.where(word))
        first = self.first_knot
        if (not closing and first is not None and len(self.knots) < self.order
                and value != first.value):
            raise CurveError(f"{word.name}: the first {self.order} knots must be equal (clamped "
                             f"start, order {self.order}); {first.name} on line {first.line} "
                             "starts the curve (Fanuc alarm PS1007)", state.where(word))
        if not closing and run == self.order and value != self.knots[0]:
            raise CurveError(f"{word.name}: interior knot {value:g} repeated {run} times (the "
                             f"order) would split the curve in two; at most {self.order - 1}",
                             state.where(word))
        self.knots.append(value)
        self.last_knot = word
        if self.first_knot is None:
            self.first_knot = word

    def _closing_knot(self, word: Word) -> bool:
        state = self.state
        if not self.n_closing and len(self.points) < self.order:
            raise CurveError(f"{count(len(self.points), 'control point')} fewer than the "
                             f"order {self.order}: a curve of order {self.order} needs at least "
                             f"{self.order}", state.where(word))
        first = self.first_closing_knot
        if first is not None and word.value > self.knots[-1]:
            raise CurveError(f"{word.name}: the last {self.order} knots must be equal (clamped "
                             f"end, order {self.order}); {first.name} on line {first.line} is the "
                             "first of them (Fanuc alarm PS1007)", state.where(word))
        self._knot(word, closing=True)
        if self.first_closing_knot is None:
            self.first_closing_knot = word
        self.n_closing += 1
        return self.n_closing == self.order

    # ---- the result ------------------------------------------------------------------------------
    def unfinished(self) -> InputError:
        """The error for a file that ends inside this curve."""
        if self.n_closing:
            detail = f"it has only {self.n_closing} of its {self.order} knot-only blocks"
        else:
            detail = f"its {self.order} knot-only K blocks never come"
        return InputError(f"the file ends inside the {self.label} curve started here: {detail}",
                          self.location)

    def finish(self) -> FinishedCurve:
        if self.unknown_moved is not None:
            axis = self.unknown_moved.letter
            self.state.known(axis, self.start, f"program {axis} in the curve's first block "
                                               "(omitted axes keep the current position)")
        self._flush_decimal_texts()
        check_coordinates(self.points, self.point_lines, self.location)
        curve = build_curve(self.order - 1, self.knots, self.points, self.weights, self.name,
                            self.location)
        feed_u, feed_mm_s = feed_steps(curve, self.feed_before, self.changes, self.state,
                                       self.location)
        end = {axis: AxisPos(self.points[-1][i], self.decimals.get(axis))
               for i, axis in enumerate(AXES)}
        for axis in self.unknown:  # never moved, never written: still unknown
            end[axis] = self.state.pos[axis]
        return FinishedCurve(curve, self.location, feed_u, feed_mm_s, end, self.feed, G6_2)
