"""The one switch between compiled and plain-Python kernels.

Kernels are written once, in numba's subset. `jit` compiles them with numba when it is installed
and `NURBSFEED_NO_JIT` is not `1`; otherwise it returns them unchanged, so the very same code runs
as plain Python (slowly, but identically).

Compiled code is cached on disk (numba's `cache=True`) and loaded by `KernelCache`, which skips
the registry refresh numba runs before every cache lookup: loading needs none of it, and the
first refresh costs ~0.15 s of every run. Should numba's internals it builds on move, numba's own
cache is used instead.
"""

from __future__ import annotations

import os
from typing import Callable, TypeVar

F = TypeVar("F", bound=Callable[..., object])


def _numba_njit() -> Callable[[F], F] | None:
    if os.environ.get("NURBSFEED_NO_JIT", "") == "1":
        return None
    try:
        import numba
    except ImportError:
        return None
    try:
        from numba.core.caching import FunctionCache
        from numba.core.runtime import rtsys
        internals = all(hasattr(FunctionCache, name) for name in (
            "_load_overload", "_guard_against_spurious_io_errors"))
    except ImportError:
        internals = False
    if not internals:  # not the internals numba 0.68 has: its own cache, with the refresh
        return numba.njit(cache=True, nogil=True)  # type: ignore[no-any-return]

    class KernelCache(FunctionCache):  # type: ignore[misc]
        """numba's on-disk cache, without the registry refresh before each lookup.

        Before every lookup numba refreshes its target context: the first refresh imports and
        registers its whole library of typing and lowering rules (~0.15 s, a quarter of a small
        conversion). Code loaded from the cache needs none of them, only the runtime (NRT)
        its arrays live in; a miss goes on to compile, and the compiler refreshes itself.
        """

        def load_overload(self, sig, target_context):  # type: ignore[no-untyped-def]
            rtsys.initialize(target_context)
            with self._guard_against_spurious_io_errors():
                return self._load_overload(sig, target_context)

    compile_ = numba.njit(nogil=True)

    def njit(func: F) -> F:
        dispatcher = compile_(func)
        dispatcher._cache = KernelCache(func)  # what njit(cache=True) sets, but KernelCache
        return dispatcher  # type: ignore[no-any-return]

    return njit


_njit = _numba_njit()
JIT_ENABLED = _njit is not None


def jit(func: F) -> F:
    """Compile `func` with numba when available; otherwise return it as it is."""
    if _njit is None:
        return func
    return _njit(func)
