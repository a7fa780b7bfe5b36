"""Files: input read as a stream of lines that round-trips byte for byte, and output that reaches
its file only whole.

Input is decoded as UTF-8 with surrogateescape: a byte that is not UTF-8 becomes a lone
surrogate and is encoded back to the same byte, so a pass-through line is copied exactly. A line
keeps its ending ("\\n" or "\\r\\n"; a lone "\\r" inside a line is part of it). A file whose lines
all end in "\\r" alone (classic Mac OS) would read as one line and convert nothing, so "\\r" ends
the lines of a file whose first LOOK_AHEAD_BYTES hold a "\\r" and no "\\n"; a "\\n" that follows
in such a file is refused rather than guessed at.

Output goes to a temporary file beside the target and is renamed into place only when the whole
conversion succeeded (a device or FIFO is written into from a temporary file at the end, never
replaced).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import secrets
import shutil
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO, cast

from nurbsfeed.errors import InputError, Location

ENCODING = "utf-8"
ERRORS = "surrogateescape"  # any byte sequence round-trips unchanged
BOM = "\ufeff"
LOOK_AHEAD_BYTES = 1 << 20  # what decides the line ending, and JSON or G-code


class InputFile:
    """An input file, read as a stream each time `lines()` or `chunks()` is called (the file is
    open only while one is read); `head`: its first LOOK_AHEAD_BYTES.

    `content`: the bytes to read instead of the file at `path` (a program held in memory). A file
    that is not a regular file (a pipe: `<(command)`) is read whole into `content` when opened,
    since it cannot be read twice.
    """

    def __init__(self, path: Path, content: bytes | None = None) -> None:
        self.path = path
        self.content = content
        if content is None:
            try:
                with open(path, "rb") as handle:
                    if stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
                        self.head = handle.read(LOOK_AHEAD_BYTES)
                        return
                    content = self.content = handle.read()
            except OSError as exc:
                raise _cannot_read(path, exc) from None
        self.head = content[:LOOK_AHEAD_BYTES]

    def _open(self) -> BinaryIO:
        if self.content is not None:
            return io.BytesIO(self.content)
        try:
            return open(self.path, "rb")
        except OSError as exc:
            raise _cannot_read(self.path, exc) from None

    @property
    def cr_only(self) -> bool:
        """Whether the lines end in "\\r" alone (module docstring)."""
        return b"\n" not in self.head and b"\r" in self.head

    def lines(self) -> Iterator[str]:
        """The lines, each with its ending, in file order (module docstring)."""
        cr_only = self.cr_only
        text = io.TextIOWrapper(self._open(), ENCODING, ERRORS, newline="\r" if cr_only else "\n")
        with text:
            for number, line in enumerate(_reporting_read_errors(self.path, text), start=1):
                if cr_only and "\n" in line:
                    raise InputError("a line ending in LF in a file whose lines end in CR alone "
                                     "(classic Mac OS): write every line ending the same way",
                                     Location(str(self.path), number, line.index("\n") + 1))
                yield line

    def chunks(self, size: int) -> Iterator[bytes]:
        """The bytes, in pieces of `size` (the last one shorter)."""
        with self._open() as handle:
            yield from _reporting_read_errors(self.path, iter(lambda: handle.read(size), b""))


def _reporting_read_errors(path: Path, pieces: Iterator) -> Iterator:
    """`pieces`, with a failing read (EIO, a file truncated under us) reported as unreadable
    input: an OSError on its way out would read as an output error."""
    while True:
        try:
            piece = next(pieces)
        except StopIteration:
            return
        except OSError as exc:
            raise _cannot_read(path, exc) from None
        yield piece


def _cannot_read(path: Path, exc: OSError) -> InputError:
    return InputError(f"cannot read input ({exc.strerror or exc})", Location(str(path)))


def read_text(path: Path) -> str:
    """The whole file as text that round-trips byte for byte (line endings kept), for the
    analyses that compare two programs line by line; a conversion streams (`InputFile`)."""
    try:
        with open(path, encoding=ENCODING, errors=ERRORS, newline="") as handle:
            return handle.read()
    except OSError as exc:
        raise _cannot_read(path, exc) from None


def _umask_mode() -> int:
    """0666 less the process umask: the mode `open()` would give a new file."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


