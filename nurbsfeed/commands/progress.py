"""On a terminal: the status line of a batch being converted (`Progress`), and the notice that
the kernels compile once after an install (`Notice`, `watch_compiling`), shown above it.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

PROGRESS_TICK_S = 0.5  # under --jobs, the status line's clock moves on this often
COMPILE_NOTICE_AFTER_S = 1.0  # compiling longer than this says so (once a run)


class Notice:
    """Whether the compile notice may show (not under -q), and, in a --jobs worker, the flag
    the workers share so that it shows once for all of them; the status line of the batch being
    converted, if any, which the notice is written above."""

    quiet = False
    watching = False
    shared: Any = None
    progress: Progress | None = None


def _say_compiling() -> None:
    if Notice.quiet:
        return
    if Notice.shared is not None:
        with Notice.shared.get_lock():
            if Notice.shared.value:
                return
            Notice.shared.value = 1
    from nurbsfeed.jit import FIRST_COMPILE_S

    text = f"nurbsfeed: compiling nurbsfeed's kernels once after install, ~{FIRST_COMPILE_S:.0f} s"
    if Notice.progress:
        Notice.progress.message(text)
    else:
        sys.stderr.write(text + "\n")
        sys.stderr.flush()


def watch_compiling() -> None:
    if not Notice.watching:
        Notice.watching = True
        from nurbsfeed.jit import watch_compiling

        watch_compiling(COMPILE_NOTICE_AFTER_S, _say_compiling)


def compile_notice_shared() -> Any:
    """The flag --jobs workers share to show the compile notice once (None: do not show it)."""
    if Notice.quiet:
        return None
    import multiprocessing

    return multiprocessing.Value("b", 0)


class Progress:
    """One status line on stderr, rewritten in place (only when stderr is a terminal): files
    done of total, points written, elapsed time and time left.

    The fraction done counts input bytes: those of the files finished, plus, for the file being
    converted in this process, its share up to the source line of the last converted curve
    (cheap, monotone, and right for programs whose curves are spread through the file). Time
    left is the elapsed time scaled by the fraction still to do.
    """

    def __init__(self, sources: list[Path]) -> None:
        self.sizes = [_size(source) for source in sources]
        self.total = max(1, sum(self.sizes))
        self.files, self.files_done, self.bytes_done, self.points = len(sources), 0, 0, 0
        self.current, self.current_points = 0.0, 0  # the file being converted here
        self.lines = 1
        self.start = time.monotonic()
        self.last = -1.0
        self.lock = threading.Lock()  # the compile notice comes from a timer thread

    def file_started(self, source: Path) -> None:
        self.current, self.current_points = 0.0, 0
        self.lines = _line_count(source)

    def curve_done(self, result: Any) -> None:
        self.current = min(1.0, (result.location.line or 1) / self.lines)
        self.current_points += result.n_points
        self.show()

    def file_done(self, index: int, points: int) -> None:
        self.files_done += 1
        self.bytes_done += self.sizes[index]
        self.points += points
        self.current, self.current_points = 0.0, 0
        self.show(force=True)

    def show(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self.last < 0.1:
            return
        self.last = now
        elapsed_s = now - self.start
        done = min(1.0, (self.bytes_done + self.current * self.sizes[
            min(self.files_done, self.files - 1)]) / self.total)
        left = (f"~{_duration(elapsed_s * (1.0 - done) / done)} left" if done > 0.0
                else "time left unknown")
        self._write(f"\r{self.files_done} of {self.files} files, "
                    f"{self.points + self.current_points:,} points, "
                    f"{_duration(elapsed_s)} elapsed, {left}\033[K")

    def message(self, text: str) -> None:
        """A line of its own above the status line."""
        self._write(f"\r\033[K{text}\n")
        self.last = -1.0

    def close(self) -> None:
        self._write("\r\033[K")

    def _write(self, text: str) -> None:
        with self.lock:
            sys.stderr.write(text)
            sys.stderr.flush()


def _size(path: Path) -> int:
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


def _line_count(path: Path) -> int:
    try:
        with open(path, "rb") as handle:
            return max(1, sum(chunk.count(b"\n") for chunk in
                              iter(lambda: handle.read(1 << 20), b"")))
    except OSError:
        return 1


def _duration(seconds: float) -> str:
    """12 s, 3 min 05 s, 1 h 02 min."""
    whole = int(round(seconds))
    if whole < 60:
        return f"{whole} s"
    if whole < 3600:
        return f"{whole // 60} min {whole % 60:02d} s"
    return f"{whole // 3600} h {whole % 3600 // 60:02d} min"

