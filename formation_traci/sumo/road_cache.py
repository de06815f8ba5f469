"""The fitted reference line of a route kept on disk, so a warm start neither fits it again
nor imports scipy (a warm set-up within about 1 s).

An entry holds what :func:`.road_setup.build_road` gets from fitting: the geometric lanes of
the reference lane along the route, the line's arrays (``ReferenceLine.ARRAYS``) with its
packed buffer ``G`` (road/line_pack.py), and the fit summary. Read back, they are the same
float64 arrays, so a run from a cached line is bit for bit the run from a fitted one.

* **Where**: ``$FORMATION_TRACI_CACHE`` if set (``off`` switches the cache off), else
  ``$NUMBA_CACHE_DIR/formation_traci`` if numba's cache is redirected, else the platform's
  user cache directory (``$XDG_CACHE_HOME`` or ``~/.cache``, ``~/Library/Caches``,
  ``%LOCALAPPDATA%``) ``/formation-traci``. Never the scenario's or the run's directory.
* **Key**: sha256 of the network file's bytes, the route, the reference lane, the fit
  tolerance and settings, the source of the modules that fit, pack and store the line, the
  numpy / scipy / numba / sumolib / Python versions, the machine type and the CPU's SIMD
  features (numpy's). Any change is a new entry.
* **Safety**: written to a temporary file in the same directory and renamed into place
  (concurrent sweep processes writing the same entry are safe); an entry that cannot be read
  or does not match its key is ignored and rebuilt; a cache that cannot be written is skipped.
* **Size**: at most :data:`MAX_ENTRIES` entries; writing one more drops the oldest.
* **Clearing**: delete the directory (``road-<40 hex digits>.npz`` files); pruning touches
  no other file in it.
"""
from __future__ import annotations

import hashlib
import json
import os
import platform
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..road.geometry import ReferenceLine
from ..road.line_pack import keep_packed
from ..core.versions import installed_versions

ENV = "FORMATION_TRACI_CACHE"
"""Environment variable: the cache directory, or ``off``."""
_CODE = ("road/geometry.py", "road/line_fit.py", "road/smoothing.py", "road/coarse.py", "road/band_qp.py",
         "road/bernstein.py", "road/line_pack.py", "road/fast_line.py", "road/lanes.py", "core/kernels.py",
         "sumo/road_cache.py", "sumo/road_setup.py")
"""Modules whose source is part of the key (paths below the package)."""
_CODE_DIGEST: list = []
MAX_ENTRIES = 64
"""Entries kept in the cache directory (a bundled route's entry is ~0.1-1 MB)."""
_OURS = re.compile(r"road-[0-9a-f]{40}\.npz")
"""The names of the entries this module writes (:func:`_path`); pruning touches no other file."""


def cache_dir() -> Path | None:
    """The directory of the road cache (module docstring), None when switched off."""
    env = os.environ.get(ENV)
    if env:
        return None if env.strip().lower() == "off" else Path(env)
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"]) / "formation_traci"
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "formation-traci"


def _code_digest() -> str:
    if not _CODE_DIGEST:
        h = hashlib.sha256()
        root = Path(__file__).resolve().parents[1]
        for rel in _CODE:
            h.update(rel.encode() + (root / rel).read_bytes())
        for dist, v in installed_versions(("numpy", "scipy", "numba", "sumolib")).items():
            h.update(f"{dist}={'?' if v == 'not installed' else v};".encode())
        h.update(f"{sys.version};{platform.machine()};{_cpu_features()}".encode())
        _CODE_DIGEST.append(h.hexdigest())
    return _CODE_DIGEST[0]


def _cpu_features() -> str:
    """The SIMD features numpy's loops may use on this CPU (its math can differ in the last
    bit between CPUs: a cache shared by the machines of a cluster keeps one entry per kind)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # pragma: no cover - another numpy layout
        return platform.processor()
    return ",".join(sorted(name for name, on in features.items() if on))


def entry_key(net_file: str, route: tuple, lane: int, tolerance: float | None, settings: str) -> str:
    """sha256 of everything the fitted line depends on (module docstring); ``settings``:
    the repr of the fit settings (road/smoothing.py)."""
    h = hashlib.sha256()
    h.update(Path(net_file).read_bytes())
    h.update(json.dumps([list(route), int(lane), repr(None if tolerance is None else float(tolerance)), settings,
                         _code_digest()]).encode())
    return h.hexdigest()


def _path(key: str) -> Path | None:
    d = cache_dir()
    return None if d is None else d / f"road-{key[:40]}.npz"


def load(key: str):
    """(lanes, line, fit) of the entry ``key``, or None (absent, unreadable, not this key)."""
    path = _path(key)
    if path is None or not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta["key"] != key:
                return None
            arrays = {name: np.array(z[name], dtype=float) for name in ReferenceLine.ARRAYS}
            G = np.array(z["G"], dtype=float)
        if G.ndim != 1 or not np.isfinite(G[0]):
            return None
        line = ReferenceLine(float(meta["length"]), **arrays)
        keep_packed(line, G)
        return list(meta["lanes"]), line, dict(meta["fit"])
    except Exception:  # noqa: BLE001 - any damaged entry is rebuilt, never an error
        return None


def store(key: str, lanes: list, line: ReferenceLine, G: np.ndarray, fit: dict) -> None:
    """Write the entry ``key`` (temporary file + rename); a failure to write is ignored."""
    path = _path(key)
    if path is None:
        return
    meta = {"key": key, "lanes": list(lanes), "length": line.length, "fit": fit}
    arrays = {name: getattr(line, name) for name in ReferenceLine.ARRAYS}
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".road-", suffix=".tmp",
                                         delete=False) as f:
            tmp = f.name
            np.savez(f, meta=np.array(json.dumps(meta)), G=G, **arrays)
        os.chmod(tmp, 0o644)  # as numba's cache files (a temporary file is private)
        os.replace(tmp, path)
        tmp = None
        _prune(path.parent)
    except OSError:
        pass
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def _prune(directory: Path) -> None:
    """Drop the oldest entries beyond :data:`MAX_ENTRIES` (another process may drop them too)."""
    entries = []
    for p in directory.glob("road-*.npz"):
        if not _OURS.fullmatch(p.name):  # never a file the tool did not write
            continue
        try:
            entries.append((p.stat().st_mtime_ns, p))
        except OSError:
            pass
    for _, p in sorted(entries)[:max(0, len(entries) - MAX_ENTRIES)]:
        try:
            p.unlink()
        except OSError:
            pass