_CREATE_MODE = _umask_mode()
# Names of an open descriptor (Linux, BSD): whatever file is behind them belongs to the shell's
# redirection, so it is written into, never replaced (`-o /dev/stdout >> log` must append).
_DESCRIPTOR_PATH = re.compile(r"/dev/(stdout|stderr|fd/\d+)|/proc/(self|thread-self|\d+)/fd/\d+")
# O_EXCL: a name taken since `_temporary_name` looked fails rather than being shared.
_TEMPORARY_FLAGS = os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
_LIVE: set[str] = set()  # the temporary outputs this process holds (atomic_output)
_KIND_NAMES = {stat.S_IFDIR: "a directory", stat.S_IFBLK: "a block device",
               stat.S_IFSOCK: "a socket"}


def output_target(path: Path) -> tuple[Path, bool]:
    """Where output named `path` goes, and whether it is written through rather than replaced.

    A new name or a regular file is replaced atomically (temporary file + rename); behind a
    symbolic link, the file it points to is (the link stays). A character device (/dev/null, a
    terminal), a FIFO or a descriptor's name (/dev/stdout) is opened and written, never replaced.
    Anything else (a directory, a block device, a socket, a link to nothing) is refused: nurbsfeed
    never replaces a file that is not a regular file.
    """
    where = Location(str(path))
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        if os.path.islink(path):
            raise InputError(f"cannot write output: a symbolic link to {os.readlink(path)}, "
                             "which does not exist", where) from None
        if not path.parent.is_dir():
            raise InputError(f"cannot write output: directory {path.parent} does not exist",
                             where) from None
        return path, False
    except OSError as exc:
        raise InputError(f"cannot write output ({exc.strerror})", where) from None
    if (stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)
            or _DESCRIPTOR_PATH.fullmatch(os.path.abspath(path))):
        return path, True
    if stat.S_ISREG(mode):
        return Path(os.path.realpath(path)), False
    kind = _KIND_NAMES.get(stat.S_IFMT(mode), "not a regular file")
    raise InputError(f"cannot write output: it is {kind} (nurbsfeed writes regular files, "
                     "character devices and FIFOs)", where)


@contextlib.contextmanager
def atomic_output(path: Path | None) -> Iterator[BinaryIO]:
    """A binary stream whose content reaches `path` only if the block completes.

    Always a temporary file first, removed on every way out (an error, an exception from a
    signal): renamed onto `path` (see `output_target`), or copied into it when `path` is written
    through; None: the caller copies it out (stdout). A failure never leaves partial output.
    """
    final, through = output_target(path) if path is not None else (None, False)
    folder = final.parent if final is not None and not through else None
    prefix = f".{final.name}." if final is not None and folder else "nurbsfeed."
    # A stop signal (cli turns it into an exception) can land anywhere, even inside the call
    # that creates the file (a signal mask does not help: another thread takes the signal and
    # the handler still runs here): the name is known and held before the file exists.
    handle = name = None
    try:
        name = _temporary_name(folder, prefix)
        handle = os.fdopen(os.open(name, _TEMPORARY_FLAGS, 0o600), "w+b")
        with handle:
            yield cast(BinaryIO, handle)
            handle.flush()
            if through and final is not None:
                handle.seek(0)
                with open(os.open(final, os.O_WRONLY | os.O_APPEND), "ab") as sink:
                    shutil.copyfileobj(handle, sink, 1 << 20)
            elif final is not None:
                os.fsync(handle.fileno())
        if folder is not None and final is not None:
            if os.path.lexists(final) and not stat.S_ISREG(os.lstat(final).st_mode):
                raise InputError("cannot write output: it is no longer a regular file",
                                 Location(str(path)))  # swapped since output_target looked
            os.chmod(name, _CREATE_MODE)  # a temp file is 0600; a new file is not
            os.replace(name, final)
        else:
            os.unlink(name)
        _LIVE.discard(name)
    except BaseException:
        if handle is not None:
            handle.close()
        if name is not None:
            with contextlib.suppress(OSError):
                os.unlink(name)
            _LIVE.discard(name)
        raise


def _temporary_name(folder: Path | None, prefix: str) -> str:
    """A new name for a temporary output in `folder` (None: the system's temporary folder),
    registered in _LIVE before anything is created under it."""
    where = str(folder) if folder is not None else tempfile.gettempdir()
    while True:
        name = os.path.join(where, f"{prefix}{secrets.token_hex(4)}.part")
        if not os.path.lexists(name) and name not in _LIVE:
            _LIVE.add(name)
            return name


def remove_live_temporaries() -> None:
    """Remove every temporary output this process still holds. A stop signal that lands in
    the instant between the file's creation and the caller's `with` holding it (inside
    contextlib's __enter__) leaves the cleanup above no frame to run in: the signal's exit
    path calls this (cli.run). A name registered whose file was never created is skipped."""
    for name in list(_LIVE):
        with contextlib.suppress(OSError):
            os.unlink(name)
        _LIVE.discard(name)
