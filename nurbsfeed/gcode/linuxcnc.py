"""LinuxCNC G5.2/G5.3 NURBS blocks.

    G5.2 [X_ Y_] [P_] [L_]    opens the block (P without X Y: weight of the start point)
    X_ Y_ P_                  one line per control point, P = weight
    G5.3                      closes the block and runs the curve

References: LinuxCNC G-code reference, "G5.2 G5.3 NURBS Block" (docs/src/gcode/g-code.adoc), and
the interpreter that runs it, `Interp::convert_nurbs` in src/emc/rs274ngc/interp_convert.cc, the
knot vector in `knot_vector_creator` (nurbs_additional_functions.cc). Where the two disagree
this reader follows the interpreter, since that is what a machine does:

- The current position is always the first control point, weight 1 unless the G5.2 line has a P
  without X and Y ("Can specify P without X and Y only for the first control point").
- Every further control point needs both axes of the plane and a positive weight P ("You must
  specify both X and Y coordinates for Control Points", "Must specify positive weight P for every
  Control Point"; the docs' "default weight 1" is not what the interpreter does).
- The order is 3 unless an L above 3 is given (smaller L is ignored by the interpreter; here it is
  an error, since it cannot mean what was written); the last L in the block wins. LinuxCNC sets
  no maximum; nurbsfeed refuses an L above nurbs_block.MAX_ORDER (docs/refusals.md, "Input
  envelope").
- Knots are uniform, clamped, integer: with n + 1 control points of order k,
  `order zeros, 1 .. n-k+1, order copies of n-k+2` (knot_vector_creator).
- G5.3 without G5.2 is an error; so are fewer control points (counting the start point) than the
  order ("You must specify a number of control points at least equal to the order L = %d").
- The plane is G17 (X Y), G18 (Z X) or G19 (Y Z), as extended in LinuxCNC pull request #2229; the
  third axis holds its current value, and a word for it is an error. The held axis may be unknown
  (the reference's own example never sets Z): it is never written and stays unknown after the
  block. The two plane axes must be known (the curve starts there), reported at G5.3.
- Under G91 each control point is relative to the position *before the block*: the interpreter's
  `find_ends` adds the current position, which it updates only at G5.3.
- The feed is the F in force at G5.3 (an F on any line of the block sets it). G5.3 ends the
  motion mode. Cutter compensation and G93/G95 are refused as for Fanuc (modal.check_nurbs_allowed).
"""

from __future__ import annotations

from nurbsfeed.errors import CurveError, InputError
from nurbsfeed.gcode.modal import AXES, G5_2, G5_3, PLANES, AxisPos, ModalState
from nurbsfeed.gcode.nurbs_block import (
    MAX_ORDER,
    FinishedCurve,
    build_curve,
    check_block,
    check_coordinates,
    check_no_assignments,
    count,
    curve_name,
    feed_steps,
    motion_words,
)
from nurbsfeed.gcode.tokenizer import Block, Word, code_name

DEFAULT_ORDER = 3


def uniform_knots(n_points: int, order: int) -> list[float]:
    """LinuxCNC's knot vector for n_points control points of `order` (n = n_points - 1)."""
    n = n_points - 1
    return [0.0] * order + [float(i) for i in range(1, n - order + 2)] + \
        [float(n - order + 2)] * order


