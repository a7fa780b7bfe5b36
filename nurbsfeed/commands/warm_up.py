"""The first run of a command after an install: its kernels compile in child processes
(nurbsfeed.jit.compile_in_children), each running the command's warm-up, the same command on the
butterfly under the same profile (`hand_off`), through cli.run_compile_child. Only the console
script's own process hands off (cli.run sets `WarmUp.enabled`): a library caller or a test
compiles in its own process as before.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from nurbsfeed.commands.common import OVERRIDE_KEYS

# samples/butterfly.json, shipped with the package: its conversion runs nearly every kernel a
# conversion runs (after it, any other sample's conversion compiles three more at most)
WARM_UP_CURVE = Path(__file__).with_name("butterfly.json")
# The child's command line: this process's own nurbsfeed first on its path, whatever the
# folder, by the path it was imported by (symbolic links kept: numba's cache is keyed by it).
_CHILD = ("import sys; sys.path.insert(0, {root!r}); "
          "from nurbsfeed.cli import run_compile_child; run_compile_child(sys.argv[1:])")


class WarmUp:
    """Whether this process hands its first run's compiling to children (the console script's
    process only)."""

    enabled = False


def profile_options(kwargs: dict[str, Any]) -> list[str]:
    """The profile options as given (`-m` and each override), for the warm-up's command line;
    before commands.common.machine_from takes them out of `kwargs`."""
    options = ["--machine", str(kwargs["machine"])]
    for key in OVERRIDE_KEYS:
        if kwargs.get(key) is not None:
            options += [f"--{key.replace('_', '-')}", str(kwargs[key])]
    return options


def warm_up(command: str, options: list[str]) -> list[str] | None:
    """The command line of a child that warms up `command` (convert, plan, compare; plot: a
    conversion, which compiles all a plot runs but its figures' own) under `options`; None
    where this process compiles for itself (not the console script's, no numba, no POSIX to
    measure a child's memory with, no interpreter to start)."""
    from nurbsfeed.jit import JIT_ENABLED

    if not (WarmUp.enabled and JIT_ENABLED and os.name == "posix" and sys.executable):
        return None
    conversion = ["convert", str(WARM_UP_CURVE), "-o", os.devnull, "-q"]
    argv = {"convert": conversion, "plot": conversion,
            "plan": ["plan", str(WARM_UP_CURVE)],
            "compare": ["compare", str(WARM_UP_CURVE), "--repeat", "1"]}[command]
    root = str(Path(__file__).absolute().parents[2])
    return [sys.executable, "-c", _CHILD.format(root=root), *argv, *options]


def hand_off(command: list[str] | None, shared: Any = None) -> None:
    """Have this process's first compilation wait for `command` (`warm_up`) to fill the cache;
    nothing for None. `shared`: see nurbsfeed.jit.compile_in_children."""
    if command is not None:
        from nurbsfeed.jit import compile_in_children

        compile_in_children(command, shared)
