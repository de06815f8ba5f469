"""Output directories: what ``--force`` may replace, and one writer at a time.

* A directory is replaced (``--force``) only if it is a previous run of this tool (its
  ``run.json`` says so) holding nothing but files this tool writes; any other non-empty
  directory, the working directory, a directory holding the scenario, or a path through a
  symbolic link is refused (:class:`RunDirError`, CLI exit 2) and left untouched.
* A writer (a run, or ``analyze``/``compare`` writing into a directory) holds an exclusive
  ``flock`` on :data:`LOCK_NAME` inside the directory for its whole life; a second writer is
  refused naming the holder (:class:`RunDirBusy`). The kernel drops the lock when its process
  dies, so the lock of a dead process is taken over with no clean-up step.
"""
from __future__ import annotations

import fcntl
import json
import os
import shutil
import socket
import sys
import time
from pathlib import Path
from typing import Iterable

RUN_SCHEMA = "formation-traci/run/1"
RUN_FINISHED = ("completed", "completed_with_incidents")
"""Statuses of a run that reached its end (``completed_with_incidents``: with a member
collision, removal, emergency brake or stranded member, sim/incidents.py)."""
"""``run.json["schema"]``: marks a directory as a run of this tool."""
LOCK_NAME = ".formation-traci.lock"
"""Lock file inside an output directory; holds the pid, host and command of the holder."""
TOOL_FILES = frozenset({
    "run.json", "error.txt", "trajectories.parquet", "events.parquet", "background.parquet",
    "ssm.parquet", "sumo", "metrics.json", "metrics.csv", "baseline.csv", "figures",
    "report.html", "case.json", "compare.csv", "compare.json", LOCK_NAME, ".run.json.tmp",
    ".reserve", "comfort.parquet", "open_loop.parquet", "comm_age.csv",
    "sections.parquet", "departures.parquet", "twin.csv"})
"""Names this tool writes at the top of a run directory: ``--force`` removes only these."""


class RunDirError(ValueError):
    """An output (or input) directory that cannot be used as asked; nothing was changed."""


class RunDirExists(RunDirError, FileExistsError):
    """The output directory exists, is not empty, and --force was not given."""


class RunDirBusy(RunDirError):
    """Another process is writing into the directory."""