class G52BlockReader:
    """One G5.2 ... G5.3 block read line by line; `take` returns True at its G5.3."""

    def __init__(self, first: Block, state: ModalState, start: Word) -> None:
        self.state = state
        self.start = start
        self.location = state.where(start)
        self.name = curve_name(first, start)
        moves = motion_words(first)
        if moves:
            raise InputError(f"{moves[0].name} and G5.2 are both motion codes; one per block",
                             state.where(moves[0]))
        state.check_nurbs_allowed(start)
        if state.plane not in PLANES:
            raise InputError(f"G5.2 needs plane G17, G18 or G19, not "
                             f"{code_name('G', state.plane)}", self.location)
        self.plane_axes = PLANES[state.plane]
        self.held = next(axis for axis in AXES if axis not in self.plane_axes)
        # The held axis is never written (its moves stay constant, MoveWriter writes changed
        # axes only), so an unknown one is held at 0 internally and stays unknown after the
        # block. An unknown plane axis is reported at G5.3, once every line's own checks ran.
        self.origin: dict[str, float] = {
            axis: 0.0 if (value := state.pos[axis].value) is None else value for axis in AXES}
        self.unknown_start = next((axis for axis in self.plane_axes
                                   if state.pos[axis].value is None), None)
        self.points: list[tuple[float, float, float]] = [
            (self.origin["X"], self.origin["Y"], self.origin["Z"])]
        self.point_lines = [start.line]  # the line of each control point, for messages
        self.weights = [1.0]
        self.decimals = {axis: state.pos[axis].decimals for axis in AXES}
        self.order = DEFAULT_ORDER
        self._line(first, opening=True)

    def take(self, block: Block) -> bool:
        """Read the next line of the block; True when it was the closing G5.3."""
        if block.is_inert:
            return False
        check_no_assignments(block, self.state)
        closing = block.codes("G").get(G5_3)
        if closing is None:
            self._line(block, opening=False)
            return False
        check_block(block, self.state, "NGF", {G5_3}, "the G5.3 line (F)")
        feed = block.first("F")
        if feed is not None:
            self.state.apply_feed(feed)
        if self.unknown_start is not None:
            self.state.known(self.unknown_start, self.start, "G5.2 starts the curve at the "
                                                             "current position; move there with "
                                                             "G0 or G1 first")
        if len(self.points) < self.order:
            raise CurveError(f"{count(len(self.points), 'control point')} fewer than the order "
                             f"L{self.order}, counting the start point: LinuxCNC needs at least "
                             f"{self.order}", self.state.where(closing))
        return True

    def _line(self, block: Block, opening: bool) -> None:
        state = self.state
        first, second = self.plane_axes
        held = block.first(self.held)
        if held is not None:
            raise InputError(f"{held.name} does not belong in a G5.2 block in the "
                             f"{first}{second} plane: the curve moves {first} and {second}, "
                             f"{self.held} holds", state.where(held))
        check_block(block, state, "NGXYZPLF", {G5_2},
                    f"a G5.2 block ({first} {second} P L F)")
        words = [block.first(first), block.first(second)]
        given = [word for word in words if word is not None]
        if len(given) == 1:
            missing = second if words[0] is not None else first
            raise InputError(f"a G5.2 control point needs both {first} and {second}; {missing} is "
                             "missing", state.where(given[0]))
        weight = block.first("P")
        if weight is not None and weight.value <= 0:
            raise CurveError(f"{weight.name}: a weight P must be positive", state.where(weight))
        order = block.first("L")
        if order is not None:
            if order.value != int(order.value) or order.value < DEFAULT_ORDER:
                raise InputError(f"{order.name}: the order L of a G5.2 block is a whole number 3 "
                                 "or more (LinuxCNC ignores smaller L and uses 3)",
                                 state.where(order))
            if order.value > MAX_ORDER:
                raise InputError(f"{order.name}: the order L is at most {MAX_ORDER} (degree "
                                 f"{MAX_ORDER - 1}, the highest nurbsfeed evaluates accurately)",
                                 state.where(order))
            self.order = int(order.value)
        feed = block.first("F")
        if feed is not None:
            state.apply_feed(feed)
        if given:
            if weight is None:
                raise CurveError("control point without a weight: LinuxCNC needs a positive P on "
                                 "every G5.2 control point", state.where(given[0]))
            self._point(dict(zip(self.plane_axes, given, strict=True)), weight.value)
        elif weight is not None:
            if not opening:
                raise InputError(f"{weight.name} without {first} and {second}: only the G5.2 line "
                                 "may set the weight of the start point", state.where(weight))
            self.weights[0] = weight.value

    def _point(self, words: dict[str, Word], weight: float) -> None:
        values = []
        for axis in AXES:
            word = words.get(axis)
            if word is None:
                values.append(self.origin[axis])
                continue
            self.decimals[axis] = word.decimals
            values.append(self.origin[axis] + word.value if self.state.incremental
                          else word.value)
        self.points.append((values[0], values[1], values[2]))
        self.point_lines.append(next(iter(words.values())).line)
        self.weights.append(weight)

    def unfinished(self) -> InputError:
        return InputError("the file ends inside the G5.2 NURBS block started here (no G5.3)",
                          self.location)

    def finish(self) -> FinishedCurve:
        knots = uniform_knots(len(self.points), self.order)
        check_coordinates(self.points, self.point_lines, self.location)
        curve = build_curve(self.order - 1, knots, self.points, self.weights, self.name,
                            self.location)
        feed = self.state.feed
        feed_u, feed_mm_s = feed_steps(curve, feed, [], self.state, self.location)
        end = {axis: AxisPos(self.points[-1][i], self.decimals[axis])
               for i, axis in enumerate(AXES)}
        end[self.held] = self.state.pos[self.held]  # held, known or not
        return FinishedCurve(curve, self.location, feed_u, feed_mm_s, end, feed, None)

