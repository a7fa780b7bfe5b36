"""nurbsfeed.jit: the notice of a long first compile (issue 30)."""

from __future__ import annotations

import gc
import threading
import time

import pytest

from nurbsfeed import jit

pytestmark = pytest.mark.skipif(not jit.JIT_ENABLED, reason="numba is not in use")


def _fresh_kernel(seconds: float):  # type: ignore[no-untyped-def]
    """A kernel of its own (never cached), and a hook that makes its compile last `seconds`:
    numba announces the compile, the hook sleeps inside it."""
    import numba
    from numba.core import event

    def body(x):  # type: ignore[no-untyped-def]
        return x + 1

    kernel = numba.njit(cache=False)(body)

    class Slow(event.Listener):
        def on_start(self, ev):  # type: ignore[no-untyped-def]
            if ev.data["dispatcher"] is kernel:
                time.sleep(seconds)

        def on_end(self, ev):  # type: ignore[no-untyped-def]
            pass

    listener = Slow()
    event.register("numba:compile", listener)
    return kernel, listener


def test_a_compile_longer_than_the_threshold_is_announced_once() -> None:
    fired: list[float] = []
    done = threading.Event()

    def notify() -> None:
        fired.append(time.perf_counter())
        done.set()

    start = time.perf_counter()
    watch = jit.watch_compiling(0.2, notify)
    first, slow = _fresh_kernel(1.0)
    try:
        first(1)  # 1 s: past the threshold while it compiles
        assert done.wait(2.0) and 0.2 <= fired[0] - start < 0.9
        second, slower = _fresh_kernel(0.5)
        try:
            second(2.0)
        finally:
            _unregister(slower)
        time.sleep(0.3)
        assert len(fired) == 1  # one notice a process, however much more compiles
    finally:
        _unregister(slow)
        _unregister(watch)


def test_short_compiles_add_up_to_the_threshold() -> None:
    """Two compiles of about 0.5 s stay under a 2 s threshold (room for a loaded machine's
    compile), a third of 1.5 s passes it: the threshold counts the time spent compiling, not
    the number of kernels."""
    fired: list[int] = []
    listeners = [jit.watch_compiling(2.0, lambda: fired.append(1))]
    try:
        for value in (1, 2):
            kernel, listener = _fresh_kernel(0.4)
            listeners.append(listener)
            kernel(value)
        time.sleep(0.2)
        assert fired == []
        kernel, listener = _fresh_kernel(1.5)
        listeners.append(listener)
        kernel(3)
        assert fired == [1]
    finally:
        for listener in listeners:
            _unregister(listener)


def test_the_garbage_collector_is_off_while_numba_compiles_and_as_it_was_after() -> None:
    """On during a compile only if it was on before: off inside the compile (the kernel's
    compile hook sees it), back on after; left off after if it was off before."""
    from numba.core import event

    seen: list[bool] = []

    class Probe(event.Listener):
        def on_start(self, ev):  # type: ignore[no-untyped-def]
            seen.append(gc.isenabled())

        def on_end(self, ev):  # type: ignore[no-untyped-def]
            pass

    probe = Probe()
    event.register("numba:compile", probe)
    was_enabled = gc.isenabled()
    try:
        gc.enable()
        kernel, slow = _fresh_kernel(0.0)
        _unregister(slow)
        kernel(1)
        assert seen == [False] and gc.isenabled()
        gc.disable()
        kernel(1.5)  # a second signature: a second compile
        assert seen == [False, False] and not gc.isenabled()
    finally:
        _unregister(probe)
        if was_enabled:
            gc.enable()
        else:
            gc.disable()


def _unregister(listener: object) -> None:
    from numba.core import event

    event.unregister("numba:compile", listener)
