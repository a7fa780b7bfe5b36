"""The modal state a G-code program builds up outside NURBS blocks.

Units (G20/G21), distance mode (G90/G91), plane (G17/G18/G19), cutter compensation (G40-G42),
feed mode (G93/G94/G95), the modal F word, the motion mode and the current position. Lengths are
in program units (mm under G21, inch under G20); feeds `_per_min` are program units per minute,
as F words are written.

The current position is tracked per axis (X, Y, Z) and can be *unknown*: the tool moved somewhere
the program text does not say. A NURBS curve needs the current position (Fanuc checks its first
control point against it, LinuxCNC G5.2 starts from it), so an unknown axis is an error there, not
here; the message says what made it unknown. The position becomes unknown for:

- G28/G30 (reference point return: named axes, all if none), G53 (machine coordinates: named
  axes), G31/G38.x (probing/skip: named axes), G27/G29 (reference check/return: named axes);
- a change of coordinate system or of the program frame: G10, G52, G54-G59.x, G54.1, G92.1-G92.3,
  G68/G69 rotation, G50/G51 scaling, G50.1/G51.1 mirror, G43.4/G43.5 TCP (all axes; a move in
  the same block, as in "G0 G54 X0. Y0.", then sets its axes in the new frame);
- tool length compensation G43/G43.1/G43.2/G44/G49 (Z, unless the same block moves Z);
- M6 tool change (many machines move to a change position), M98/M99/G65/G66 sub-program and
  macro calls (all axes);
- canned cycles G73-G89 (Z: it ends at the R plane or the initial level), axis words with no
  motion mode in effect, and axis words with a G code this reader does not know (named axes).

G92 X.. sets the named axes; the X of a Fanuc dwell "G04 X1.5" is a time, not a position. A
G20/G21 switch converts the known position to the new unit. A block delete line (`/`) is
treated as executed (switch off): its modal effects apply, and a NURBS block containing one is
replaced as a whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from nurbsfeed.errors import InputError, Location
from nurbsfeed.gcode.tokenizer import Block, Word, code_name
from nurbsfeed.gcode.writer import format_number
from nurbsfeed.program import MM_PER_INCH

AXES = ("X", "Y", "Z")
VALUE_DECIMALS = 6  # finer than any control's input increment
INPUT_INCREMENT = {"mm": 0.001, "in": 0.0001}  # IS-B least input increment

# G and M codes in tenths (tokenizer.Word.code).
G5_2, G5_3, G6_2 = 52, 53, 62
GROUP1_MOVES = {0, 10, 20, 30, 330}  # G0 G1 G2 G3 G33: axis words are the end point
SPLINES = {50, 51}  # LinuxCNC G5/G5.1 splines with axis words; Fanuc G05/G05.1 modes without
PROBES = {382, 383, 384, 385}  # G38.2-G38.5 (LinuxCNC, group 1)
CYCLES = {730, 740, 760} | set(range(810, 900, 10))  # G73 G74 G76 G81-G89
G80 = 800
PLANES = {170: ("X", "Y"), 180: ("Z", "X"), 190: ("Y", "Z")}  # G17 G18 G19
OTHER_PLANES = {171, 181, 191}  # G17.1 G18.1 G19.1 (UV, WU, VW)
CUTTER_COMP_ON = {410, 420, 411, 421}
FEED_MODES = {930: "inverse time", 940: "per minute", 950: "per revolution"}
REFERENCE_RETURN = {280, 300}  # G28 G30
NAMED_AXES_LOST = {530, 310, 270, 290, 1530}  # G53 G31 G27 G29, Sinumerik G153
TOOL_LENGTH = {430, 431, 432, 440, 490}
# All axes lost, then the block's own axis words move in the new frame ("G0 G54 X0. Y0.").
FRAME_SELECT = {540, 550, 560, 570, 580, 590, 591, 592, 593, 541, 921, 922, 923, 690, 500,
                501, 434, 435}  # G54-G59.3 G54.1 G92.1-G92.3 G69 G50 G50.1 G43.4 G43.5
# Sinumerik: G500 and the settable frames G505-G599 change the frame too
FRAME_SELECT |= {5000} | set(range(5050, 6000, 10))
M_FRAME_SELECT = {60, 980, 990}  # M6 M98 M99
# All axes lost; the block's axis words are arguments, not a move (G10 L2 P1 X0, G68 X0 Y0 R45).
FRAME_ARGUMENTS = {100, 520, 680, 682, 510, 511, 650, 660, 661}
NOT_SUPPORTED = {
    160: "G16 (polar coordinate command) is not supported: X and Y would be radius and angle",
    121: "G12.1 (polar coordinate interpolation) is not supported",
    71: "G7.1 (cylindrical interpolation) is not supported",
}
DWELL = 40  # G4: its X or P word is the dwell time, not a position
NO_POSITION_EFFECT = ({70, 80, 90, 150, 131, 200, 210, 400, 610, 611, 640, 670, 800, 900, 910,
                       901, 911, 960, 970, 980, 990}
                      | {600, 6010, 6020, 6030, 6410, 6420, 6430, 6440, 6450}  # Sinumerik G60x G64x
                      | set(PLANES) | OTHER_PLANES | CUTTER_COMP_ON | set(FEED_MODES))
KNOWN_G = (GROUP1_MOVES | SPLINES | PROBES | CYCLES | REFERENCE_RETURN | NAMED_AXES_LOST
           | TOOL_LENGTH | FRAME_SELECT | FRAME_ARGUMENTS | NO_POSITION_EFFECT | {920, DWELL})


@dataclass(frozen=True)
class AxisPos:
    """One axis of the current position. value None: unknown, and `lost` says why.

    decimals: fractional digits of the word that set it (None: no precision information).
    """

    value: float | None
    decimals: int | None = None
    lost: str = "no move has set it since the start of the program"


@dataclass(frozen=True)
class FeedWord:
    """The modal F: its value (program units per minute) and how to write it back."""

    per_min: float
    word: str  # "F1200." as written; a parameter F#1 is written as its value


@dataclass(frozen=True)
class Mode:
    """A modal setting that blocks NURBS, with the line that set it."""

    name: str
    line: int


def coarser_decimals(*decimals: int | None) -> int | None:
    """The fewest fractional digits among those known (None if none is known)."""
    known = [d for d in decimals if d is not None]
    return min(known) if known else None


def tolerance(units: str, *decimals: int | None) -> float:
    """When two written coordinates are the same point: the larger of

    - half a unit in the last decimal of the coarser written value (0.5 if neither has any).
      Posts trim trailing zeros ("X10." for 10.000), so a value without fractional digits
      carries no precision information; two values written to different precisions (a G0 to 3
      decimals, a control point to 4) are the same point when they agree to the coarser one;
    - half the least input increment of the usual IS-B setting (0.001 mm, 0.0001 inch), the
      resolution at which the controller itself compares them.
    """
    digits = coarser_decimals(*decimals)
    return max(0.5 * 10.0 ** -(digits or 0), 0.5 * INPUT_INCREMENT[units])


def format_value(value: float) -> str:
    """A number read from the program, written back (an F word written without a point, a
    value in a message) the way nurbsfeed writes numbers, to VALUE_DECIMALS: 1200 -> "1200.",
    -0.5 -> "-0.5"."""
    return format_number(value, VALUE_DECIMALS)


@dataclass
class ModalState:
    """Mutable while a program is read; `apply` executes one block outside NURBS blocks."""

    path: str
    units: str = "mm"
    incremental: bool = False
    plane: int = 170
    cutter_comp: Mode | None = None
    feed_mode: Mode | None = None  # None: G94, feed per minute
    feed: FeedWord | None = None
    motion: int | None = None  # group 1 code (0, 10, 20, 30, 330, 50, 51, 382.., 62)
    cycle: int | None = None  # canned cycle code while one is active
    pos: dict[str, AxisPos] = field(default_factory=lambda: {axis: AxisPos(None)
                                                               for axis in AXES})
    # the last G code this reader does not know, until a motion code follows it: a G5.3 with no
    # G5.2 before it blames it as a likely typo (G2.2 for G5.2), at its own line
    unknown_g: Word | None = None

    def where(self, word: Word) -> Location:
        return Location(self.path, word.line, word.col)

    # ---- checks shared by the NURBS readers ----------------------------------------------------
    def check_nurbs_allowed(self, word: Word) -> None:
        """NURBS blocks need cutter compensation off and feed per minute (Fanuc PS1006)."""
        if self.cutter_comp is not None:
            raise InputError(f"{word.name} cannot run under cutter compensation "
                             f"{self.cutter_comp.name} (since line {self.cutter_comp.line}): "
                             "cancel it with G40 first (Fanuc alarm PS1006)", self.where(word))
        if self.feed_mode is not None:
            raise InputError(f"{word.name} needs feed per minute G94, but {self.feed_mode.name} "
                             f"is in effect since line {self.feed_mode.line} (Fanuc alarm "
                             "PS1006)", self.where(word))

    def known(self, axis: str, word: Word, purpose: str) -> float:
        """The current position on `axis`, or an error at `word` saying why it is unknown."""
        current = self.pos[axis]
        if current.value is None:
            raise InputError(f"{axis} is unknown here ({current.lost}): {purpose}",
                             self.where(word))
        return current.value

    # ---- executing a block -------------------------------------------------------------------
    def apply_feed(self, word: Word) -> FeedWord:
        """A new modal F; F must not be negative (F0 is legal on rapid-only programs)."""
        self.feed = self.feed_from(word)
        return self.feed

    def feed_from(self, word: Word) -> FeedWord:
        """The modal F an F word sets, checked, without setting it."""
        if word.value < 0:
            raise InputError(f"{word.name}: a feed must not be negative", self.where(word))
        # restored after our moves, so written our way: with a decimal point (F60 -> F60.),
        # a parameter as its value; a value already written with a point is kept as written
        plain = "." in word.text and "#" not in word.text
        text = word.name if plain else "F" + format_value(word.value)
        return FeedWord(word.value, text)

    def apply(self, block: Block) -> None:
        """Execute one block that is not part of a NURBS block (parse -> check -> execute)."""
        g = block.codes("G")
        m = block.codes("M")
        axes = {word.letter: word for word in block.words if word.letter in AXES}
        for code, word in g.items():
            if code in NOT_SUPPORTED:
                raise InputError(NOT_SUPPORTED[code], self.where(word))
        motions = [word for code, word in g.items()
                   if code in GROUP1_MOVES | PROBES or (code in SPLINES and axes)]
        if len(motions) > 1:
            raise InputError(f"{motions[0].name} and {motions[1].name} are both motion codes; "
                             "one per block", self.where(motions[1]))
        units = [word for code, word in g.items() if code in (200, 210)]
        if len(units) > 1:
            raise InputError("G20 and G21 in one block", self.where(units[1]))
        feed = block.first("F")
        if feed is not None:
            self.apply_feed(feed)
        if units:
            self._set_units("in" if units[0].code == 200 else "mm")
        if 900 in g:
            self.incremental = False
        if 910 in g:
            self.incremental = True
        for code in g:
            if code in PLANES or code in OTHER_PLANES:
                self.plane = code
            elif code == 400:
                self.cutter_comp = None
            elif code in CUTTER_COMP_ON:
                self.cutter_comp = Mode(code_name("G", code), block.line)
            elif code == 940:
                self.feed_mode = None
            elif code in FEED_MODES:
                self.feed_mode = Mode(f"{code_name('G', code)} feed {FEED_MODES[code]}",
                                      block.line)
            elif code in CYCLES:
                self.cycle = code
            elif code == G80:
                self.cycle = None
        if motions:
            self.motion = motions[0].code
            self.cycle = None
            self.unknown_g = None
        unknown = [word for code, word in g.items() if code not in KNOWN_G]
        if unknown:
            self.unknown_g = unknown[-1]
        self._move(block, g, m, axes)

    def apply_plain_move(self, motion: int | None,
                         axes: list[tuple[str, float, int | None]], feed: Word | None) -> None:
        """`apply` for a block of only a G0 or G1 (motion 0 or 10; None: none), X, Y, Z words
        (axis, value, decimals written) and an F of at least zero, each at most once, under G0
        or G1 and no canned cycle where it has no G word (gcode.plain_moves): what `apply`
        does to such a block, `_goto` included."""
        if feed is not None:
            self.apply_feed(feed)
        if motion is not None:
            self.motion = motion
            self.cycle = None
            self.unknown_g = None
        for axis, value, decimals in axes:
            if not self.incremental:
                self.pos[axis] = AxisPos(value, decimals)
                continue
            current = self.pos[axis]
            if current.value is not None:
                self.pos[axis] = AxisPos(current.value + value,
                                         coarser_decimals(current.decimals, decimals))

    def _set_units(self, units: str) -> None:
        if units == self.units:
            return
        factor = 1.0 / MM_PER_INCH if units == "in" else MM_PER_INCH
        for axis, current in self.pos.items():
            if current.value is not None:
                self.pos[axis] = AxisPos(current.value * factor, None)
        self.units = units

    def _lose(self, axes: list[str] | tuple[str, ...], reason: str) -> None:
        for axis in axes:
            self.pos[axis] = AxisPos(None, None, reason)

    def _move(self, block: Block, g: dict[int, Word], m: dict[int, Word],
              axes: dict[str, Word]) -> None:
        line = block.line
        frame = [code_name("G", code) for code in g if code in FRAME_SELECT | FRAME_ARGUMENTS] \
            + [code_name("M", code) for code in m if code in M_FRAME_SELECT]
        if frame:
            self._lose(AXES, f"after {frame[0]} on line {line}")
        if g.keys() & TOOL_LENGTH:
            code = min(g.keys() & TOOL_LENGTH)
            self._lose(("Z",), f"after {code_name('G', code)} on line {line}")
        named = list(axes)
        if 920 in g:
            for axis, word in axes.items():
                self.pos[axis] = AxisPos(word.value, word.decimals)
            return
        lost_by = sorted(g.keys() & (REFERENCE_RETURN | NAMED_AXES_LOST))
        if lost_by:
            code = lost_by[0]
            everywhere = code in REFERENCE_RETURN and not named
            self._lose(AXES if everywhere else named, f"after {code_name('G', code)} on line "
                                                      f"{line}")
            return
        if not axes or DWELL in g or g.keys() & FRAME_ARGUMENTS:
            return
        unknown = sorted(code for code in g if code not in KNOWN_G)
        if unknown:
            self._lose(named, f"after {code_name('G', unknown[0])} on line {line}, a G code "
                              "nurbsfeed does not interpret")
        elif self.cycle is not None:
            self._goto({axis: word for axis, word in axes.items() if axis != "Z"})
            self._lose(("Z",), f"after canned cycle {code_name('G', self.cycle)} on line {line}")
        elif self.motion in GROUP1_MOVES or self.motion in SPLINES:
            self._goto(axes)
        elif self.motion in PROBES:
            self._lose(named, f"after probing {code_name('G', self.motion)} on line {line}")
        else:
            self._lose(named, f"after axis words with no motion mode in effect on line {line}")

    def _goto(self, axes: dict[str, Word]) -> None:
        """The end point of a move: absolute, or relative to a known position under G91."""
        for axis, word in axes.items():
            current = self.pos[axis]
            if not self.incremental:
                self.pos[axis] = AxisPos(word.value, word.decimals)
            elif current.value is not None:
                self.pos[axis] = AxisPos(current.value + word.value,
                                         coarser_decimals(current.decimals, word.decimals))

    def end_curve(self, end: dict[str, AxisPos], feed: FeedWord | None, motion: int | None) -> None:
        """After a NURBS curve: the tool is at its end point, with the block's F and mode."""
        self.pos = dict(end)
        self.feed = feed
        self.motion = motion
        self.cycle = None

