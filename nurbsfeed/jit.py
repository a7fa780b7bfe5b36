"""The one switch between compiled and plain-Python kernels.

Kernels are written once, in numba's subset. `jit` compiles them with numba when it is installed
and `NURBSFEED_NO_JIT` is not `1`; otherwise it returns them unchanged, so the very same code runs
as plain Python (slowly, but identically).

Compiled code is cached on disk by numba's public `cache=True`; nothing here reaches into numba's
internals, so a numba release can change how its cache works without breaking a conversion (at
worst the kernels compile once more). A kernel compiles when it first runs, never at import, so
that a command compiles only what it runs.

The first conversion after an install compiles the kernels it runs (`FIRST_COMPILE_S`, measured
with `python -m tests.bench.first_run`); `watch_compiling` lets the command line say so rather
than sit silent. It, `_hold_gc_while_compiling` and the compile children listen to numba's
public event API (`numba.core.event`).

Numba keeps every kernel it compiles, with its LLVM modules, for the life of the process, and
gives none of it back: compiling the butterfly's ~100 kernels took a conversion from 158 MB to
438 MB (170 MB with them loaded from the cache). So the first run compiles in child processes
(`compile_in_children`, armed by the commands: commands.warm_up): the first compilation that
starts in a process waits while children, one at a time, run the command's warm-up and fill
numba's cache, each ending itself (`compile_child`) before a compilation could take it past
COMPILE_CHILD_MB, the next going on from the cache; their memory ends with them, and the process
loads the kernels from the cache as any later run does. Whatever fails there (no child starts,
one fails, the cache keeps nothing) leaves the rest to compile in the process, as before.

`_hold_gc_while_compiling` turns Python's garbage collector off while numba compiles: a
compilation allocates objects by the hundred thousand, and every collection they trigger walks
all live objects (numba's own among them), about 3.5 s of the butterfly's first conversion
compiled in one process; held, the garbage of one compilation is collected after it, for about
36 MB more at the peak there (438 MB against 403 MB). The compile children collect as they go
(`compile_child`): each holds few objects, and its memory is what decides how much it compiles.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
from collections.abc import Callable
from types import ModuleType
from typing import Any, TypeVar, cast

F = TypeVar("F", bound=Callable[..., object])

# seconds the first conversion after an install takes on a 2-core machine (an empty cache)
# (the butterfly, default profile; `python -m tests.bench.first_run`, docs/benchmarks.md)
FIRST_COMPILE_S = 30.0
# A compile child (`compile_in_children`) ends itself at the start of a compilation that could
# take its peak RSS past COMPILE_CHILD_MB: one that adds COMPILE_STEP_MB (the most any adds,
# 12 MB measured, but those `compiles_large` declares), with the child's peak as it stands.
# (MB here: MiB, ru_maxrss / 1024; 250 MiB is 256,000 kB, what /usr/bin/time -v would show.)
COMPILE_CHILD_MB = 250.0
COMPILE_STEP_MB = 15.0
COMPILE_CHILD_TIMEOUT_S = 600.0  # a child stuck this long is ended and the rest compiles here
EXIT_COMPILE_MORE = 75  # a compile child's exit status when it ended itself with more to compile
COMPILE_REPORT_ENV = "NURBSFEED_COMPILE_REPORT"  # the file a compile child lists its kernels in


def _numba_njit() -> Callable[[F], F] | None:
    if os.environ.get("NURBSFEED_NO_JIT", "") == "1":
        return None
    try:
        numba = _import_numba()
    except ImportError:
        return None
    return numba.njit(cache=True, nogil=True)


def _import_numba() -> ModuleType:
    """numba, imported with scipy hidden from it. Where scipy is installed (the test and reference
    extras install it) numba imports it on its own twice: to check its version, and in
    numba.np.arraymath (imported when the first kernel loads) to probe for BLAS, which imports
    scipy.linalg; 0.27 s of the 0.6 s a small conversion takes. The probe decides one thing,
    whether compiled np.correlate and np.convolve call BLAS or a loop of their own, and no
    kernel here uses either; np.dot and np.linalg look for scipy themselves when they compile.
    So both imports happen while sys.modules holds None for scipy, which makes `import scipy`
    raise ImportError (the import system's rule for a None entry), and the entry goes again
    after them: scipy imports as usual for whoever needs it later (plan --reference,
    the tests). If scipy is already imported there is nothing to save."""
    if "scipy" in sys.modules:
        import numba

        return numba
    sys.modules["scipy"] = None  # type: ignore[assignment]
    try:
        import numba
        import numba.np.arraymath  # noqa: F401  (the BLAS probe, see above)
    finally:
        del sys.modules["scipy"]
    return numba


def _hold_gc_while_compiling() -> Any:
    """Turn Python's garbage collector off while numba compiles, from the start of an outermost
    compilation to its end (callees compile inside it), and on again after it unless it was off
    before. Returns the listener (for `numba.core.event.unregister`)."""
    from numba.core import event

    class GcHold(event.Listener):
        depth = 0
        was_enabled = False

        def on_start(self, ev: Any) -> None:
            self.depth += 1
            if self.depth == 1:
                self.was_enabled = gc.isenabled()
                gc.disable()

        def on_end(self, ev: Any) -> None:
            self.depth -= 1
            if self.depth == 0 and self.was_enabled:
                gc.enable()

    hold = GcHold()
    event.register("numba:compile", hold)
    return hold


_njit = _numba_njit()
JIT_ENABLED = _njit is not None
_gc_hold = _hold_gc_while_compiling() if JIT_ENABLED else None


def jit(func: F) -> F:
    """Compile `func` with numba when available; otherwise return it as it is."""
    if _njit is None:
        return func
    return _njit(func)


_compile_mb: dict[Callable[..., object], float] = {}  # python function -> `compiles_large`


def compiles_large(step_mb: float) -> Callable[[F], F]:
    """Declare that compiling the `jit` kernel decorated adds up to `step_mb` to the process's
    peak RSS, more than COMPILE_STEP_MB (a kernel with `inline` kernels compiled into it many
    times): a compile child starts it only with that much room."""

    def mark(kernel: F) -> F:
        _compile_mb[getattr(kernel, "py_func", kernel)] = step_mb
        return kernel

    return mark


def inline(func: F) -> F:
    """`func`, a `jit` kernel, compiled into each kernel that calls it (numba's
    `inline="always"`) rather than called from it; as it is without numba. For the few
    evaluations an inner loop makes at every step: a call costs the loop about as much as a
    short function's work. The arithmetic is the same, operation for operation."""
    python_func = getattr(func, "py_func", func)
    if _njit is None:
        return cast(F, python_func)
    import numba

    return cast(F, numba.njit(cache=True, nogil=True, inline="always")(python_func))


def watch_compiling(after_s: float, notify: Callable[[], None]) -> Any:
    """Call `notify` once, from a timer thread, when numba has spent `after_s` seconds compiling
    in this process (loading kernels from the cache takes milliseconds and does not count).
    Returns the listener (for `numba.core.event.unregister`); None without numba."""
    if not JIT_ENABLED:
        return None
    from numba.core import event

    class CompileWatch(event.Listener):
        """Adds up the time spent in outermost compilations (a kernel's callees compile inside
        it); a timer fires `notify` when the total would reach `after_s` while one runs."""

        depth, spent_s, started = 0, 0.0, 0.0
        timer: threading.Timer | None = None
        fired = False

        def on_start(self, ev: Any) -> None:
            self.depth += 1
            if self.depth == 1:
                self.started = time.perf_counter()
                if not self.fired:
                    self.timer = threading.Timer(max(0.0, after_s - self.spent_s), self.fire)
                    self.timer.daemon = True
                    self.timer.start()

        def on_end(self, ev: Any) -> None:
            self.depth -= 1
            if self.depth == 0:
                self.spent_s += time.perf_counter() - self.started
                if self.timer is not None:
                    self.timer.cancel()
                    self.timer = None

        def fire(self) -> None:
            if not self.fired:
                self.fired = True
                notify()

    watch = CompileWatch()
    event.register("numba:compile", watch)
    return watch


def compile_in_children(command: list[str], shared: Any = None) -> Any:
    """Have the first compilation that starts in this process (a kernel numba found in no
    cache: the first run after an install) wait while `command`, a Python process that runs a
    warm-up under `compile_child`, fills numba's cache; it is started again until it completes,
    each process ending itself before a compilation could take its peak RSS past
    COMPILE_CHILD_MB. This process then loads from the cache what the children compiled, and
    compiles the rest (the kernel that was starting, whatever the warm-up did not run) as
    before.

    Numba keeps every kernel it compiles, and the LLVM modules behind it, for the life of the
    process: compiled in this process, the butterfly's ~100 kernels held 270 MB, which no
    collection gives back; compiled in children, the memory ends with each child.

    Where a child cannot start, fails, or reports a kernel that a child before it compiled (the
    cache kept nothing), the children stop and the rest compiles here. With `shared` (a
    multiprocessing.Value, "b") only the first of the processes that share it starts the
    children, and the others wait for them (--jobs workers). It acts once in a process, at its
    first compilation. Returns the listener (for `numba.core.event.unregister`); None without
    numba."""
    if not JIT_ENABLED:
        return None
    from numba.core import event

    class HandOff(event.Listener):
        done = False

        def on_start(self, ev: Any) -> None:
            if self.done:
                return
            self.done = True
            if shared is None:
                fill_cache(command)
                return
            with shared.get_lock():
                if not shared.value:
                    shared.value = 1
                    fill_cache(command)

        def on_end(self, ev: Any) -> None:
            pass

    hand_off = HandOff()
    event.register("numba:compile", hand_off)
    return hand_off


def fill_cache(command: list[str]) -> bool:
    """Run `command` (see `compile_in_children`), one process at a time, until one completes:
    True; False where one cannot start (or its folder cannot be made), fails, runs past
    COMPILE_CHILD_TIMEOUT_S, or ends itself having compiled nothing or a kernel already
    compiled. The children write their temporary files in a folder of their own (TMPDIR),
    removed after them."""
    import subprocess
    import tempfile

    compiled: set[str] = set()
    try:
        with tempfile.TemporaryDirectory(prefix="nurbsfeed-compile.") as folder:
            report = os.path.join(folder, "kernels")
            env = dict(os.environ, TMPDIR=folder, **{COMPILE_REPORT_ENV: report})
            while True:
                with open(report, "w"):
                    pass
                status = subprocess.run(command, env=env, stdin=subprocess.DEVNULL,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                        timeout=COMPILE_CHILD_TIMEOUT_S).returncode
                with open(report, encoding="utf-8") as listed:
                    kernels = set(listed.read().splitlines())
                if status != EXIT_COMPILE_MORE:
                    return status == 0
                if not kernels or kernels & compiled:
                    return False
                compiled |= kernels
    except (OSError, subprocess.TimeoutExpired):
        return False


def compile_child(limit_mb: float = COMPILE_CHILD_MB,
                  modules: tuple[str, ...] = ("nurbsfeed.",)) -> Any:
    """In a process that `compile_in_children` started: end it, with EXIT_COMPILE_MORE, at the
    start of a compilation that could take its peak RSS past `limit_mb` (its peak so far, plus
    COMPILE_STEP_MB or what `compiles_large` declared), once it has compiled a kernel of
    `modules` (cached on disk: numba saves a kernel before the next compilation starts), so
    that the next child goes on from there with the cache this one filled. Each kernel of
    `modules` compiled here is listed, a line each, in the file COMPILE_REPORT_ENV names.
    Returns the listener."""
    from numba.core import event

    report = os.environ[COMPILE_REPORT_ENV]
    # The collector runs while a child compiles: the garbage a compilation would hold until its
    # end counts in the child's peak (compiling the stepping loop: 43 MB more held, 29 MB
    # collected), and a collection walks only the child's own objects, few: fewer children.
    event.unregister("numba:compile", _gc_hold)

    class Budget(event.Listener):
        compiled = 0

        def on_start(self, ev: Any) -> None:
            step_mb = _compile_mb.get(ev.data["dispatcher"].py_func, COMPILE_STEP_MB)
            if self.compiled and _peak_rss_mb() + step_mb > limit_mb:
                os._exit(EXIT_COMPILE_MORE)

        def on_end(self, ev: Any) -> None:
            func = ev.data["dispatcher"].py_func
            if func.__module__.startswith(modules):
                self.compiled += 1
                with open(report, "a", encoding="utf-8") as listed:
                    listed.write(f"{func.__module__}.{func.__qualname__}{ev.data['args']}\n")

    budget = Budget()
    event.register("numba:compile", budget)
    return budget


def _peak_rss_mb() -> float:
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1 << 20) if sys.platform == "darwin" else peak / 1024  # bytes there, KiB here
