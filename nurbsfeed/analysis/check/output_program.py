"""The two programs as `check` reads them: the source as tokens (pass-through lines and curves),
the output as tokens plus one Section of moves per curve, and the moves' words decoded."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nurbsfeed import windowed
from nurbsfeed.analysis.check.report import Findings
from nurbsfeed.chains import ChainWindow, chain_items
from nurbsfeed.files import InputFile
from nurbsfeed.gcode.profile_record import RECORD_START, SEMICOLON_START
from nurbsfeed.gcode.writer import ZERO_LENGTH_COMMENT, rapid_line
from nurbsfeed.machine import Machine
from nurbsfeed.pipeline import chain_block
from nurbsfeed.program import CurveBlock, PassThrough
from nurbsfeed.readers import read_program

COMMENT_RE = re.compile(r"\(nurbsfeed: curves? (\d+)(?:-\d+ chained,)? (.*), (\d+) points, "
                        r"period ([0-9.eE+-]+) ms, (\w+), length ([0-9.]+) (mm|in), "
                        r"planned cycle ([0-9.]+) s(, continued)?\)$")
ZERO_LENGTH_LINE = ZERO_LENGTH_COMMENT  # pipeline.convert_block
MOVE_LINE_RE = re.compile(r"(?:G0*1(?![0-9.])\s*)?(?:[XYZF]\s*[-+]?[0-9.]*\s*)+")
WORD_RE = re.compile(r"([A-Z])\s*([-+]?[0-9.]*)")
G90_G91_MESSAGE = ("the moves of a G91 block must be bracketed by G90 and G91 lines (the "
                   "moves are absolute)")

Token = tuple[str, Any]  # ("line", text with its ending) or ("curve", index)


@dataclass
class Section:
    """The lines that replaced one curve in the output."""

    index: int
    comment_line: int  # 1-based
    n_points: int
    period_ms: float
    zero_length: bool
    moves: list[tuple[int, str]] = field(default_factory=list)  # (line number, text)
    runs_on: bool = False  # its last part's comment says the next section continues it
    joints_done: int = 0  # the chain's joints whose lines its parts have read


def split_lines(text: str, ending: str) -> list[str]:
    """Lines with their endings, each ending in `ending` ("\\n": "\\r\\n" stays with its line)
    but perhaps the last."""
    parts = text.split(ending)
    lines = [part + ending for part in parts[:-1]]
    if parts[-1]:
        lines.append(parts[-1])
    return lines


def body(line: str) -> str:
    """A line without its ending; a Sinumerik comment "; nurbsfeed: ..." as the "(...)" it
    stands for (writer.comment_line)."""
    text = line.rstrip("\r\n")
    return f"({text[2:]})" if text.startswith("; nurbsfeed: ") else text


def source_tokens(path: Path, machine: Machine, dialect: str
                  ) -> tuple[list[Token], list[CurveBlock], dict[int, list[str]],
                             dict[int, list[list[str]]]]:
    """Source -> tokens, curve blocks (in mm), the pass-through lines that follow each curve
    (the G0 the writer puts before a JSON curve reads as one, in its place), and the lines at
    each joint of a chain.

    Curves that join are gathered as the conversion gathers them (chains.chain_items, design
    §3b): a chain is one token and one section, its first curve's index, and every one of its
    curves has the chain's merged block (in mm) as its block; the lines read between its curves
    are expected inside its section, at the joints, in order."""
    tokens: list[Token] = []
    blocks: list[CurveBlock] = []
    following: dict[int, list[str]] = {}
    joint_lines: dict[int, list[list[str]]] = {}
    section = -1
    # a pass-through item is a line of the source, or several (the inert lines inside a block):
    # split as the reader split them (the lines the JSON reader writes hold no "\r")
    source = InputFile(path)
    ending = "\r" if source.cr_only else "\n"
    run: list[ChainWindow] = []  # the windows of a chain that run on into each other
    for item in chain_items(read_program(source, dialect), machine):
        if isinstance(item, ChainWindow) and (item.ahead or run) and windowed.RUN_ON:
            run.append(item)
            if item.ahead:
                continue
            item = ChainWindow(tuple(b for w in run for b in w.blocks),
                               tuple(lines for w in run for lines in (
                                   *w.between, *(w.ahead_between[:1] if w.ahead else ()))))
            run = []
        block = None if isinstance(item, PassThrough) else item.blocks[0]
        if isinstance(item, PassThrough) or (block is not None and block.rapid_to_start):
            text = item.text if isinstance(item, PassThrough) else rapid_line(
                item.blocks[0].curve.points[0], machine.decimals, item.blocks[0].units) + \
                item.blocks[0].eol
            for line in split_lines(text, ending):
                tokens.append(("line", line))
                if section >= 0:
                    following[section].append(line)
        if isinstance(item, ChainWindow):
            section = len(blocks)
            tokens.append(("curve", section))
            following[section] = []
            merged = chain_block(item, machine.limits)[0] if len(item.blocks) > 1 else block
            assert merged is not None, "a window has a first block"
            blocks.extend([merged] * len(item.blocks))
            joint_lines[section] = [[line for passed in at for line in split_lines(passed.text,
                                                                                   ending)]
                                    for at in item.between]
            if item.ahead:  # a window at rest at its cut: the lines there follow it
                for passed in item.ahead_between[0]:
                    for line in split_lines(passed.text, ending):
                        tokens.append(("line", line))
                        following[section].append(line)
    return tokens, blocks, following, joint_lines


def parse_output(lines: list[str], blocks: list[CurveBlock], following: dict[int, list[str]],
                 findings: Findings, joint_lines: dict[int, list[list[str]]] | None = None
                 ) -> tuple[list[Token], list[int], list[Section]]:
    """Output lines -> tokens, their line numbers, and the curve sections. A section is a
    nurbsfeed comment line and the moves after it (a chain's: with the lines of its joints
    among them). The profile record's lines before the first section are nurbsfeed's, not the
    source's (the CLI reads them)."""
    tokens: list[Token] = []
    token_lines: list[int] = []
    sections: list[Section] = []
    i = 0
    while i < len(lines):
        if not sections and lines[i].startswith((RECORD_START, SEMICOLON_START)):
            after = i
            while after < len(lines) and lines[after].startswith((RECORD_START,
                                                                  SEMICOLON_START)):
                after += 1
            if after < len(lines) and COMMENT_RE.match(body(lines[after])):
                i = after
        match = COMMENT_RE.match(body(lines[i]))
        if match is None:
            tokens.append(("line", lines[i]))
            token_lines.append(i + 1)
            i += 1
            continue
        if sections and sections[-1].runs_on:  # the next part of a chain run on in windows
            section = sections[-1]
            section.runs_on = match[9] is not None
            section.n_points += int(match[3])
            block = blocks[section.index] if section.index < len(blocks) else None
            i = _parse_section(lines, i + 1, section, block, following.get(section.index, []),
                               findings, (joint_lines or {}).get(section.index, []))
            continue
        index = int(match[1])
        section = Section(index, i + 1, int(match[3]), float(match[4]), False,
                          runs_on=match[9] is not None)
        tokens.append(("curve", index))
        token_lines.append(i + 1)
        sections.append(section)
        block = blocks[index] if index < len(blocks) else None
        i = _parse_section(lines, i + 1, section, block, following.get(index, []), findings,
                           (joint_lines or {}).get(index, []))
    return tokens, token_lines, sections


