"""One error hierarchy for everything the user can get wrong, and the exit codes in one table.

Only `cli` turns these into messages and exit codes; every other module raises them.
"""

from __future__ import annotations

from dataclasses import dataclass

EXIT_OK = 0
EXIT_VIOLATION = 1  # `check` found a broken limit
EXIT_BAD_INPUT = 2  # bad usage, bad input file, bad machine profile, an unwritable output
EXIT_SIGNAL_BASE = 128  # stopped by signal N: 128 + N (SIGHUP 129, SIGINT 130, SIGTERM 143)
EXIT_BROKEN_PIPE = EXIT_SIGNAL_BASE + 13  # 141, as if killed by SIGPIPE: stdout's reader left


@dataclass(frozen=True)
class Location:
    """Where in a user's file something is: 1-based line and column."""

    file: str
    line: int | None = None  # None: the file as a whole (e.g. it cannot be read)
    col: int = 1

    def __str__(self) -> str:
        if self.line is None:
            return self.file
        return f"{self.file}:{self.line}:{self.col}"


class NurbsfeedError(Exception):
    """Base of every error nurbsfeed reports to the user (never with a traceback)."""

    exit_code = EXIT_BAD_INPUT


class InputError(NurbsfeedError):
    """Bad input: a message, and where it is once the reader knows."""

    def __init__(self, message: str, location: Location | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.location = location

    def at(self, location: Location) -> InputError:
        """The same error, placed at `location` unless it already has a place."""
        if self.location is not None:
            return self
        return type(self)(self.message, location)

    def __str__(self) -> str:
        if self.location is None:
            return self.message
        return f"{self.location}: {self.message}"


class CurveError(InputError):
    """A NURBS definition that no controller would accept (knots, weights, points)."""


class ProfileError(InputError):
    """A machine profile with a missing, unknown or invalid key."""


class Interrupted(BaseException):
    """SIGINT, SIGTERM or SIGHUP arrived (raised by the CLI's signal handler).

    It unwinds the conversion like an error, so every temporary file is removed on the way out.
    A BaseException, so that no `except Exception` (a batch reporting a file's crash) stops it.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return EXIT_SIGNAL_BASE + self.signum
