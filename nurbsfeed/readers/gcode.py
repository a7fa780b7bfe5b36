"""G-code program -> stream of PassThrough lines and CurveBlocks (program.py), line by line.

The lines come from files.InputFile (decoded, endings kept) and are read as the items are taken:
a pass-through line is yielded before the line after it is read, and only inside a G06.2 / G6.2
curve does the reader look ahead, point_lines.RUN_LINES lines at most, for a run of control
points.

Call chain for one line: `tokenizer.tokenize_line` (`siemens.tokenize_siemens_line` in a
Sinumerik program; for a plain "K_ X_ Y_ Z_ [R_]" line inside
a G06.2 curve, `fanuc.NurbsCurveReader.take_line` reads the text directly instead, with the same
result, and `take_run` reads a whole run of such lines at once in compiled code, point_lines.py;
`take_knot_line` reads a plain closing "K_" line the same way; outside a NURBS block a plain
straight move "[N_ ][G0 |G1 ]X_ Y_ Z_ F_" is read and executed without words, `_plain_move`)
-> if a NURBS block is open, its reader
(`fanuc.NurbsCurveReader`, `linuxcnc.G52BlockReader` or `siemens.BsplineReader`) takes the block,
and the CurveBlock is yielded when the block completes, after the comment, blank and N-only lines
read inside it (kept, in order, as one PassThrough: they come out right before the block's
moves); a `%` inside a block is an error. A BSPLINE has no closing block: the block that ends it
(a motion command, the program end) completes it and is then read as any other. Outside a block
(`_outside`): a LinuxCNC G5 / G5.1 is a curve of its own (`linuxcnc_splines.read_spline`);
otherwise `_start` decides whether the block opens a NURBS block, and if not
`modal.ModalState.apply` executes it and the line passes through unchanged.
Parameter assignments (numbered and named) take effect after their line.

Dialect dispatch. `fanuc`: G06.2 curves (a Q word is an error, G5.2 is refused, G5 and G5.1
are Fanuc's modes and pass through). `linuxcnc`: G5 / G5.1 splines, G5.2 blocks and G6.2 curves
with LinuxCNC's rules. `siemens`: Sinumerik syntax and BSPLINE. `auto`: a .mpf / .spf file is
Sinumerik, and so is the rest of a program from a line with BSPLINE on; G5 / G5.1 with X, Y, I
or J is LinuxCNC's spline (Fanuc's G05 P10000, G05.1 Q1 have none); G5.2 is LinuxCNC; G6.2 is
LinuxCNC when its first block has a Q word, Fanuc otherwise; a curve that continues a modal G6.2
follows the rules of the curve before it. Each curve is decided from what has been read up to
its first block, never from lines after it.

Nothing is held but the modal state, the parameters, the lines looked ahead at (and, for
`take_run`, one copy of them as ASCII codes) and the NURBS block being read (its control points,
not its lines: their line ending is all a CurveBlock keeps): memory does not grow with the
number of lines.
"""

from __future__ import annotations

import itertools
import re
from collections import deque
from collections.abc import Iterator
from pathlib import Path

from nurbsfeed.choices import DIALECTS
from nurbsfeed.errors import InputError, Location
from nurbsfeed.files import BOM
from nurbsfeed.gcode import point_lines
from nurbsfeed.gcode.fanuc import LINEAR_MODES, NurbsCurveReader, stray_knot
from nurbsfeed.gcode.linuxcnc import G52BlockReader
from nurbsfeed.gcode.linuxcnc_splines import G5, G5_1, is_spline_block, read_spline
from nurbsfeed.gcode.modal import (
    AXES,
    G5_2,
    G5_3,
    G6_2,
    GROUP1_MOVES,
    NO_POSITION_EFFECT,
    PROBES,
    SPLINES,
    ModalState,
    tolerance,
)
from nurbsfeed.gcode.nurbs_block import FinishedCurve, first_word, motion_words
from nurbsfeed.gcode.plain_moves import plain_move
from nurbsfeed.gcode.siemens import BSPLINE, SUFFIXES, BsplineReader, tokenize_siemens_line
from nurbsfeed.gcode.tokenizer import Block, Param, ParamKey, Word, code_name, tokenize_line
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem

