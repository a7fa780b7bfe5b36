"""A JSON file decoded piece by piece (`JsonText`), for readers.json_curves: a window of its text
from the value being read on, grown only while a value is unfinished, and where each character
of the window is in the file (FILE:LINE:COL), so that an error points at the value or key at
fault.

A JSON file is UTF-8 (RFC 8259): any other byte is refused where it is, as are the constants
JSON does not have (NaN, Infinity), integers too long for int() and nesting deeper than the
decoder follows, each with its location.
"""

from __future__ import annotations

import json
import re
from typing import Any

from nurbsfeed.errors import InputError, Location
from nurbsfeed.files import BOM, InputFile

PIECE_BYTES = 1 << 16  # read at a time; the window grows past it only for a longer value
_WHITESPACE = " \t\n\r"
# the end of the window a value reaching it may continue past (a number, an escape, a literal)
_CUT_MARGIN = 16
_LONG_INTEGER = re.compile(r"[0-9]{4300,}")  # int() refuses more digits (sys.int_info)
_NESTING = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]')


class _NonStandardNumber(ValueError):
    def __init__(self, name: str) -> None:
        super().__init__(f"{name} is not a number JSON allows")
        self.name = name


def _reject_constants(name: str) -> Any:
    raise _NonStandardNumber(name)


_DECODER = json.JSONDecoder(parse_constant=_reject_constants)


class JsonText:
    """A JSON file decoded piece by piece: a window of its text from the value being read on,
    and where each of its characters is in the file."""

    def __init__(self, source: InputFile) -> None:
        self.path = str(source.path)
        self.pieces = source.chunks(PIECE_BYTES)
        self.window = ""
        self.pos = 0  # the next character to read, in the window
        self.line = 1  # the line of window[0] ...
        self.col0 = 0  # ... and its 0-based column
        self.counted = (0, 0)  # (a window index, the newlines before it): locations go forward
        self.undecoded = b""  # the start of a character a piece ended in
        self.ended = False
        self.started = False

    # ---- the window -------------------------------------------------------------------------
    def _more(self) -> bool:
        """Append the next piece to the window; False at the end of the file."""
        piece = next(self.pieces, None)
        if piece is None:
            self.ended = True
            if self.undecoded:
                self._decode(self.undecoded)
            self.undecoded = b""
            return False
        data = self.undecoded + piece
        cut = _complete_utf8(data)
        self.undecoded = data[cut:]
        self._decode(data[:cut])
        return True

    def _decode(self, data: bytes) -> None:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            self.window += data[:exc.start].decode("utf-8")
            raise InputError(f"not UTF-8: byte 0x{data[exc.start]:02X} (a JSON file is UTF-8)",
                             self.location(len(self.window))) from None
        if not self.started:
            self.started = True
            text = text.removeprefix(BOM)  # json refuses it; positions count from after it
        self.window += text

    def release(self) -> None:
        """Forget the text before the read position (what has been read is not looked at)."""
        if self.pos < PIECE_BYTES:
            return
        done = self.window[:self.pos]
        newlines = done.count("\n")
        if newlines:
            self.line += newlines
            self.col0 = self.pos - (done.rfind("\n") + 1)
        else:
            self.col0 += self.pos
        self.window = self.window[self.pos:]
        self.pos = 0
        self.counted = (0, 0)

    def location(self, at: int) -> Location:
        """FILE:LINE:COL of window[at]."""
        newline = self.window.rfind("\n", 0, at)
        col = at - newline if newline >= 0 else self.col0 + at + 1
        since, newlines = self.counted if self.counted[0] <= at else (0, 0)
        newlines += self.window.count("\n", since, at)
        self.counted = (at, newlines)
        return Location(self.path, self.line + newlines, col)

    # ---- reading ----------------------------------------------------------------------------
    def next_char(self) -> str:
        """The next character that is not whitespace ("" at the end), left to be read."""
        while True:
            while self.pos < len(self.window) and self.window[self.pos] in _WHITESPACE:
                self.pos += 1
            if self.pos < len(self.window) or not self._more():
                return self.window[self.pos:self.pos + 1]

    def expect(self, chars: str, what: str) -> str:
        """Read the next character, one of `chars`, else refuse the file with json's `what`."""
        char = self.next_char()
        if not char or char not in chars:
            raise InputError(f"not valid JSON: {what}", self.location(self.pos))
        self.pos += 1
        return char

    def value(self) -> tuple[Any, int, int]:
        """Decode the next value: (value, its start and end in the window)."""
        self.next_char()
        start = self.pos
        while True:
            try:
                value, end = _DECODER.raw_decode(self.window, start)
            except json.JSONDecodeError as exc:
                if self._continues(exc):
                    continue
                raise InputError(f"not valid JSON: {exc.msg}", self.location(exc.pos)) from None
            except _NonStandardNumber as exc:
                found = self.window.find(exc.name, start)
                raise InputError(f"not valid JSON: {exc}",
                                 self.location(found if found >= 0 else start)) from None
            except RecursionError:
                raise InputError("nested deeper than nurbsfeed reads JSON (a curve needs 2 "
                                 "levels of lists)", self.location(self._too_deep(start))) from None
            except ValueError:  # an integer too long for int(): json gives no position
                digits = _LONG_INTEGER.search(self.window, start)
                raise InputError("an integer of more than 4300 digits is out of range",
                                 self.location(digits.start() if digits else start)) from None
            if end < len(self.window) - _CUT_MARGIN or self.ended or not self._grow():
                self.pos = end
                return value, start, end

    def _continues(self, exc: json.JSONDecodeError) -> bool:
        """Whether the value may only be cut by the window's end: then the window grew."""
        near_end = exc.pos >= len(self.window) - _CUT_MARGIN
        return (near_end or exc.msg.startswith("Unterminated string")) and self._grow()

    def _grow(self) -> bool:
        """Double the unread part of the window (a value longer than a piece is read in
        O(its length)); False at the end of the file."""
        wanted = len(self.window) - self.pos
        grew = False
        while len(self.window) - self.pos < 2 * wanted and self._more():
            grew = True
        return grew

    def _too_deep(self, start: int) -> int:
        """Where the nesting of the value at `start` passes the depth json follows."""
        depth = 0
        limit = 900  # below the interpreter's recursion limit, where the decoder stopped
        for match in _NESTING.finditer(self.window, start):
            depth += {"[": 1, "{": 1, "]": -1, "}": -1}.get(match.group(), 0)
            if depth > limit:
                return match.start()
        return start

    def key_location(self, key: str, start: int, end: int) -> Location:
        """Where `"key"` is written in window[start:end] (the value there), else its start."""
        found = self.window.find(f'"{key}"', start, end)
        return self.location(found if found >= 0 else start)


def _complete_utf8(data: bytes) -> int:
    """The length of `data` without the start of a UTF-8 character it may end in."""
    for back in range(1, min(4, len(data)) + 1):
        byte = data[-back]
        if byte < 0x80:
            return len(data)
        if byte >= 0xC0:  # a lead byte: does its character fit?
            size = 2 if byte < 0xE0 else 3 if byte < 0xF0 else 4
            return len(data) if size <= back else len(data) - back
    return len(data)

