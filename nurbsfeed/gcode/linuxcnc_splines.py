"""LinuxCNC G5 (cubic) and G5.1 (quadratic) splines: one block, one Bézier curve.

    G5 X_ Y_ [I_ J_] P_ Q_     cubic: I J = first control point - start,
                                      P Q = second control point - end
    G5.1 X_ Y_ I_ J_           quadratic: I J = control point - start

References: LinuxCNC G-code reference, "G5 Cubic spline" and "G5.1 Quadratic spline"
(docs/src/gcode/g-code.adoc), and the interpreter that runs them, `Interp::convert_spline` in
src/emc/rs274ngc/interp_convert.cc. The messages in quotes below are the interpreter's own.

- A Bézier curve is a clamped B-spline with no interior knot: degree 3 with knots
  [0, 0, 0, 0, 1, 1, 1, 1] (G5), degree 2 with [0, 0, 0, 1, 1, 1] (G5.1), weights 1. The control
  points are the current position, the offset points and the end: exactly the points the
  interpreter hands its NURBS_FEED canonical call, so the curve is the one LinuxCNC traces.
- I J P Q are offsets whatever the distance mode; X Y are the end point (relative to the start
  under G91, an omitted axis stays where it is).
- G5 without I and J leaves in the direction the previous G5 arrived: I J = -P -Q of that G5
  (the interpreter keeps them as `cycle_i`, `cycle_j`). LinuxCNC's reference calls it an error
  in the first G5 of a series (the interpreter would use whatever the last G5, even one far
  back, left); here the previous block that moves must be a G5 ending where this one starts,
  else the block is refused. "Must specify both I and J, or neither"; "Must specify both P and Q
  with G5"; "Must specify both I and J with G5.1".
- XY plane only: "Splines must be in the XY plane". No Z (nor A B C): "Splines may not have
  motion in Z, A, B, or C"; Z holds its current value, known or not, like G5.2's held axis.
- No X and no Y: "All axes missing with motion code". Not under cutter compensation or
  G93/G95 (modal.check_nurbs_allowed); a feed above zero (nurbs_block.feed_steps).
- G5 and G5.1 leave the motion mode as it was (`convert_spline` never sets it): after a G5 that
  follows a G0, a line with axis words only is a rapid for LinuxCNC, but after nurbsfeed's G1
  moves it would be a feed move. The reader refuses such a line (readers/gcode.py).

Each G5 is its own curve: consecutive G5 segments that join tangentially each come to rest at
their joint until chains of curves are planned as one path (design §3b).
"""

from __future__ import annotations

from nurbsfeed.errors import InputError
from nurbsfeed.gcode.modal import AXES, AxisPos, ModalState
from nurbsfeed.gcode.nurbs_block import (
    FinishedCurve,
    build_curve,
    check_block,
    check_coordinates,
    curve_name,
    feed_steps,
    motion_words,
)
from nurbsfeed.gcode.tokenizer import Block, Word, code_name

G5, G5_1 = 50, 51
CUBIC_KNOTS = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]
QUADRATIC_KNOTS = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
SPLINE_WORDS = frozenset("XYIJPQ")  # any of them makes a G5 / G5.1 block a LinuxCNC spline


def is_spline_block(block: Block, code: int) -> bool:
    """True when a G5 / G5.1 block is LinuxCNC's spline: it has spline words (Fanuc's G05 P10000
    and G05.1 Q1 modes have none of X Y I J, and G5.1 with Q is Fanuc's, never LinuxCNC's)."""
    letters = block.letters()
    if code == G5_1 and "Q" in letters:
        return False
    return bool(letters & (SPLINE_WORDS - {"P", "Q"}))