def is_tool_run(path: Path) -> bool:
    """True if ``path/run.json`` is a run record written by this tool."""
    try:
        meta = json.loads((path / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if not isinstance(meta, dict):
        return False
    if meta.get("schema") == RUN_SCHEMA:
        return True
    # runs recorded before the schema mark: the fields every such run.json has
    return ({"status", "scenario", "versions", "started"} <= meta.keys()
            and isinstance(meta["versions"], dict) and "formation-traci" in meta["versions"])


def _inside(child: Path, parent: Path) -> bool:
    return child == parent or parent in child.parents


def check_path(out: Path) -> Path:
    """``out`` as an absolute path if a directory can be (or is) there; else RunDirError."""
    out = Path(out)
    absolute = Path(os.path.abspath(out))
    for anc in reversed(absolute.parents):
        if anc.exists() and not anc.is_dir():
            raise RunDirError(f"{out}: cannot create a directory under {anc}, which is a file")
    if out.exists() and not out.is_dir():
        raise RunDirError(f"{out}: exists and is a file, not a directory")
    existing = next(p for p in [absolute, *absolute.parents] if p.exists())
    if not os.access(existing, os.W_OK | os.X_OK):
        raise RunDirError(f"{out}: {existing} is not writable")
    return absolute


def check_replaceable(out: Path, force: bool, protect: Iterable[Path] = (), what: str = "run",
                      probe_lock: bool = True) -> None:
    """Refuse (RunDirError) an existing non-empty ``out`` unless ``force`` and it is a previous
    run of this tool with only its files, away from the working directory and ``protect``."""
    absolute = check_path(out)
    if not absolute.is_dir():
        return
    holder = is_locked(absolute) if probe_lock else None
    if holder:
        raise RunDirBusy(f"{out}: another formation-traci process is writing here ({holder}); "
                         "wait for it or choose another directory")
    entries = [p.name for p in absolute.iterdir()]
    if not [e for e in entries if e != LOCK_NAME]:
        return
    if not force:
        raise RunDirExists(f"{out} exists and is not empty; pass --force to replace a previous run")
    if out.is_symlink() or absolute != absolute.resolve():
        raise RunDirError(f"{out}: is (or lies under) a symbolic link; --force replaces only a real "
                          f"run directory: give {absolute.resolve()}")
    real = absolute.resolve()
    if _inside(Path.cwd().resolve(), real):
        raise RunDirError(f"{out}: is the working directory or one of its parents; --force never replaces it")
    for p in protect:
        if p is not None and _inside(Path(p).resolve(), real):
            raise RunDirError(f"{out}: holds {p}; --force never replaces a directory holding the scenario "
                              "or its files")
    if not is_tool_run(real):
        raise RunDirError(f"{out}: is not a previous {what} of formation-traci (no run.json written by it); "
                          "--force replaces only those: left untouched")
    foreign = sorted(e for e in entries if e not in TOOL_FILES)
    if foreign:
        raise RunDirError(f"{out}: holds files formation-traci did not write ({', '.join(foreign[:5])}"
                          f"{', ...' if len(foreign) > 5 else ''}); --force left the directory untouched")


def clear_run(out: Path) -> None:
    """Remove the files of a previous run (checked by :func:`check_replaceable`), not the lock."""
    for p in Path(out).iterdir():
        if p.name == LOCK_NAME or p.name not in TOOL_FILES:
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink()


class DirLock:
    """Exclusive lock on an output directory for the life of one writer."""

    def __init__(self, directory: Path):
        self.directory = Path(directory)
        self._f = None

    def acquire(self) -> "DirLock":
        path = self.directory / LOCK_NAME
        try:
            f = open(path, "a+", encoding="utf-8")
        except OSError as exc:
            raise RunDirError(f"{self.directory}: cannot open {LOCK_NAME}: {exc.strerror}") from None
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            holder = f.read().strip() or "another process"
            f.close()
            raise RunDirBusy(f"{self.directory}: another formation-traci process is writing here "
                             f"({holder}); wait for it or choose another directory") from None
        f.seek(0)
        f.truncate()
        f.write(f"pid {os.getpid()} on {socket.gethostname()} since "
                f"{time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}: {' '.join(sys.argv)[:200]}\n")
        f.flush()
        self._f = f
        return self

    def release(self) -> None:
        if self._f is not None:
            try:
                fcntl.flock(self._f, fcntl.LOCK_UN)
            finally:
                self._f.close()
                self._f = None

    def __enter__(self) -> "DirLock":
        return self.acquire() if self._f is None else self

    def __exit__(self, *exc) -> None:
        self.release()


def is_locked(directory: Path) -> str | None:
    """The holder of ``directory``'s lock if a live process holds it, else None (no side effect
    beyond opening the lock file read-only)."""
    path = Path(directory) / LOCK_NAME
    try:
        f = open(path, "r", encoding="utf-8")
    except OSError:
        return None
    with f:
        try:
            fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:
            return f.read().strip() or "another process"
        fcntl.flock(f, fcntl.LOCK_UN)
    return None


def open_out_dir(out: Path, force: bool, protect: Iterable[Path] = (), what: str = "run") -> DirLock:
    """Check, create and lock ``out``; with ``force`` replace a previous run. Returns the held
    lock (release it when the writer is done). Raises RunDirError with nothing changed."""
    protect = list(protect)
    check_replaceable(out, force, protect, what)
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunDirError(f"{out}: cannot create the directory: {exc.strerror}") from None
    lock = DirLock(out).acquire()
    try:
        check_replaceable(out, force, protect, what, probe_lock=False)  # again under the lock: nobody changed it since
        if force:
            clear_run(out)
    except BaseException:
        lock.release()
        raise
    return lock


def open_report_dir(out: Path, marker: str, own_run: Path | None = None) -> DirLock:
    """Check, create and lock a directory that ``analyze`` (``marker`` = metrics.json) or
    ``compare`` (compare.json) writes into: missing, empty, the analysed run itself
    (``own_run``), or an earlier output of the same command holding only this tool's files.
    Another run's directory is refused: its report would be overwritten."""
    absolute = check_path(out)
    same_run = own_run is not None and absolute.resolve() == Path(os.path.abspath(own_run)).resolve()
    if absolute.is_dir() and not same_run:
        entries = [p.name for p in absolute.iterdir() if p.name != LOCK_NAME]
        if "run.json" in entries:
            raise RunDirError(f"{out}: is a run directory; writing here would overwrite that run's "
                              "report: choose another --out")
        foreign = sorted(e for e in entries if e not in TOOL_FILES)
        if foreign or (entries and marker not in entries):
            raise RunDirError(f"{out}: is not empty and not an earlier output of this command "
                              f"({', '.join(foreign[:5]) or ', '.join(entries[:5])}); choose another --out")
    try:
        absolute.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunDirError(f"{out}: cannot create the directory: {exc.strerror}") from None
    return DirLock(absolute).acquire()


def require_run_dir(run_dir: Path) -> Path:
    """``run_dir`` if it is an existing directory (never created), else RunDirError."""
    run_dir = Path(run_dir)
    if not run_dir.exists():
        raise RunDirError(f"{run_dir}: no such run directory")
    if not run_dir.is_dir():
        raise RunDirError(f"{run_dir}: is a file, not a run directory")
    return run_dir
