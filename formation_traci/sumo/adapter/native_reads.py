"""The C++ extension ``_sumo_reads`` (sumo/adapter/native/sumo_reads.cpp), built on first use: the
members' and neighbours' subscription rows as numpy tables and the members' moves through the
libsumo C++ API inside the loaded ``libsumo/_libsumo.so`` (the same SUMO), without SWIG's
conversion to Python objects and their extraction (benchmarks/RESULTS.md). :func:`load` returns the module or None (then the
caller keeps the SWIG path; :data:`REASON` says why). This module imports neither libsumo nor
traci: the caller (sumo/adapter/__init__.py) gives the path of ``_libsumo.so`` (``_libsumo.__file__``).

* **Off**: ``FORMATION_TRACI_NATIVE=off``.
* **Needs**: a C++17 compiler (``$CXX``, else ``g++`` / ``c++`` on PATH), ``Python.h``, the
  SUMO headers of the eclipse-sumo wheel of libsumo's version, numpy's headers, and
  ``_libsumo.so`` already loaded (imported) by the caller.
* **Where**: ``native/`` in the road cache's directory (sumo/road_cache.py ``cache_dir``),
  file ``_sumo_reads-<key>`` + the extension suffix. Key: sha256 of the source, the libsumo
  version, the path, size and mtime of ``_libsumo.so``, the extension suffix, numpy's version,
  the compiler's ``--version`` line and the flags. Built into a temporary file in that
  directory and renamed into place (concurrent first runs of a sweep are safe).
* **Cache off** (``FORMATION_TRACI_CACHE=off``) or not writable: built into a temporary
  directory, imported and deleted, in every process that loads it (~3 s each).
* One build per process at most: the result (module or None) is kept per path.
"""
from __future__ import annotations

import hashlib
import importlib.metadata as md
import importlib.util
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

ENV = "FORMATION_TRACI_NATIVE"
"""Environment variable: ``off`` switches the extension off."""
SOURCE = Path(__file__).resolve().parent / "native" / "sumo_reads.cpp"
NAME = "_sumo_reads"
TIMEOUT = 60.0
"""Seconds the compiler may take (then the SWIG path, as for any failed build)."""
NOTICE = "formation-traci: building the C++ reads of libsumo"
"""The build notice's first words (stderr; tests look for them)."""
REASON = ""
"""Why the last :func:`load` returned None ('' when it returned the module)."""
COMMAND: list[str] = []
"""The compile command of the last build or key (``-o`` target last)."""
_LOADED: dict[str, tuple] = {}  # path -> (module or None, reason)


class _Unavailable(Exception):
    """Something the extension needs is missing (the message is the reason)."""


def load(libsumo_so: str):
    """The extension attached to the loaded ``libsumo_so``, or None (module docstring)."""
    global REASON
    if os.environ.get(ENV, "").strip().lower() == "off":
        REASON = f"{ENV}=off"
        return None
    if libsumo_so not in _LOADED:
        try:
            mod = _build_and_import(libsumo_so)
            error = getattr(sys.modules.get("libsumo"), "TraCIException", None)  # not imported here
            mod.attach(libsumo_so, error)
            _LOADED[libsumo_so] = mod, ""
        except Exception as exc:  # anything missing or failing: the SWIG path
            _LOADED[libsumo_so] = None, f"{type(exc).__name__}: {exc}"
    mod, REASON = _LOADED[libsumo_so]
    return mod


