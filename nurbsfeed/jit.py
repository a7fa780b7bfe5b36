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
than sit silent. It and `_hold_gc_while_compiling` listen to numba's public event API
(`numba.core.event`). The latter turns Python's garbage collector off while numba compiles: a
compilation allocates objects by the hundred thousand, and every collection they trigger walks
all live objects (numba's own among them), about 2 s of the butterfly's first conversion; held,
the garbage of one compilation is collected after it, for about 20 MB more at the peak.
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
if JIT_ENABLED:
    _hold_gc_while_compiling()


def jit(func: F) -> F:
    """Compile `func` with numba when available; otherwise return it as it is."""
    if _njit is None:
        return func
    return _njit(func)


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
