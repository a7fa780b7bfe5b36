"""The one switch between compiled and plain-Python kernels.

Kernels are written once, in numba's subset. `jit` compiles them with numba when it is installed
and `NURBSFEED_NO_JIT` is not `1`; otherwise it returns them unchanged, so the very same code runs
as plain Python (slowly, but identically).

Compiled code is cached on disk (numba's `cache=True`) and loaded by `KernelCache`, which skips
what only compiling needs: the registry refresh numba runs before every cache lookup (~0.15 s of
every run), and the import of the numba modules whose functions were inlined into the kernels
(~0.05 s). Should numba's internals it builds on move, numba's own cache is used instead.
"""

from __future__ import annotations

import os
import sys
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
        from numba.core import environment
        from numba.core.caching import FunctionCache
        from numba.core.runtime import rtsys
        internals = (all(hasattr(FunctionCache, name) for name in (
            "_load_overload", "_guard_against_spurious_io_errors"))
            and all(hasattr(environment, name) for name in ("_rebuild_env", "lookup_environment"))
            and hasattr(environment.Environment, "_memo"))
    except ImportError:
        internals = False
    if not internals:  # not the internals numba 0.68 has: its own cache, with the refresh
        return numba.njit(cache=True, nogil=True)  # type: ignore[no-any-return]

    class KernelCache(FunctionCache):  # type: ignore[misc]
        """numba's on-disk cache, without what only compiling needs.

        Before every lookup numba refreshes its target context: the first refresh imports and
        registers its whole library of typing and lowering rules (~0.15 s, a quarter of a small
        conversion). Code loaded from the cache needs none of them, only the runtime (NRT)
        its arrays live in; a miss goes on to compile, and the compiler refreshes itself.

        Each compiled function carries an environment: its constants and the globals of the
        module it was defined in. Unpickling one imports that module, and the kernels inline
        numba's own array functions (np.empty, np.sort, ...), whose modules register hundreds
        of typing rules on import. Compiled nopython code reads only the constants (the
        globals serve object mode), so while a kernel loads, the environment of a numba
        module not yet imported gets a dictionary with just its name.
        """

        def load_overload(self, sig, target_context):  # type: ignore[no-untyped-def]
            rtsys.initialize(target_context)
            environment._rebuild_env = _rebuild_env_lazily
            try:
                with self._guard_against_spurious_io_errors():
                    return self._load_overload(sig, target_context)
            finally:
                environment._rebuild_env = rebuild_env

    rebuild_env = environment._rebuild_env

    def _rebuild_env_lazily(modname, consts, env_name):  # type: ignore[no-untyped-def]
        """numba's _rebuild_env, without importing a numba module for its globals."""
        if modname in sys.modules or not modname.startswith("numba."):
            return rebuild_env(modname, consts, env_name)
        env = environment.lookup_environment(env_name)
        if env is None:
            env = environment.Environment({"__name__": modname})
            env.consts[:] = consts
            env.env_name = env_name
            environment.Environment._memo[env_name] = env
        return env

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