G1 = 10
_BSPLINE = re.compile(r"\bBSPLINE\b", re.IGNORECASE)
MOTION_CODES = GROUP1_MOVES | PROBES | SPLINES | {G5_2, G6_2}


def read_gcode(path: Path, lines: Iterator[str], dialect: str = "auto"
               ) -> Iterator[ProgramItem]:
    """The program whose `lines` (read from `path`, each with its ending, files.InputFile) are
    given as items in file order, streamed (module docstring).

    The PassThrough texts and the lines the CurveBlocks stand for concatenate to the lines
    exactly, except that the comment, blank and N-only lines inside a NURBS block come (in
    order) right before its CurveBlock, and a BOM comes first on its own.
    Raises InputError (or CurveError) at FILE:LINE:COL of the word at fault, when the stream
    reaches it; an unknown dialect is refused at once.
    """
    if dialect not in DIALECTS:
        raise InputError(f"unknown G-code dialect '{dialect}' (use {', '.join(DIALECTS)})")
    if dialect == "auto" and path.suffix.lower() in SUFFIXES:
        dialect = "siemens"
    return _Reader(str(path), dialect).items(lines)


class _Reader:
    """The state of one read: modal state, parameters, and the NURBS block being read."""

    def __init__(self, path: str, dialect: str) -> None:
        self.path = path
        self.dialect = dialect
        self.state = ModalState(path)
        self.params: dict[ParamKey, Param] = {}
        self.open: NurbsCurveReader | G52BlockReader | BsplineReader | None = None
        self.g70: Word | None = None  # Sinumerik G70 in force (siemens.py)
        self.eol = "\n"
        self.last_curve: NurbsCurveReader | None = None  # the modal G6.2 curve's rules
        self.kept: list[str] = []  # the inert lines inside the open block, yielded before it
        self.g5_exit: tuple[float, float] | None = None  # -P -Q of a G5 that ends here
        # the last G5 / G5.1 and the motion mode it left in force, while that is not G1
        self.spline_after: tuple[Word, int] | None = None

    def items(self, lines: Iterator[str]) -> Iterator[ProgramItem]:
        ahead = _LookAhead(lines)
        first = ahead.peek(1)
        if first and first[0].startswith(BOM):  # kept byte for byte, not part of the first line
            yield PassThrough(BOM)
            ahead.replace_first(first[0][len(BOM):])
        # Once a scan reads no line, the next waits for a line take_line reads: where a program
        # writes its points in another form (N words, F on every line), a scan per line would
        # cost more than it saves.
        scan = point_lines.RUNS_ENABLED
        line = 0
        while True:
            if scan and isinstance(self.open, NurbsCurveReader):
                n, more = self._take_run(ahead, line + 1)
                if n:  # a run of plain control points, scanned at once
                    line += n
                    scan = more
                    continue
                scan = False
            line_text = ahead.next()
            if line_text is None:
                break
            line += 1
            if isinstance(self.open, NurbsCurveReader):  # plain lines, read straight from text
                if self.open.take_line(line_text, line):
                    scan = point_lines.RUNS_ENABLED
                    continue  # a control point
                closed = self.open.take_knot_line(line_text, line)
                if closed is not None:  # a closing knot
                    if closed:
                        yield from self._close()
                    continue
            if self.open is None:
                moved = self._plain_move(line_text, line)
                if moved is not None:
                    yield moved
                    continue
            block = self._tokenize(line_text, line)
            if self.open is not None:
                if block.delimiter:
                    body = line_text.rstrip("\r\n")
                    raise InputError("'%' (start or end of the program) inside a NURBS block: "
                                     "the block has not ended here",
                                     Location(self.path, line,
                                              len(body) - len(body.lstrip(" \t\r")) + 1))
                if block.is_inert:  # a comment, blank or N-only line: kept, in order
                    self.kept.append(line_text)
                elif isinstance(self.open, BsplineReader) and self.open.ends_at(block):
                    yield from self._close()  # then the block that ends it, as any other
                    yield from self._outside(block, line_text)
                elif self.open.take(block):
                    yield from self._close()
            else:
                yield from self._outside(block, line_text)
            for assignment in block.assignments:
                self.params[assignment.key] = assignment.param
        if isinstance(self.open, BsplineReader):  # a modal BSPLINE ends with the program
            yield from self._close()
        elif self.open is not None:
            raise self.open.unfinished()

    def _tokenize(self, line_text: str, line: int) -> Block:
        """The line's words, in the syntax of the dialect; under `auto`, a BSPLINE makes the
        program a Sinumerik one from its line on (the lines before read the same in both)."""
        if (self.dialect == "auto" and ("PLINE" in line_text or "pline" in line_text)
                and _BSPLINE.search(_code_part(line_text))):  # (a substring test first: fast)
            self.dialect = "siemens"
        if self.dialect == "siemens":
            return tokenize_siemens_line(line_text, line, self.path)
        return tokenize_line(line_text, line, self.path, self.params)

    def _outside(self, block: Block, line_text: str) -> Iterator[ProgramItem]:
        """A block outside any NURBS block: a G5 / G5.1 curve, the start of a NURBS block, or
        a line that passes through once executed."""
        spline = self._spline_word(block)
        if spline is not None:
            self.eol = block.eol or _line_ending(line_text)
            yield self._spline(block, spline)
            return
        self.open = self._start(block)
        if self.open is None:
            self._check_after_spline(block)
            if self.dialect == "siemens":
                self._units_word(block)
            before = (self._motion_state() if self.dialect != "siemens" and _may_join(block)
                      else None)
            self.state.apply(block)
            self._moved(block)
            joins = before is not None and self._joins(before)
            yield PassThrough(line_text, joins, joins and not block.is_inert)
        else:
            self.eol = block.eol or _line_ending(line_text)

    def _plain_move(self, line_text: str, line: int) -> PassThrough | None:
        """A plain straight move outside any NURBS block (gcode.plain_moves), executed as
        `_outside` executes its block, which here opens no curve, is no spline and may join a
        chain; None, having read nothing, for any other line, and under Sinumerik syntax, after
        a G5 / G5.1 that left another motion mode, under another motion mode or a canned cycle
        without a G word, or with a negative F (the general path words the error)."""
        if self.dialect == "siemens" or self.spline_after is not None:
            return None
        read = plain_move(line_text, line)
        if read is None:
            return None
        motion, axes, feed = read
        state = self.state
        if ((motion is None and (state.motion not in LINEAR_MODES or state.cycle is not None))
                or (feed is not None and feed.value < 0.0)):
            return None
        before = self._motion_state()
        state.apply_plain_move(motion, axes, feed)
        if motion is not None or axes:  # `_moved`
            self.g5_exit = None
        joins = self._joins(before)
        return PassThrough(line_text, joins, joins)

    def _motion_state(self) -> tuple[object, ...]:
        """What a line between two curves of a chain must leave as it was (PassThrough.joins):
        the position (`_same_place`), units, distance mode, plane, feed mode, cutter
        compensation, canned cycle."""
        state = self.state
        return (state.pos.copy(), state.units, state.incremental, state.plane, state.feed_mode,
                state.cutter_comp, state.cycle)

    def _joins(self, before: tuple[object, ...]) -> bool:
        """Whether the line just executed left the motion state `before` as it was: each axis
        at the same point to the resolution both were written with (modal.tolerance: a G1 to
        the point reached, written to fewer decimals, is still that point)."""
        after = self._motion_state()
        if after[1:] != before[1:]:
            return False
        units = self.state.units
        for axis in AXES:
            was, now = before[0][axis], after[0][axis]  # type: ignore[index]
            if was.value is None or now.value is None:
                return False
            if abs(now.value - was.value) > tolerance(units, was.decimals, now.decimals):
                return False
        return True

    def _units_word(self, block: Block) -> None:
        """Sinumerik G70 (inch, F in the machine's unit) until G700 / G71 / G710."""
        for word in block.words:
            if word.letter == "G" and word.code in (200, 210):
                self.g70 = word if word.text.rstrip(".") == "70" else None

    def _take_run(self, ahead: _LookAhead, line: int) -> tuple[int, bool]:
        """`NurbsCurveReader.take_run` on the next lines (line number `line` on), at most
        point_lines.RUN_LINES of them and only as far as they are ASCII (where string and byte
        positions agree; a point line is ASCII): the number of lines it read, now consumed, and
        whether it read every line given (else the next line is one the scan refuses, and would
        refuse again: the run has ended)."""
        assert isinstance(self.open, NurbsCurveReader), "called inside a G06.2 / G6.2 curve"
        if not self.open.takes_runs:  # (before the text is joined: ~50 us a call)
            return 0, False
        batch = ahead.peek(point_lines.RUN_LINES)
        text = "".join(batch)
        if not text.isascii():  # rare: find the first line that is not
            n_ascii = next(i for i, line_text in enumerate(batch) if not line_text.isascii())
            if not n_ascii:
                return 0, False
            batch = batch[:n_ascii]
            text = "".join(batch)
        n, _ = self.open.take_run(point_lines.ProgramCodes(text), 0, line)
        ahead.drop(n)
        return n, n == len(batch)

    def _spline_word(self, block: Block) -> Word | None:
        """The G5 / G5.1 word of a LinuxCNC spline block, or None (module docstring)."""
        if self.dialect in ("fanuc", "siemens"):
            return None
        g = block.codes("G")
        for code in (G5, G5_1):
            if code in g and is_spline_block(block, code):
                return g[code]
        return None

    def _spline(self, block: Block, start: Word) -> CurveBlock:
        """The CurveBlock of one G5 / G5.1 block (linuxcnc_splines.py)."""
        before = self.state.motion
        finished, self.g5_exit = read_spline(block, self.state, start, self.g5_exit)
        if before not in (None, G1):
            self.spline_after = (start, before)
        return self._curve_block(finished)

    def _check_after_spline(self, block: Block) -> None:
        """After a G5 / G5.1 in a motion mode other than G1, a block of axis words only moves
        in that mode for LinuxCNC, but in G1 after the moves written in place of the spline:
        refused (linuxcnc_splines.py)."""
        if self.spline_after is None:
            return
        if block.codes("G").keys() & MOTION_CODES:
            self.spline_after = None
            return
        axes = [word for word in block.words if word.letter in AXES]
        if axes and all(word.code in NO_POSITION_EFFECT for word in block.words
                        if word.letter == "G"):
            spline, mode = self.spline_after
            raise InputError(f"{axes[0].name} without a G code after the {spline.name} on line "
                             f"{spline.line}: LinuxCNC moves it in {code_name('G', mode)}, the "
                             f"mode before the spline, but the G1 moves written in place of the "
                             f"spline leave G1 in force: write {code_name('G', mode)} on this "
                             "line", self.state.where(axes[0]))

    def _moved(self, block: Block) -> None:
        """A pass-through block with G codes or axis words ends a run of G5 splines: the next
        G5 needs its own I and J."""
        if self.g5_exit is not None and any(word.letter == "G" or word.letter in AXES
                                            for word in block.words):
            self.g5_exit = None

    def _close(self) -> Iterator[ProgramItem]:
        """The kept lines of the block just completed, then its CurveBlock."""
        assert self.open is not None, "called when a block completes"
        finished = self.open.finish()
        if self.kept:
            yield PassThrough("".join(self.kept), joins=True)
            self.kept = []
        yield self._curve_block(finished)
        self.open = None
        self.g5_exit = None
        self.spline_after = None

    def _start(self, block: Block) -> NurbsCurveReader | G52BlockReader | BsplineReader | None:
        """The reader of the NURBS block this block opens, or None for an ordinary block."""
        g = block.codes("G")
        state = self.state
        if self.dialect == "siemens":
            bspline = block.first(BSPLINE)
            return None if bspline is None else BsplineReader(block, state, bspline, self.g70)
        if G6_2 in g:
            question = block.first("Q")
            linuxcnc = self.dialect == "linuxcnc" or (self.dialect == "auto"
                                                     and question is not None)
            self.last_curve = NurbsCurveReader(block, state, g[G6_2], linuxcnc)
            return self.last_curve
        if G5_2 in g:
            if self.dialect == "fanuc":
                raise InputError("G5.2 is LinuxCNC's NURBS block; read this file with --dialect "
                                 "linuxcnc (or auto)", state.where(g[G5_2]))
            return G52BlockReader(block, state, g[G5_2])
        if G5_3 in g:
            typo = state.unknown_g
            if typo is not None:
                raise InputError(f"{typo.name} is a G code nurbsfeed does not know, and the G5.3 "
                                 f"on line {block.line} closes a NURBS block nothing opened: "
                                 "write G5.2 to open it", state.where(typo))
            raise InputError("G5.3 without G5.2 first (LinuxCNC: Cannot use G5.3 without G5.2 "
                             "first)", state.where(g[G5_3]))
        previous = self.last_curve
        if state.motion != G6_2 or previous is None:
            stray = None if g else stray_knot(block, state)
            if stray is not None:
                raise stray
            return None
        if state.cycle is not None or motion_words(block):
            return None
        knot = block.first("K")
        axes = [word for word in block.words if word.letter in AXES]
        if knot is not None and axes:
            start = first_word(block)
            self.last_curve = NurbsCurveReader(block, state, start, previous.linuxcnc)
            return self.last_curve
        if knot is not None:
            raise InputError(f"{knot.name}: knot-only block after the curve ended; a curve of "
                             f"order {previous.order} closes with exactly {previous.order} K "
                             "blocks", state.where(knot))
        # Axis words without K are a control point missing its knot, unless a G code of the
        # block gives them another meaning (G28 Z0., G92 X0, G04 X1.5, ...).
        if axes and all(word.code in NO_POSITION_EFFECT for word in block.words
                        if word.letter == "G"):
            raise InputError(f"{axes[0].name} in NURBS mode without a knot: a {previous.label} "
                             "control point carries K (Fanuc alarm PS1002); write G1 for a "
                             "straight move", state.where(axes[0]))
        return None

    def _curve_block(self, finished: FinishedCurve) -> CurveBlock:
        state = self.state
        state.end_curve(finished.end, finished.feed, finished.motion)
        return CurveBlock(curve=finished.curve, location=finished.location, units=state.units,
                          eol=self.eol, incremental=state.incremental,
                          feed_word_after=None if finished.feed is None else finished.feed.word,
                          feed_u=finished.feed_u, feed_mm_s=finished.feed_mm_s,
                          semicolon_comments=self.dialect == "siemens")


