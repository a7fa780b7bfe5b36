"""G-code program -> stream of PassThrough lines and CurveBlocks (program.py), line by line.

Call chain for one line: `tokenizer.tokenize_line` (for a plain "K_ X_ Y_ Z_ [R_]" line inside
a G06.2 curve, `fanuc.NurbsCurveReader.take_line` reads the text directly instead, with the same
result, and `take_run` reads a whole run of such lines at once in compiled code, point_lines.py;
`take_knot_line` reads a plain closing "K_" line the same way)
-> if a NURBS block is open, its reader
(`fanuc.NurbsCurveReader` or `linuxcnc.G52BlockReader`) takes the block, and the CurveBlock is
yielded when the block completes, after the comment, blank and N-only lines read inside it (kept,
in order, as one PassThrough: they come out right before the block's moves); a `%` inside a block
is an error; otherwise `_start` decides whether the block opens a NURBS
block, and if not `modal.ModalState.apply` executes it and the line passes through unchanged.
Parameter assignments take effect after their line.

Dialect dispatch. `fanuc`: G06.2 curves (a Q word is an error, G5.2 is refused). `linuxcnc`: G5.2
blocks and G6.2 curves with LinuxCNC's rules. `auto`: G5.2 is LinuxCNC; G6.2 is LinuxCNC when its
first block has a Q word, Fanuc otherwise; a curve that continues a modal G6.2 follows the rules
of the curve before it.

Besides the text (and, for `take_run`, one copy of it as ASCII codes), nothing is held but the
modal state, the parameters and the NURBS block being read (its control points, not its lines:
their line ending is all a CurveBlock keeps).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from nurbsfeed.errors import InputError, Location
from nurbsfeed.gcode.fanuc import NurbsCurveReader, stray_knot
from nurbsfeed.gcode.linuxcnc import G52BlockReader
from nurbsfeed.gcode.modal import AXES, G5_2, G5_3, G6_2, NO_POSITION_EFFECT, ModalState
from nurbsfeed.gcode.nurbs_block import FinishedCurve, first_word, motion_words
from nurbsfeed.gcode.point_lines import ProgramCodes
from nurbsfeed.gcode.tokenizer import Block, Param, tokenize_line
from nurbsfeed.program import CurveBlock, PassThrough, ProgramItem

DIALECTS = ("auto", "fanuc", "linuxcnc")
BOM = "\ufeff"


def read_gcode(path: Path, text: str, dialect: str = "auto") -> Iterator[ProgramItem]:
    """The program in `text` (read from `path`) as items in file order, streamed.

    `text` keeps its line endings; the PassThrough texts and the lines the CurveBlocks stand for
    concatenate to it exactly, except that the comment, blank and N-only lines inside a NURBS
    block come (in order) right before its CurveBlock, and a BOM comes first on its own.
    Raises InputError (or CurveError) at FILE:LINE:COL of the word at fault, when the stream
    reaches it; an unknown dialect is refused at once.
    """
    if dialect not in DIALECTS:
        raise InputError(f"unknown G-code dialect '{dialect}' (use auto, fanuc or linuxcnc)")
    return _Reader(str(path), dialect).items(text)


class _Reader:
    """The state of one read: modal state, parameters, and the NURBS block being read."""

    def __init__(self, path: str, dialect: str) -> None:
        self.path = path
        self.dialect = dialect
        self.state = ModalState(path)
        self.params: dict[int, Param] = {}
        self.open: NurbsCurveReader | G52BlockReader | None = None
        self.eol = "\n"
        self.last_curve: NurbsCurveReader | None = None  # the modal G6.2 curve's rules
        self.kept: list[str] = []  # the inert lines inside the open block, yielded before it

    def items(self, text: str) -> Iterator[ProgramItem]:
        if text.startswith(BOM):  # kept byte for byte, and not part of the first line
            yield PassThrough(BOM)
            text = text[len(BOM):]
        # "\n" ends a line (a lone "\r" inside one is a space), except in a file whose lines all
        # end in "\r" (classic Mac OS): read as one line, it would convert nothing
        newline = "\r" if "\n" not in text and "\r" in text else "\n"
        program = ProgramCodes.of(text)
        # Once a scan reads no line, the next waits for a line take_line reads: where a program
        # writes its points in another form (N words, F on every line), a scan per line would
        # cost more than it saves.
        scan = True
        pos = 0  # where the next line starts
        line = 0
        while pos < len(text):
            line += 1
            if scan and program is not None and isinstance(self.open, NurbsCurveReader):
                n, after = self.open.take_run(program, pos, line)
                if n:  # a run of plain control points, scanned at once
                    line += n - 1
                    pos = after
                    continue
                scan = False
            end = text.find(newline, pos) + 1 or len(text)
            line_text = text[pos:end]
            pos = end
            if isinstance(self.open, NurbsCurveReader):  # plain lines, read straight from text
                if self.open.take_line(line_text, line):
                    scan = True
                    continue  # a control point
                closed = self.open.take_knot_line(line_text, line)
                if closed is not None:  # a closing knot
                    if closed:
                        yield from self._close()
                    continue
            block = tokenize_line(line_text, line, self.path, self.params)
            if self.open is not None:
                if block.delimiter:
                    body = line_text.rstrip("\r\n")
                    raise InputError("'%' (start or end of the program) inside a NURBS block: "
                                     "the block has not ended here",
                                     Location(self.path, line,
                                              len(body) - len(body.lstrip(" \t\r")) + 1))
                if block.is_inert:  # a comment, blank or N-only line: kept, in order
                    self.kept.append(line_text)
                elif self.open.take(block):
                    yield from self._close()
            else:
                self.open = self._start(block)
                if self.open is None:
                    self.state.apply(block)
                    yield PassThrough(line_text)
                else:
                    self.eol = block.eol or newline
            for assignment in block.assignments:
                self.params[assignment.number] = assignment.param
        if self.open is not None:
            raise self.open.unfinished()

    def _close(self) -> Iterator[ProgramItem]:
        """The kept lines of the block just completed, then its CurveBlock."""
        assert self.open is not None, "called when a block completes"
        finished = self.open.finish()
        if self.kept:
            yield PassThrough("".join(self.kept))
            self.kept = []
        yield self._curve_block(finished)
        self.open = None

    def _start(self, block: Block) -> NurbsCurveReader | G52BlockReader | None:
        """The reader of the NURBS block this block opens, or None for an ordinary block."""
        g = block.codes("G")
        state = self.state
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
                          feed_u=finished.feed_u, feed_mm_s=finished.feed_mm_s)
