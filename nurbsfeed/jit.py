"""The one switch between compiled and plain-Python kernels.

Kernels are written once, in numba's subset. `jit` compiles them with numba when it is installed
and `NURBSFEED_NO_JIT` is not `1`; otherwise it returns them unchanged, so the very same code runs
as plain Python (slowly, but identically).

Compiled code is cached on disk by numba's public `cache=True`; nothing here reaches into numba's
internals, so a numba release can change how its cache works without breaking a conversion (at
worst the kernels compile once more).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TypeVar

F = TypeVar("F", bound=Callable[..., object])


def _numba_njit() -> Callable[[F], F] | None:
    if os.environ.get("NURBSFEED_NO_JIT", "") == "1":
        return None
    try:
        import numba
    except ImportError:
        return None
    return numba.njit(cache=True, nogil=True)  # type: ignore[return-value]


_njit = _numba_njit()
JIT_ENABLED = _njit is not None


def jit(func: F) -> F:
    """Compile `func` with numba when available; otherwise return it as it is."""
    if _njit is None:
        return func
    return _njit(func)
