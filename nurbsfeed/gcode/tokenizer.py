"""One G-code line -> words, each with its line and column (1-based, in characters).

The lexical rules, shared by Fanuc and LinuxCNC programs:

- A word is a letter and a number: `X10.5`, `x-.5`, `X 10.0`, `G01X0Y0` (spaces may sit between the
  letter, the sign and the digits; digits themselves are contiguous). `N`, `O`, `G`, `M`, `F` are
  words like any other. A number without a decimal point means its face value (`X10` is 10.0, the
  "calculator-type" input of LinuxCNC and of Fanuc with parameter DPI set); the digits written
  after the point are kept as `Word.decimals`, the precision the program was written to. Digits
  are ASCII 0-9: full-width or Arabic-Indic digits (which a regex digit class and float() accept)
  are refused with their own message.
- Comments: `( ... )` anywhere, `;` to the end of the line.
- `%` alone at the start of a line is the program delimiter; the line has no words.
- `/` (optionally `/1`..`/9`, Fanuc optional block skip) as the first character: block delete.
- Literal parameters, numbered or named: `#1=10.5` (or `#1=#2`), `#<depth> = 2.5`,
  `#<_safe_z> = 5` assign; `X#1` / `F#1` / `X-#1` / `Z-#<depth>` read. Named parameters are
  LinuxCNC's: the name is case-insensitive and spaces inside it do not count (the interpreter
  reads `#<Safe Z>` as `#<safez>`); a leading `_` makes a global, which outside subroutines (not
  read here) is the same as a local. As in the LinuxCNC interpreter, assignments on a line take
  effect after the whole line is read, so `#1=5 X#1` reads the value #1 had before the line.
  Reading a parameter that was never assigned is an error: for a named one LinuxCNC's own
  ("Named parameter #<depth> not defined"); for a numbered one LinuxCNC would read 0 and Fanuc
  <vacant>, both almost always a mistake here.
- Not supported, each with its own message: expressions `[...]`, indirect parameters `##1`,
  macro / O-word statements (IF, WHILE, GOTO, `o100 sub`, ...).

Values are checked here once: finite, and for G and M at most one decimal (`G06.2` == `G6.2`,
compared as `Word.code`, tenths as an integer: G6.2 -> 62, G01 -> 10, G17 -> 170).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

from nurbsfeed.errors import InputError, Location

_SPACE = "[ \t\r]"  # the spaces between words (a lone CR inside a line is one)
_DIGITS = r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)"  # ASCII only: \d would take any script's digits
_NUMBER = re.compile(rf"[+-]?{_SPACE}*{_DIGITS}")
# a parameter: numbered (#12) or named (#<depth>), the name up to the first '>'
_PARAMETER = rf"#{_SPACE}*(?:([0-9]+)|<([^>]*)>)"
_PARAM_REF = re.compile(rf"([+-]?){_SPACE}*{_PARAMETER}")
_ASSIGN = re.compile(rf"{_PARAMETER}{_SPACE}*=")
_NAME = re.compile(r"[A-Za-z0-9_.]+")
_LETTER_RUN = re.compile(r"[A-Za-z]{2,}")
_FUNCTION = re.compile(rf"([A-Za-z]{{2,}}){_SPACE}*\[")
# The fast paths: a line of words separated by single spaces (what posts write), then a line of
# plain words and comments only (no %, /, #, [ or statements).
PLAIN_NUMBER = rf"[+-]?{_DIGITS}"  # a number written without spaces
_WORD = rf"[A-Za-z]{PLAIN_NUMBER}"
_SIMPLE_LINE = re.compile(rf"{_WORD}(?: {_WORD})*")
_PLAIN_LINE = re.compile(rf"{_SPACE}*(?:(?:[A-Za-z]{_SPACE}*[+-]?{_SPACE}*{_DIGITS}"
                         rf"|\([^)]*\)){_SPACE}*)*(?:;.*)?")
_PLAIN_WORD = re.compile(rf"([A-Za-z]){_SPACE}*([+-]?){_SPACE}*({_DIGITS})|\([^)]*\)|;.*")

# Letter runs that open a macro / O-word statement (Fanuc custom macro B, LinuxCNC O-codes).
KEYWORDS = frozenset({
    "IF", "THEN", "ELSE", "ELSEIF", "ENDIF", "WHILE", "ENDWHILE", "DO", "END", "GOTO",
    "SUB", "ENDSUB", "CALL", "RETURN", "REPEAT", "ENDREPEAT", "BREAK", "CONTINUE",
    "POPEN", "PCLOS", "DPRNT", "BPRNT", "SETVN",
})
BAD_PARAMETER = ("'#' must be followed by a parameter number or a name in <> (#1=10.5, X#1, "
                 "#<depth>=2.5); indirect (##1) parameters are not supported")
PARAMETER_LIMIT = 999999  # above the highest numbered parameter of any controller (Fanuc #100000s)
CODE_LIMIT = 10000.0  # G and M numbers above this are typos, and would overflow `code`


@dataclass(frozen=True)
class Param:
    """A parameter value and the fractional digits it was written with (None: none written)."""

    value: float
    decimals: int | None


class Word(NamedTuple):
    """A letter and its value. `text` is the value as written, spaces removed ("-.5", "#3").

    Words and blocks are named tuples, frozen values like the dataclasses elsewhere, because
    every word of every line is one: a tuple is built three times faster.
    """

    letter: str
    value: float
    text: str
    decimals: int | None
    line: int
    col: int

    @property
    def code(self) -> int:
        """G/M number in tenths: G6.2 -> 62, G1 -> 10 (only meaningful for G and M)."""
        return round(self.value * 10)

    @property
    def name(self) -> str:
        """The word as a user reads it: "X10.5", "G6.2", "F#1"."""
        return f"{self.letter}{self.text}"


ParamKey = int | str  # 12 for #12, "depth" for #<depth> (lower case, spaces removed)


def param_label(key: ParamKey) -> str:
    """12 -> "#12", "depth" -> "#<depth>": a parameter as a message names it."""
    return f"#{key}" if isinstance(key, int) else f"#<{key}>"


@dataclass(frozen=True)
class Assignment:
    """`#number=value` or `#<name>=value` on a line, applied after the line is read."""

    key: ParamKey
    param: Param
    col: int


class Block(NamedTuple):
    """One line: its words in order, its assignments, and how it ends."""

    line: int
    words: tuple[Word, ...]
    assignments: tuple[Assignment, ...] = ()
    block_delete: bool = False
    delimiter: bool = False  # a '%' line
    eol: str = "\n"

    def first(self, letter: str) -> Word | None:
        """The first word with this letter, or None."""
        for word in self.words:
            if word.letter == letter:
                return word
        return None

    def letters(self) -> set[str]:
        return {word.letter for word in self.words}

    def codes(self, letter: str) -> dict[int, Word]:
        """G (or M) codes of the block: code -> word."""
        return {word.code: word for word in self.words if word.letter == letter}

    @property
    def is_inert(self) -> bool:
        """Nothing to execute: blank, comment-only, `%`, or only a sequence number N."""
        return not self.assignments and all(word.letter == "N" for word in self.words)


def code_name(letter: str, code: int) -> str:
    """62 -> "G6.2", 10 -> "G1": the normalised spelling used in messages."""
    whole, tenth = divmod(code, 10)
    return f"{letter}{whole}" + (f".{tenth}" if tenth else "")


def printable(text: str) -> str:
    """Text safe to print: undecodable bytes (kept as surrogates) as \\xNN, controls escaped."""
    shown = []
    for char in text:
        if 0xDC80 <= ord(char) <= 0xDCFF:
            shown.append(f"\\x{ord(char) - 0xDC00:02x}")
        elif char.isprintable():
            shown.append(char)
        else:
            shown.append(repr(char)[1:-1])
    return "".join(shown)


def decimals_written(text: str) -> int | None:
    """Fractional digits of a number as written: "10.50" -> 2, "10." and "10" -> None."""
    point = text.find(".")
    return len(text) - point - 1 if -1 < point < len(text) - 1 else None


class _Scanner:
    """Walks one line's body; every error names the column where the scanner stands."""

    def __init__(self, body: str, line: int, path: str, params: Mapping[ParamKey, Param]
                 ) -> None:
        self.body = body
        self.line = line
        self.path = path
        self.params = params
        self.pos = 0

    def error(self, message: str, pos: int | None = None) -> InputError:
        col = (self.pos if pos is None else pos) + 1
        return InputError(message, Location(self.path, self.line, col))

    def skip_spaces(self) -> None:
        while self.pos < len(self.body) and self.body[self.pos] in " \t\r":
            self.pos += 1

    def at_end(self) -> bool:
        return self.pos >= len(self.body)

    def peek(self) -> str:
        return self.body[self.pos] if self.pos < len(self.body) else ""

    def snippet(self) -> str:
        rest = self.body[self.pos:self.pos + 8].rstrip()
        return f"'{printable(rest)}'" if rest else "the end of the line"

    def parameter_number(self, digits: str, pos: int) -> int:
        """A parameter number as written (#12 -> 12), refused above PARAMETER_LIMIT before int()
        reads it (Python refuses to convert strings of more than 4300 digits)."""
        stripped = digits.lstrip("0") or "0"
        if len(stripped) > len(str(PARAMETER_LIMIT)) or int(stripped) > PARAMETER_LIMIT:
            shown = digits if len(digits) <= 12 else digits[:8] + "..."
            raise self.error(f"#{shown}: parameter numbers go from 0 to {PARAMETER_LIMIT}", pos)
        return int(stripped)

    def bad_parameter(self) -> InputError:
        """The error for a '#' that starts no parameter the reader knows."""
        if re.match(rf"#{_SPACE}*<", self.body[self.pos:]):
            return self.error("'#<' starts a named parameter but no '>' closes its name on this "
                              "line (write #<depth>)")
        return self.error(BAD_PARAMETER)

    def parameter_key(self, number: str | None, name: str, pos: int) -> ParamKey:
        """The parameter `#number` or `#<name>` (as `_PARAMETER` splits it) names: its number,
        or its name normalised as the LinuxCNC interpreter does (spaces removed, lower case)."""
        if number is not None:
            return self.parameter_number(number, pos)
        key = re.sub(_SPACE, "", name).lower()
        if not _NAME.fullmatch(key):
            shown = printable(name if len(name) <= 24 else name[:20] + "...")
            raise self.error(f"'#<{shown}>' is not a parameter name: a name is letters, digits "
                             "and '_' between < and > (#<depth>, #<_safe_z>)", pos)
        return key

    def value(self, owner: str, owner_pos: int) -> tuple[float, str, int | None]:
        """A number or a parameter read after a letter (or after `#n=`): value, text, decimals."""
        self.skip_spaces()
        if self.peek() == "[":
            raise self.error("expressions in [...] are not supported; write the value as a "
                             "number")
        function = _FUNCTION.match(self.body, self.pos)
        if function:
            raise self.error(f"'{function.group(1)}[...]' is an expression; expressions are not "
                             "supported, write the value as a number")
        if owner == "O" and self.peek() == "<":
            raise self.error("'O<name>' starts an O-word statement; nurbsfeed reads literal "
                             "G-code only (no subroutines, IF/WHILE/GOTO or expressions)")
        ref = _PARAM_REF.match(self.body, self.pos)
        if ref:
            key = self.parameter_key(ref.group(2), ref.group(3),
                                     self.body.index("#", ref.start()))
            label = param_label(key)
            if key not in self.params:
                if isinstance(key, str):
                    raise self.error(f"Named parameter {label} not defined (LinuxCNC): assign it "
                                     f"({label} = value) on an earlier line")
                raise self.error(f"{label} is used before it is assigned (write {label}="
                                 "value on an earlier line)")
            param = self.params[key]
            self.pos = ref.end()
            sign = -1.0 if ref.group(1) == "-" else 1.0
            return sign * param.value, f"{ref.group(1)}{label}", param.decimals
        if self.peek() == "#":
            raise self.bad_parameter()
        if self.peek().isdigit() and not self.peek().isascii():
            raise self.error(f"'{printable(self.peek())}' is not one of the digits 0-9 "
                             "(full-width and other scripts' digits are not G-code numbers)")
        literal = _NUMBER.match(self.body, self.pos)
        if not literal:
            raise self.error(f"{owner} has no number after it (found {self.snippet()}); write "
                             f"e.g. {owner}10.5", owner_pos)
        text = re.sub(_SPACE, "", literal.group())
        value = float(text)
        if not math.isfinite(value):
            shown = text if len(text) <= 24 else text[:20] + "..."
            raise self.error(f"{owner}{shown} is too large to be a number", owner_pos)
        self.pos = literal.end()
        return value, text, decimals_written(text)