def _parse_section(lines: list[str], i: int, section: Section, block: CurveBlock | None,
                   after: list[str], findings: Findings, joints: list[list[str]]) -> int:
    """Read the moves of one section from line index i; return the index after the section.
    joints: the lines expected at each joint of a chain, in order, among the moves."""
    if i < len(lines) and body(lines[i]) == ZERO_LENGTH_LINE:
        section.zero_length = True
        return i + 1
    incremental = block is not None and block.incremental
    restore = (block.feed_word_after + block.eol
               if block is not None and block.feed_word_after else None)
    if incremental and not section.moves:
        if i < len(lines) and body(lines[i]) == "G90":
            i += 1
        else:
            findings.add("g90-g91", i + 1, G90_G91_MESSAGE)
    first = i
    joint = section.joints_done
    at_joints: list[int] = []  # the line indices of the joints' lines, not moves
    while i < len(lines):
        while joint < len(joints) and not joints[joint]:
            joint += 1
        if joint < len(joints) and lines[i:i + len(joints[joint])] == joints[joint]:
            at_joints.extend(range(i, i + len(joints[joint])))
            i += len(joints[joint])
            joint += 1
        elif MOVE_LINE_RE.fullmatch(body(lines[i])):
            i += 1
        else:
            break
    while joint < len(joints) and not joints[joint]:
        joint += 1
    section.joints_done = joint
    if section.runs_on:  # the next part goes on with the moves, the joints and the ending
        skip = set(at_joints)
        section.moves += [(n + 1, lines[n]) for n in range(first, i) if n not in skip]
        return i
    if joint < len(joints):
        findings.add("pass-through", i + 1, f"the lines of joint {joint + 1} of the chain are "
                     f"missing among its moves: {body(joints[joint][0])!r}")
    if not incremental:
        # a bare F or coordinate line after the block (its F restore, or the program's next
        # lines) looks like a move: give back the trailing lines that are exactly those
        expected = ([restore] if restore else []) + after
        for k in range(min(len(expected), i - first), 0, -1):
            if lines[i - k:i] == expected[:k]:
                i -= k
                break
    skip = set(at_joints)
    section.moves += [(n + 1, lines[n]) for n in range(first, i) if n not in skip]
    if incremental:
        if i < len(lines) and body(lines[i]) == "G91":
            i += 1
        else:
            findings.add("g90-g91", i + 1, G90_G91_MESSAGE)
    if restore is not None:
        if i < len(lines) and lines[i] == restore:
            i += 1
        else:
            findings.add("feed-restore", i + 1, f"the program's feed must be restored after the "
                         f"moves with the line {restore.strip()!r}")
    return i


