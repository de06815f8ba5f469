"""The shared warm-up cache on disk: where it may be, what an entry holds, and how an entry is
checked, locked and replaced (sumo/warm_state.py makes and reads the entries).

The cache never deletes or overwrites what it did not write and never follows a symbolic link:
an entry is ``DIR/<key>/`` holding only the names :data:`ENTRY_NAMES` (and the files its
``warm.json`` lists); its ``warm.json`` carries the SHA-256 of every file of the entry and of
itself (``checksum``), so a truncated state or a hand-edited ``warm.json`` is found, said in one
warning and made again. A run that waits for another process making the same entry says so.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import stat
import sys
import warnings
from pathlib import Path

from run_contract.rundir import RunDirError, check_path, looks_like_run

ENTRY_NAMES = frozenset({"state.xml.gz", "warm.json", "job.json", ".warm.json.tmp", "sumo.log", "messages.log",
                         "traffic.rou.xml", "measure.add.xml", "sections.add.xml", "measure.xml",
                         "sections.xml", "lanechanges.xml", "ssm.xml"})
"""Names the warm-up's process writes into an entry."""


class WarmEntryError(RuntimeError):
    """An entry of the cache that cannot be used or replaced (the run fails; nothing deleted)."""


def check_cache(cache: str | Path, out_dir: Path) -> Path:
    """The cache directory as an absolute path if it may be used by a run into ``out_dir``;
    else RunDirError (bad input): an empty path, a comma (SUMO splits its file names there),
    a file or a path under one, not writable, a symbolic link, or inside a run directory (the
    run's own ``--out`` included)."""
    if str(cache) == "":
        raise RunDirError("--warm-cache: is empty: give a directory")
    absolute = Path(os.path.abspath(cache))
    if "," in str(absolute):
        raise RunDirError(f"{cache}: SUMO splits file names at commas; choose a warm-up cache without ','")
    check_path(absolute)
    if absolute.is_symlink():
        raise RunDirError(f"{cache}: is a symbolic link; the warm-up cache never follows one: give "
                          f"{absolute.resolve()}")
    out = Path(os.path.abspath(out_dir))
    for d in (absolute, *absolute.parents):
        if d == out or looks_like_run(d):
            raise RunDirError(f"{cache}: is (or lies inside) the run directory {d}; a warm-up cache "
                              "lives outside every run: choose another directory")
    return absolute


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def seal(entry: Path, doc: dict) -> dict:
    """``doc`` with ``files`` (name -> SHA-256 of every file now in ``entry``) and its own
    ``checksum``: what :func:`damage` checks."""
    files = {p.name: _digest(p) for p in sorted(entry.iterdir()) if p.is_file() and p.name != "warm.json"}
    doc = {**doc, "files": files}
    return {**doc, "checksum": _text_digest(doc)}


def _text_digest(doc: dict) -> str:
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def read_entry(entry: Path, fmt: str) -> tuple[dict | None, str | None]:
    """(``warm.json`` of ``entry``, None) if the entry is whole, else (None, why not)."""
    try:
        doc = json.loads((entry / "warm.json").read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None, "no warm.json"
    except (OSError, ValueError) as exc:
        return None, f"warm.json unreadable ({type(exc).__name__})"
    if not isinstance(doc, dict) or doc.get("format") != fmt or not isinstance(doc.get("files"), dict):
        return None, "warm.json is not a warm-up record of this version"
    body = {k: v for k, v in doc.items() if k != "checksum"}
    if doc.get("checksum") != _text_digest(body):
        return None, "warm.json does not match its checksum (edited or damaged)"
    for name, digest in doc["files"].items():
        p = entry / str(name)
        if p.is_symlink() or not p.is_file() or _digest(p) != digest:
            return None, f"{name} is missing or does not match its checksum"
    if "state.xml.gz" not in doc["files"]:
        return None, "no state.xml.gz"
    return doc, None


def foreign(entry: Path) -> list[str]:
    """Entries of ``entry`` the cache did not write (links, folders, other names)."""
    listed: set = set()
    with contextlib.suppress(OSError, ValueError, AttributeError):
        listed = set(json.loads((entry / "warm.json").read_text(encoding="utf-8")).get("files") or ())
    return [p.name for p in sorted(entry.iterdir())
            if p.is_symlink() or not p.is_file() or (p.name not in ENTRY_NAMES and p.name not in listed)]


def check_entry_path(entry: Path) -> None:
    """WarmEntryError if ``entry`` is a link, a file, or a folder holding what the cache did not write."""
    if entry.is_symlink() or (entry.exists() and not entry.is_dir()):
        raise WarmEntryError(f"{entry}: is a symbolic link or a file, not a warm-up entry; the cache never "
                             "replaces or follows one: remove it or choose another --warm-cache")
    if entry.is_dir():
        names = foreign(entry)
        if names:
            raise WarmEntryError(f"{entry}: holds files formation-traci did not write ({', '.join(names[:5])}); "
                                 "the warm-up cache left it untouched: remove them or choose another --warm-cache")


def remove_entry(entry: Path, why: str) -> None:
    """Remove a damaged entry of ours (checked by :func:`check_entry_path`) with a warning."""
    check_entry_path(entry)
    warnings.warn(f"the shared warm-up {entry} is damaged ({why}): it is made again", stacklevel=2)
    for p in entry.iterdir():
        p.unlink()
    entry.rmdir()


@contextlib.contextmanager
def key_lock(cache: Path, key: str):
    """Hold ``cache/<key>.lock`` (never through a link); says on stderr when it waits for
    another process making the same entry."""
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"{key}.lock"
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise WarmEntryError(f"{path}: cannot open the warm-up lock: {exc.strerror} (a symbolic link "
                             "is never followed)") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise WarmEntryError(f"{path}: is not a regular file; the warm-up cache locks only its own lock files")
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "another process"
            print(f"waiting for {holder} making the shared warm-up {cache / key} ...", file=sys.stderr, flush=True)
            fcntl.flock(fd, fcntl.LOCK_EX)
        if os.pread(fd, 4, 0) in (b"", b"pid "):  # ours (empty when new): say who holds it
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"pid {os.getpid()}".encode(), 0)
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
