"""nurbsfeed.jit: the notice of a long first compile (issue 30); the first run's compiling
handed to child processes (issue 28)."""

from __future__ import annotations

import gc
import json
import multiprocessing
import os
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from nurbsfeed import jit
from tests.conftest import ROOT

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


# Kernels of their own, cached (in the test's NUMBA_CACHE_DIR): `outer` compiles `inner_a` and
# `inner_b` inside its own compilation, as a kernel compiles its callees.
DEMO_KERNELS = """
from nurbsfeed.jit import jit


@jit
def inner_a(x):
    return x * 2.0


@jit
def inner_b(x):
    return x + 0.5


@jit
def outer(x):
    return inner_a(x) - inner_b(x)


@jit
def other(x):
    return x * x


def work():
    return outer(3.0), other(4.0)
"""
# A compile child of the demo: one kernel a child (no room at all), each child noted in `children`.
DEMO_CHILD = """
import os, sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nurbsfeed import jit
with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "children"), "a") as out:
    out.write("child\\n")
jit.compile_child(limit_mb=0.0, modules=("demo_kernels",))
import demo_kernels
demo_kernels.work()
"""
# The process whose first compilation hands off to DEMO_CHILD: what it computed and compiled.
DEMO_PARENT = """
import json, os, sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from numba.core import event
from nurbsfeed import jit
here, depth = [], [0]

class Seen(event.Listener):
    def on_start(self, ev):
        depth[0] += 1
        if ev.data["dispatcher"].py_func.__module__ == "demo_kernels":
            here.append(ev.data["dispatcher"].py_func.__name__)

    def on_end(self, ev):
        depth[0] -= 1

event.register("numba:compile", Seen())
jit.compile_in_children([sys.executable, os.path.join(os.path.dirname(__file__), "child.py")])
import demo_kernels
print(json.dumps({"results": demo_kernels.work(), "compiled_here": here}))
"""


def _demo(tmp_path: Path, cache: Path) -> dict[str, object]:
    for name, text in (("demo_kernels.py", DEMO_KERNELS), ("child.py", DEMO_CHILD),
                       ("parent.py", DEMO_PARENT)):
        (tmp_path / name).write_text(textwrap.dedent(text))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, str(tmp_path / "parent.py")], env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout)  # type: ignore[no-any-return]


def test_the_first_compilation_waits_for_children_to_fill_the_cache(tmp_path: Path) -> None:
    """An empty cache: the first compilation (`outer`) has children compile the run's kernels,
    a kernel each (they have no room), the one ending in the middle of `outer`'s callees
    handing the rest on through the cache; this process compiles only `outer`, whose miss
    started it all, and loads the others. With the cache full, it compiles nothing and starts
    no child. The results are the kernels' either way."""
    cache = tmp_path / "cache"
    first = _demo(tmp_path, cache)
    assert first == {"results": [2.5, 16.0], "compiled_here": ["outer"]}
    # inner_a; inner_b, then `outer` itself once its callees were done; `other`, to the end
    assert len((tmp_path / "children").read_text().split()) == 3
    (tmp_path / "children").unlink()
    assert _demo(tmp_path, cache) == {"results": [2.5, 16.0], "compiled_here": []}
    assert not (tmp_path / "children").exists()


def _child(tmp_path: Path, body: str) -> list[str]:
    """A compile child's command line: `body`, Python, run with `runs` (a file it may count
    its runs in) and `report` (the file listing what it compiled) defined."""
    script = tmp_path / "fake_child.py"
    script.write_text("import os, sys, tempfile\n"
                      f"runs = {str(tmp_path / 'runs')!r}\n"
                      f"report = os.environ[{jit.COMPILE_REPORT_ENV!r}]\n"
                      "with open(runs, 'a') as out:\n"
                      "    out.write('run\\n')\n" + textwrap.dedent(body))
    return [sys.executable, str(script)]


def _runs(tmp_path: Path) -> int:
    return len((tmp_path / "runs").read_text().split())


def test_children_run_until_one_completes_in_a_folder_removed_after_them(
        tmp_path: Path) -> None:
    command = _child(tmp_path, f"""
        with open(tempfile.gettempdir() + "/left", "w"):
            pass
        with open({str(tmp_path / 'folder')!r}, "w") as out:
            out.write(tempfile.gettempdir())
        if len(open(runs).read().split()) < 3:
            with open(report, "a") as out:
                out.write(f"kernel{{len(open(runs).read().split())}}\\n")
            sys.exit({jit.EXIT_COMPILE_MORE})
        """)
    assert jit.fill_cache(command)
    assert _runs(tmp_path) == 3
    folder = (tmp_path / "folder").read_text()
    assert folder != os.environ.get("TMPDIR") and not os.path.exists(folder)


@pytest.mark.parametrize(("body", "runs"), [
    ("sys.exit(2)", 1),  # failed
    (f"sys.exit({jit.EXIT_COMPILE_MORE})", 1),  # ended itself having compiled nothing
    # compiled what the child before it compiled: the cache keeps nothing
    (f"open(report, 'a').write('kernel\\n')\nsys.exit({jit.EXIT_COMPILE_MORE})", 2),
])
def test_children_stop_where_they_make_no_headway(tmp_path: Path, body: str,
                                                   runs: int) -> None:
    assert not jit.fill_cache(_child(tmp_path, body))
    assert _runs(tmp_path) == runs


def test_a_compilation_goes_on_here_when_no_child_can_start(tmp_path: Path) -> None:
    missing = str(tmp_path / "no-such-python")
    assert not jit.fill_cache([missing])
    hand_off = jit.compile_in_children([missing])
    kernel, slow = _fresh_kernel(0.0)
    try:
        assert kernel(20) == 21 and hand_off.done
    finally:
        _unregister(slow)
        _unregister(hand_off)


def test_processes_that_share_the_flag_start_the_children_once(tmp_path: Path) -> None:
    """--jobs workers: the first to compile starts the children, the others find them done."""
    shared = multiprocessing.Value("b", 0)
    command = _child(tmp_path, "")
    hand_offs = [jit.compile_in_children(command, shared) for _ in range(2)]
    kernel, slow = _fresh_kernel(0.0)
    try:
        assert kernel(1) == 2
        assert all(hand_off.done for hand_off in hand_offs) and shared.value == 1
        assert _runs(tmp_path) == 1
    finally:
        _unregister(slow)
        for hand_off in hand_offs:
            _unregister(hand_off)


def _unregister(listener: object) -> None:
    from numba.core import event

    event.unregister("numba:compile", listener)
