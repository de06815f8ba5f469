"""Reading cached kernels at less cost per kernel (start-up): two of numba's steps in
loading a kernel from its on-disk cache are skipped when nothing needs them.

* **The module for linking.** Each cached kernel holds its machine code and the LLVM bitcode of
  itself and every kernel it calls (60-320 kB a kernel). numba parses that bitcode on load (~2 ms
  per 100 kB), but needs it only when another library links the kernel in: a compilation in this
  process. :class:`_LazyLinkLibrary` parses it then, not before.
* **Its defined symbols.** numba also lists the symbols the bitcode defines, so that the machine
  code's entry points can be found; the list is kept beside the cache (``symbols-<sha256 of the
  bitcode>.nbsym``, one name a line) the first time, and read from there afterwards.
* **numba's runtime (NRT).** Its few functions are compiled afresh in every process (~20 ms of
  LLVM); :func:`init_runtime` keeps their machine code beside the cache too
  (``nrt-<key>.nbnrt``, keyed by the numba and llvmlite versions and the CPU's name and
  features) and loads it as any cached kernel.

The machine code run is numba's own, read from its own cache: results do not change. Any
surprise (another numba version, an unreadable file) falls back to numba's own way.

This is the one module of the package that reaches into numba's internals: kernels.py's
``@kernel`` hands each dispatcher to :func:`quick_load` and asks :func:`cache_path` where its
cache is.
"""
from __future__ import annotations

import hashlib
import os
import pickle
import tempfile
from pathlib import Path

import llvmlite
import llvmlite.binding as ll
import numba
from numba.core import config
from numba.core.caching import FunctionCache
from numba.core.codegen import JITCodeLibrary
from numba.core.compiler_lock import global_compiler_lock
from numba.core.runtime import _nrt_python, nrt, nrtdynmod

PATTERNS = ("symbols-*.nbsym", "nrt-*.nbnrt")
"""The files this module writes into a kernel cache directory (kernels.py clears them with the
kernels when the package changes)."""


class _LazyLinkLibrary(JITCodeLibrary):
    """A kernel's code library read from the cache whose bitcode is parsed when another library
    links it in (a compilation in this process), not when it is read."""

    _lazy_bitcode = None

    def _get_module_for_linking(self):
        if self._shared_module is None and self._lazy_bitcode is not None:
            self._shared_module = ll.parse_bitcode(self._lazy_bitcode)
            self._lazy_bitcode = None
        return super()._get_module_for_linking()