def read_spline(block: Block, state: ModalState, start: Word,
                exit_offset: tuple[float, float] | None) -> tuple[FinishedCurve, tuple[float, float]
                                                                   | None]:
    """The curve of one G5 / G5.1 block and, for a G5, the I J a following G5 without them
    takes (-P, -Q). `exit_offset`: that of the G5 right before, None if the previous move was
    not a G5 ending here. Checks every word before anything is computed; changes no state."""
    cubic = start.code == G5
    label = start.name
    moves = [word for word in motion_words(block) if word is not start]
    if moves:
        raise InputError(f"{moves[0].name} and {label} are both motion codes; one per block",
                         state.where(moves[0]))
    held = next((word for word in block.words if word.letter == "Z"), None)
    if held is not None:
        raise InputError(f"{held.name}: Splines may not have motion in Z, A, B, or C (LinuxCNC): "
                         f"{label} moves X and Y only", state.where(held))
    letters = "NGXYIJPQF" if cubic else "NGXYIJF"
    what = f"a {label} block ({' '.join(letters[2:])})"
    check_block(block, state, letters, {start.code}, what)
    state.check_nurbs_allowed(start)
    if state.plane != 170:
        raise InputError(f"{label} in plane {code_name('G', state.plane)}: Splines must be in "
                         "the XY plane (LinuxCNC); select G17 first", state.where(start))
    ends = {axis: block.first(axis) for axis in ("X", "Y")}
    if ends["X"] is None and ends["Y"] is None:
        raise InputError(f"{label} without X or Y: All axes missing with motion code (LinuxCNC)",
                         state.where(start))
    i_word, j_word = block.first("I"), block.first("J")
    if (i_word is None) != (j_word is None):
        given = i_word or j_word
        assert given is not None, "one of I, J is given"
        rule = "Must specify both I and J, or neither" if cubic else \
            "Must specify both I and J with G5.1"
        raise InputError(f"{given.name} alone: {rule} (LinuxCNC)", state.where(given))
    if i_word is None and not cubic:
        raise InputError("G5.1 without I and J: Must specify both I and J with G5.1 (LinuxCNC): "
                         "I J is the control point relative to the start", state.where(start))
    if i_word is None and exit_offset is None:
        raise InputError("G5 without I and J leaves in the direction the previous G5 arrived, "
                         "but the move before this one is not a G5: write I and J (the first "
                         "control point relative to the start)", state.where(start))
    p_word, q_word = block.first("P"), block.first("Q")
    if cubic and (p_word is None or q_word is None):
        missing = "P" if p_word is None else "Q"
        raise InputError(f"{label} without {missing}: Must specify both P and Q with G5 "
                         "(LinuxCNC): P Q is the second control point relative to the end",
                         state.where(start))
    feed = state.feed
    feed_word = block.first("F")
    if feed_word is not None:
        feed = state.feed_from(feed_word)
    origin = {axis: state.known(axis, start, f"{label} starts at the current position; move "
                                             "there with G0 or G1 first")
              for axis in ("X", "Y")}
    z = state.pos["Z"].value
    z_held = 0.0 if z is None else z  # never written (its moves stay constant), stays unknown
    end = {axis: origin[axis] if word is None
           else (origin[axis] + word.value if state.incremental else word.value)
           for axis, word in ends.items()}
    first = exit_offset if i_word is None or j_word is None else (i_word.value, j_word.value)
    assert first is not None, "a G5 without I J has an exit offset (checked above)"
    points = [(origin["X"], origin["Y"], z_held),
              (origin["X"] + first[0], origin["Y"] + first[1], z_held)]
    if cubic:
        assert p_word is not None and q_word is not None, "checked above"
        points.append((end["X"] + p_word.value, end["Y"] + q_word.value, z_held))
    points.append((end["X"], end["Y"], z_held))
    location = state.where(start)
    check_coordinates(points, [block.line] * len(points), location)
    curve = build_curve(3 if cubic else 2, CUBIC_KNOTS if cubic else QUADRATIC_KNOTS, points,
                        [1.0] * len(points), curve_name(block, start), location)
    feed_u, feed_mm_s = feed_steps(curve, feed, [], state, location)
    after = {axis: AxisPos(end[axis], word.decimals) if word is not None else state.pos[axis]
             for axis, word in ends.items()}
    after["Z"] = state.pos["Z"]
    exit_next = None if p_word is None or q_word is None else (-p_word.value, -q_word.value)
    return (FinishedCurve(curve, location, feed_u, feed_mm_s,
                          {axis: after[axis] for axis in AXES}, feed, state.motion), exit_next)