def _command(libsumo_so: str) -> tuple[list[str], str]:
    """The compile command (without ``-o``) and the key of its product."""
    import numpy
    import sumo
    versions = md.version("libsumo"), md.version("eclipse-sumo")
    if versions[0] != versions[1]:
        raise _Unavailable(f"libsumo {versions[0]} but SUMO headers (eclipse-sumo) {versions[1]}")
    inc_sumo = Path(sumo.SUMO_HOME) / "include"
    inc_py = Path(sysconfig.get_paths()["include"])
    cxx = shlex.split(os.environ.get("CXX", "")) or [shutil.which("g++") or shutil.which("c++")]
    if not cxx[0]:
        raise _Unavailable("no C++ compiler ($CXX, g++, c++)")
    if not (inc_py / "Python.h").is_file():
        raise _Unavailable(f"no Python.h in {inc_py}")
    if not (inc_sumo / "libsumo" / "Vehicle.h").is_file():
        raise _Unavailable(f"no SUMO headers in {inc_sumo}")
    try:
        out = subprocess.run([*cxx, "--version"], capture_output=True, text=True, timeout=TIMEOUT)
        cxx_version = (out.stdout.splitlines() or [""])[0]
    except (OSError, subprocess.SubprocessError) as exc:
        raise _Unavailable(f"compiler {' '.join(cxx)}: {exc}") from exc
    cmd = [*cxx, "-std=c++17", "-O2", "-fPIC", "-shared", "-D_GLIBCXX_USE_CXX11_ABI=1", f"-I{inc_py}",
           f"-I{numpy.get_include()}", f"-I{inc_sumo}", str(SOURCE), "-ldl"]
    st = os.stat(libsumo_so)
    key = hashlib.sha256(SOURCE.read_bytes())
    for part in (versions[0], libsumo_so, st.st_size, st.st_mtime_ns, _suffix(), numpy.__version__,
                 cxx_version, *cmd[len(cxx):]):  # the compiler by its --version line, not its path
        key.update(f"|{part}".encode())
    return cmd, key.hexdigest()[:32]


def _suffix() -> str:
    return sysconfig.get_config_var("EXT_SUFFIX") or ".so"


def _compile(cmd: list[str], target: Path) -> None:
    """Compile into a temporary file next to ``target``, then rename it into place; says so
    on stderr before (with the bound, :data:`TIMEOUT`) and after (how long it took)."""
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".tmp-" + NAME, suffix=_suffix())
    os.close(fd)
    COMMAND[:] = [*cmd, "-o", tmp]
    print(f"{NOTICE} (first run only, cached afterwards): 3-7 s, at most {TIMEOUT:.0f} s",
          file=sys.stderr, flush=True)
    t0 = time.monotonic()
    try:
        out = subprocess.run(COMMAND, capture_output=True, text=True, timeout=TIMEOUT)
    except (OSError, subprocess.SubprocessError) as exc:
        os.unlink(tmp)
        print(f"formation-traci: the C++ reads not built ({exc}); libsumo's Python API is used",
              file=sys.stderr, flush=True)
        raise _Unavailable(f"build failed: {exc}") from exc
    print(f"formation-traci: the C++ reads built in {time.monotonic() - t0:.1f} s"
          + ("" if out.returncode == 0 else " with errors; libsumo's Python API is used"),
          file=sys.stderr, flush=True)
    try:
        if out.returncode != 0:
            raise _Unavailable(f"build failed ({out.returncode}): {(out.stderr or out.stdout)[-2000:]}")
        os.replace(tmp, target)  # atomic: a parallel first run sees the whole file or none
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _build_and_import(libsumo_so: str):
    from ..road_cache import cache_dir
    cmd, key = _command(libsumo_so)
    name, base = f"{NAME}-{key}{_suffix()}", cache_dir()
    if base is not None:
        target = base / "native" / name
        try:
            if not target.is_file():
                target.parent.mkdir(parents=True, exist_ok=True)
                _compile(cmd, target)
        except OSError:  # a cache that cannot be written: as if it were off
            pass
        else:
            COMMAND[:] = [*cmd, "-o", str(target)]
            return _import(target)
    with tempfile.TemporaryDirectory(prefix="formation-traci-native-") as tmp:
        target = Path(tmp) / name
        _compile(cmd, target)
        return _import(target)  # the loaded file may go: it stays mapped


def _import(path: Path):
    spec = importlib.util.spec_from_file_location(NAME, path)  # PyInit__sumo_reads
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