def _write_atomic(path: Path, data: bytes) -> None:
    """``data`` into ``path`` by a temporary file renamed into place; a cache that cannot be
    written is skipped."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=path.suffix)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError:  # pragma: no cover - read-only cache: numba's own cost next time too
        pass


def _defined_symbols(cache_dir: str, bitcode: bytes):
    """The names the bitcode defines (functions and global variables that are not
    declarations) and the parsed module, or None for it when the names were read from the
    side file."""
    path = Path(cache_dir) / f"symbols-{hashlib.sha256(bitcode).hexdigest()}.nbsym"
    try:
        names = path.read_text(encoding="ascii").split("\n")
        if names and names[-1] == "end":  # a whole file
            return set(names[:-1]), None
    except (OSError, UnicodeDecodeError):
        pass
    mod = ll.parse_bitcode(bitcode)
    names = {gv.name for gvs in (mod.functions, mod.global_variables) for gv in gvs
             if not gv.is_declaration}
    if all(n.isascii() and "\n" not in n for n in names):
        _write_atomic(path, ("\n".join(sorted(names) + ["end"])).encode("ascii"))
    return names, mod


def lazy_unserialize(codegen, cache_dir: str):
    """A replacement of ``codegen.unserialize_library`` for one cached kernel of
    ``cache_dir`` (numba's ``CPUCodeLibrary._unserialize`` of the 'object' kind, less the
    parse), or None when this numba is not the one it was written for."""
    engine = getattr(codegen, "_engine", None)
    if codegen._library_class is not JITCodeLibrary or not isinstance(
            getattr(engine, "_defined_symbols", None), set):
        return None

    def unserialize(state):
        name, kind, data = state
        if kind != "object":
            return type(codegen).unserialize_library(codegen, state)
        object_code, shared_bitcode = data
        lib = codegen.create_library(name)
        lib.__class__ = _LazyLinkLibrary
        lib.enable_object_caching()
        lib._set_compiled_object(object_code)
        names, mod = _defined_symbols(cache_dir, shared_bitcode)
        if mod is None:
            lib._lazy_bitcode = shared_bitcode
        else:
            lib._shared_module = mod
        lib._finalize_final_module()
        engine._defined_symbols |= names
        return lib

    return unserialize


def _runtime_key(codegen) -> str:
    h = hashlib.sha256(repr((numba.__version__, llvmlite.__version__, codegen.magic_tuple(),
                             Path(nrtdynmod.__file__).read_bytes())).encode())
    return h.hexdigest()[:40]


@global_compiler_lock
def init_runtime(target_context, cache_dir: str) -> None:
    """``nrt.rtsys.initialize(target_context)`` with the runtime's machine code kept in
    ``cache_dir`` (module docstring); numba's own initialisation where anything differs."""
    rt = nrt.rtsys
    if rt._init or config.NRT_STATS:
        return nrt.rtsys.initialize(target_context)
    codegen = target_context.codegen()
    path = Path(cache_dir) / f"nrt-{_runtime_key(codegen)}.nbnrt"
    for py_name, c_address in _nrt_python.c_helpers.items():  # as rtsys.initialize does
        ll.add_symbol(py_name if py_name.startswith("_") else "NRT_" + py_name, c_address)
    library = None
    try:
        state = pickle.loads(path.read_bytes())
        if isinstance(state, tuple) and len(state) == 3 and state[1] == "object":
            library = codegen.unserialize_library(state)
    except (OSError, pickle.UnpicklingError, EOFError, ValueError, TypeError):
        library = None
    if library is None:  # compile_nrt_functions, its machine code kept
        ir_mod, library = nrtdynmod.create_nrt_module(target_context)
        library.enable_object_caching()
        library.add_ir_module(ir_mod)
        library.finalize()
        _write_atomic(path, pickle.dumps(library.serialize_using_object_code(), protocol=4))
    rt._library = library
    rt._init = True


class _QuickLoadCache(FunctionCache):
    """numba's cache of a function, loading without the compiler's registries (the cost of a
    warm start: kernels.py's module docstring): ``Cache.load_overload`` minus its
    ``target_context.refresh()``."""

    def load_overload(self, sig, target_context):
        try:
            init_runtime(target_context, self._cache_path)  # the runtime (NRT)
            codegen = target_context.codegen()
            lazy = lazy_unserialize(codegen, self._cache_path)
            if lazy is not None:  # this one load: no parse of the bitcode
                codegen.unserialize_library = lazy
            try:
                with self._guard_against_spurious_io_errors():
                    return self._load_overload(sig, target_context)
            finally:
                if lazy is not None:
                    del codegen.unserialize_library
        except Exception:  # numba's internals moved (another version): its own load (a
            # genuine failure of the cache raises there again, as numba alone would)
            return FunctionCache.load_overload(self, sig, target_context)
        return None  # an I/O error swallowed by the guard: numba compiles


def quick_load(dispatcher) -> None:
    """Make a cached ``njit`` dispatcher read its kernels through :class:`_QuickLoadCache`
    (nothing under ``NUMBA_DISABLE_JIT`` or with another cache)."""
    if type(getattr(dispatcher, "_cache", None)) is FunctionCache:
        dispatcher._cache.__class__ = _QuickLoadCache


def cache_path(dispatcher) -> str | None:
    """The directory of a dispatcher's on-disk cache; None without one (``NUMBA_DISABLE_JIT``,
    no ``cache=True``)."""
    return getattr(getattr(dispatcher, "_cache", None), "cache_path", None)