class _LookAhead:
    """The lines of a program, with the next few readable before they are taken."""

    def __init__(self, lines: Iterator[str]) -> None:
        self.lines = lines
        self.ahead: deque[str] = deque()

    def next(self) -> str | None:
        """The next line, or None at the end."""
        if self.ahead:
            return self.ahead.popleft()
        return next(self.lines, None)

    def peek(self, n: int) -> list[str]:
        """The next `n` lines (fewer at the end), left to be taken."""
        if len(self.ahead) < n:
            self.ahead.extend(itertools.islice(self.lines, n - len(self.ahead)))
        return list(itertools.islice(self.ahead, n))

    def drop(self, n: int) -> None:
        """Take the next `n` lines, already peeked."""
        for _ in range(n):
            self.ahead.popleft()

    def replace_first(self, line: str) -> None:
        """Read the next line, already peeked, as `line` (as no line if it is empty)."""
        if line:
            self.ahead[0] = line
        else:
            self.ahead.popleft()


# G codes a line between two curves of a chain may carry (PassThrough.joins): G0 / G1 (a move,
# which must then have no length) and modal words that may repeat what is in force
JOINING_G = {0, 10, 170, 180, 190, 200, 210, 400, 900, 910, 940}
JOINING_LETTERS = {"N", "F", "G", *AXES}


def _may_join(block: Block) -> bool:
    """Whether the block's words alone allow a chain to run on across it: no parameter
    assignment, block delete or '%', and only N, F, X, Y, Z and the G codes of JOINING_G (an M,
    S, T, a dwell, an offset change end a chain whatever they do)."""
    if block.assignments or block.block_delete or block.delimiter:
        return False
    return all(word.letter in JOINING_LETTERS
               and (word.letter != "G" or word.code in JOINING_G) for word in block.words)


def _code_part(line_text: str) -> str:
    """A line without its comments: what precedes ';', with '(...)' removed."""
    return re.sub(r"\([^)]*\)", "", line_text.split(";", 1)[0])


def _line_ending(line_text: str) -> str:
    """The ending a line the tokenizer gives none is written with: "\\r" in a file whose lines
    end in it alone. (The last line of a file has none either, but a block opened there never
    completes.)"""
    return "\r" if line_text.endswith("\r") else "\n"
