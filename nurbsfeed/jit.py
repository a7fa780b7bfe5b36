"""The one switch between compiled and plain-Python kernels.

Kernels are written once, in numba's subset. `jit` compiles them with numba when it is installed
and `NURBSFEED_NO_JIT` is not `1`; otherwise it returns them unchanged, so the very same code runs
as plain Python (slowly, but identically).

Compiled code is cached on disk (numba's `cache=True`) and loaded by `KernelCache`, which skips
what only compiling needs: the registry refresh numba runs before every cache lookup (~0.15 s of
every run), the import of the numba modules whose functions were inlined into the kernels
(~0.05 s), and the parsing of each library's IR (~0.05 s). Should numba's internals it builds on
move, numba's own cache is used instead.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., object])


def _numba_njit() -> Callable[[F], F] | None:
    if os.environ.get("NURBSFEED_NO_JIT", "") == "1":
        return None
    try:
        import numba
    except ImportError:
        return None
    try:
        import llvmlite.binding as ll
        from numba.core import codegen, environment
        from numba.core.caching import FunctionCache
        from numba.core.runtime import rtsys
    except ImportError:
        return numba.njit(cache=True, nogil=True)  # type: ignore[no-any-return]
    internals = (
        all(hasattr(FunctionCache, name)
            for name in ("_load_overload", "_guard_against_spurious_io_errors"))
        and all(hasattr(environment, name) for name in ("_rebuild_env", "lookup_environment"))
        and hasattr(environment.Environment, "_memo")
        and all(hasattr(codegen.JITCodeLibrary, name)
                for name in ("_unserialize", "enable_object_caching", "_set_compiled_object",
                             "_finalize_final_module", "_ensure_finalized"))
        and getattr(codegen.JITCPUCodegen, "_library_class", None) is codegen.JITCodeLibrary)
    if not internals:  # not the internals numba 0.68 has: its own cache, with the refresh
        return numba.njit(cache=True, nogil=True)  # type: ignore[no-any-return]

    class LoadedLibrary(codegen.JITCodeLibrary):  # type: ignore[misc]
        """A kernel's compiled library as loaded from the cache, its IR parsed on first use.

        A cached library holds its object code and its IR. numba loads the object code, then
        parses the IR (the "shared module", which code compiled later links in) and walks its
        symbols, which is most of the loading. Here the IR stays bytes until something asks for
        it, which a conversion never does; a symbol of the library is looked up if the object
        code names it, where numba would look among the symbols of the IR.
        """

        _shared_bitcode: bytes | None = None
        _object_code = b""

        @property
        def _shared_module(self) -> Any:
            if self._shared_bitcode is not None:
                self.__dict__["_shared_ir"] = ll.parse_bitcode(self._shared_bitcode)
                self._shared_bitcode = None
            return self.__dict__.get("_shared_ir")

        @_shared_module.setter
        def _shared_module(self, module: Any) -> None:
            self.__dict__["_shared_ir"] = module

        @classmethod
        def _unserialize(cls, cg: Any, state: Any) -> Any:
            name, kind, data = state
            if kind != "object":  # (the cache writes object code only)
                return codegen.JITCodeLibrary._unserialize(cg, state)
            object_code, shared_bitcode = data
            library = cls(cg, name)
            library._object_code = object_code  # (numba drops its reference once loaded)
            library.enable_object_caching()
            library._set_compiled_object(object_code)
            library._shared_bitcode = shared_bitcode
            library._finalize_final_module()
            return library

        def get_pointer_to_function(self, name: str) -> int:
            if not self._object_code:  # not loaded by `_unserialize` from object code
                return int(super().get_pointer_to_function(name))
            if name.encode() not in self._object_code:
                return 0  # not a symbol of this library
            self._ensure_finalized()
            return int(self._codegen._engine.get_function_address(name))

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

        The library itself is loaded as a `LoadedLibrary`.
        """

        def load_overload(self, sig, target_context):  # type: ignore[no-untyped-def]
            rtsys.initialize(target_context)
            cg = target_context.codegen()
            environment._rebuild_env = _rebuild_env_lazily
            cg._library_class = LoadedLibrary  # for this load only (under numba's compile lock)
            try:
                with self._guard_against_spurious_io_errors():
                    return self._load_overload(sig, target_context)
            finally:
                environment._rebuild_env = rebuild_env
                del cg._library_class

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