def decode_moves(section: Section, findings: Findings
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Decode the moves: X/Y/Z words (M, 3) as NaN where not written, F (M,) (NaN: modal), the
    unit of each F word's last decimal as written (M,) (NaN where F is modal: F1.5 is 0.1),
    line numbers (M,); number-format violations are recorded on the way."""
    m = len(section.moves)
    axes = np.full((m, 3), np.nan)
    feed = np.full(m, np.nan)
    feed_unit = np.full(m, np.nan)
    lines = np.array([line for line, _ in section.moves], dtype=np.int64)
    for k, (line, text) in enumerate(section.moves):
        for letter, value in WORD_RE.findall(body(text)):
            if letter == "G":
                continue
            if "." not in value:
                findings.add("decimal-point", line, f"{letter}{value} has no decimal point "
                             f"(write {letter}{value or '0'}.)")
            try:
                number = float(value)
            except ValueError:
                findings.add("number", line, f"{letter}{value} is not a number")
                continue
            if number == 0.0 and value.startswith("-"):
                findings.add("negative-zero", line, f"{letter}{value} is a negative zero "
                             f"(write {letter}0.)")
            if letter == "F":
                if number <= 0.0:
                    findings.add("zero-feed", line, f"F{value}: a G1 move needs a positive feed")
                feed[k] = number
                feed_unit[k] = 10.0 ** -len(value.partition(".")[2])
            else:
                axes[k, "XYZ".index(letter)] = number
    return axes, feed, feed_unit, lines