def tokenize_line(line_text: str, line: int, path: str,
                  params: Mapping[ParamKey, Param]) -> Block:
    """Split one line (with or without its line ending) into a Block.

    `params` are the parameter values before this line; the line's own assignments are returned
    in `Block.assignments` for the caller to apply afterwards. Raises InputError at the column of
    the offending character or word.
    """
    if line_text.endswith("\n"):
        eol = "\r\n" if line_text.endswith("\r\n") else "\n"
        body = line_text[:-len(eol)]
    else:
        eol = ""
        body = line_text
    if _SIMPLE_LINE.fullmatch(body):
        words = _simple_words(body, line)
        if words is not None:
            return tuple.__new__(Block, (line, words, (), False, False, eol))  # as in Word
    if _PLAIN_LINE.fullmatch(body):
        words = _plain_words(body, line)
        if words is not None:
            return Block(line, words, eol=eol)
    return _scan_line(body, eol, line, path, params)


def _simple_words(body: str, line: int) -> tuple[Word, ...] | None:
    """Words of a line of words separated by single spaces, or None if a value needs a message
    (as `_plain_words`, without a regex pass: the words are the pieces between the spaces)."""
    words = []
    col = 1
    for piece in body.split(" "):
        text = piece[1:]
        value = float(text)
        letter = piece[0].upper()
        if not math.isfinite(value) or (letter in "GM" and not valid_code(value)):
            return None
        # tuple.__new__ is what Word._make calls, minus its checks: the fields are all here
        words.append(tuple.__new__(Word, (letter, value, text, decimals_written(text), line,
                                          col)))
        col += len(piece) + 1
    return tuple(words)


def _plain_words(body: str, line: int) -> tuple[Word, ...] | None:
    """Words of a line of plain words and comments, or None if a value needs a message.

    The fast path for the bulk of a program: one regex pass, no parameters. Any value the
    scanner would reject (too large, a G/M number with two decimals) returns None, and the
    scanner then reads the line again and raises its message.
    """
    words = []
    for match in _PLAIN_WORD.finditer(body):
        letter = match.group(1)
        if letter is None:
            continue
        text = match.group(2) + match.group(3)
        value = float(text)
        upper = letter.upper()
        if not math.isfinite(value) or (upper in "GM" and not valid_code(value)):
            return None
        words.append(Word(upper, value, text, decimals_written(text), line, match.start() + 1))
    return tuple(words)


def valid_code(value: float) -> bool:
    """G and M numbers: 0 to CODE_LIMIT, at most one decimal."""
    return 0.0 <= value <= CODE_LIMIT and abs(value * 10 - round(value * 10)) <= 1e-6


def _scan_line(body: str, eol: str, line: int, path: str,
               params: Mapping[ParamKey, Param]) -> Block:
    """The full reader of one line: parameters, block delete, `%`, and every error message."""
    scan = _Scanner(body, line, path, params)
    scan.skip_spaces()
    if scan.peek() == "%":
        return Block(line, (), delimiter=True, eol=eol)
    block_delete = False
    if scan.peek() == "/":
        block_delete = True
        scan.pos += 1
        if scan.peek() and scan.peek() in "0123456789":
            scan.pos += 1
    words: list[Word] = []
    assignments: list[Assignment] = []
    while True:
        scan.skip_spaces()
        if scan.at_end():
            break
        char = scan.peek()
        start = scan.pos
        if char == "(":
            close = body.find(")", start)
            if close < 0:
                raise scan.error("comment '(' is not closed by ')' on this line")
            scan.pos = close + 1
        elif char == ";":
            break
        elif char.isalpha() and char.isascii():
            run = _LETTER_RUN.match(body, start)
            if run and run.group().upper() in KEYWORDS:
                raise scan.error(f"'{run.group()}' starts a macro or O-word statement; nurbsfeed "
                                 "reads literal G-code only (no subroutines, IF/WHILE/GOTO or "
                                 "expressions)")
            function = _FUNCTION.match(body, start)
            if function:
                raise scan.error(f"'{function.group(1)}[...]' is an expression; expressions are "
                                 "not supported, write the value as a number")
            letter = char.upper()
            scan.pos += 1
            value, text, decimals = scan.value(letter, start)
            if letter in "GM" and not valid_code(value):
                example = "G6.2" if letter == "G" else "M30"
                raise scan.error(f"{letter}{text} is not a valid {letter} code: a whole number "
                                 f"or one decimal from 0 to 10000 (e.g. {example})", start)
            words.append(Word(letter, value, text, decimals, line, start + 1))
        elif char == "#":
            assign = _ASSIGN.match(body, start)
            if not assign:
                ref = _PARAM_REF.match(body, start)
                if ref:
                    shown = f"#{ref.group(2)}" if ref.group(2) is not None \
                        else f"#<{printable(ref.group(3))}>"
                    raise scan.error(f"'{shown}' must be assigned ({shown}=value) or follow a "
                                     f"letter (X{shown})")
                raise scan.bad_parameter()
            scan.pos = assign.end()
            key = scan.parameter_key(assign.group(1), assign.group(2), start)
            value, _, decimals = scan.value(f"{param_label(key)}=", start)
            assignments.append(Assignment(key, Param(value, decimals), start + 1))
        elif char == "[":
            raise scan.error("expressions in [...] are not supported; write the value as a "
                             "number")
        elif char == "/":
            raise scan.error("'/' (block delete) must be the first character of the line")
        elif char.isdigit() and not char.isascii():
            raise scan.error(f"'{printable(char)}' is not one of the digits 0-9 (full-width and "
                             "other scripts' digits are not G-code numbers)")
        elif char in "0123456789+-.":
            stray = _NUMBER.match(body, start)
            shown = re.sub(_SPACE, "", stray.group()) if stray else char
            raise scan.error(f"'{shown}' has no letter in front of it (a word is a letter and a "
                             "number, e.g. X10.5)")
        else:
            raise scan.error(f"unexpected character '{printable(char)}' (a word is a letter and "
                             "a number, e.g. X10.5)")
    return Block(line, tuple(words), tuple(assignments), block_delete, False, eol)
