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
import re
import shutil
import socket
import stat
import tempfile
import sys
import time
from pathlib import Path
from typing import Iterable

RUN_SCHEMA = "formation-traci/run/1"
"""``run.json["schema"]``: marks a directory as a run of this tool."""
RUN_FINISHED = ("completed", "completed_with_incidents")
"""Statuses of a run that reached its end (``completed_with_incidents``: with a member
collision, removal, emergency brake or stranded member, formation_traci/sim/incidents.py)."""
LOCK_NAME = ".formation-traci.lock"
"""Lock file inside an output directory; holds the pid, host and command of the holder."""
TOOL_FILES = frozenset({
    "run.json", "error.txt", "trajectories.parquet", "events.parquet", "background.parquet",
    "ssm.parquet", "sumo", "metrics.json", "metrics.csv", "baseline.csv", "figures",
    "report.html", "case.json", "compare.csv", "compare.json", LOCK_NAME, ".run.json.tmp",
    ".reserve", "comfort.parquet", "open_loop.parquet", "comm_age.csv",
    "sections.parquet", "departures.parquet", "twin.csv"})
"""Names this tool writes at the top of a run directory: ``--force`` removes only these."""
TOOL_TEMP = re.compile(r"^\.[A-Za-z0-9_.\-]+\.tmp$")
"""Temporary files of an atomic write (:func:`atomic_write_bytes`), left by a killed process."""
_PARTS = re.compile(r"^\.?part-\d{5}\.parquet(\.tmp)?$")
TOOL_SUBFILES = {
    **{t: _PARTS for t in ("trajectories.parquet", "events.parquet", "background.parquet", "ssm.parquet",
                           "comfort.parquet", "open_loop.parquet")},
    "figures": re.compile(r"^(\.[\w.\-]+\.tmp(\.png|\.gif)?|[a-z_]+\.(png|gif))$"),
    "sumo": re.compile(r"^(sumo\.log|messages\.log|traffic\.rou\.xml|ssm\.xml|measure\.xml|measure\.add\.xml"
                       r"|fcd\.parquet|fcd\.tmp\.parquet|sections\.add\.xml|sections\.xml|sumo_cacc\.add\.xml)$"),
}
"""The manifest of the folders this tool writes: the names it writes inside each (``sumo/`` also
holds the outputs named in the run's ``run.json`` ``sumo.args``). ``--force`` replaces a run
only when these are all it holds."""


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
    if any(len(os.fsencode(part)) > 255 for part in absolute.parts) or len(os.fsencode(str(absolute))) > 4000:
        raise RunDirError(f"{str(out)[:80]}...: the path is too long for the file system "
                          "(255 bytes per name, 4000 in all)")
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
    foreign = foreign_files(real)
    if foreign:
        raise RunDirError(f"{out}: holds files formation-traci did not write ({', '.join(foreign[:5])}"
                          f"{', ...' if len(foreign) > 5 else ''}); --force left the directory untouched")


def _sumo_outputs(run_dir: Path) -> set[str]:
    """Names of the files in ``sumo/`` that the run's SUMO options wrote (from run.json)."""
    try:
        args = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))["sumo"]["args"]
    except (OSError, ValueError, KeyError, TypeError):
        return set()
    if not isinstance(args, list):
        return set()
    names = set()
    for a in args:
        value = str(a).partition("=")[2] if str(a).startswith("--") else str(a)
        if Path(value).parent.name == "sumo":
            names.add(Path(value).name)
    return names


def foreign_files(run_dir: Path) -> list[str]:
    """Paths (relative) in ``run_dir`` this tool did not write: anything outside
    :data:`TOOL_FILES`, any entry of the tool's folders outside :data:`TOOL_SUBFILES`, and
    any symbolic link."""
    out = []
    for p in sorted(run_dir.iterdir()):
        if p.is_symlink():
            out.append(f"{p.name} (a symbolic link)")
            continue
        if p.name not in TOOL_FILES and not TOOL_TEMP.match(p.name):
            out.append(p.name)
            continue
        if p.is_dir():
            allowed, extra = TOOL_SUBFILES.get(p.name), _sumo_outputs(run_dir) if p.name == "sumo" else set()
            for q in sorted(p.iterdir()):
                if q.is_symlink():
                    out.append(f"{p.name}/{q.name} (a symbolic link)")
                elif allowed is None or not q.is_file() or not (allowed.match(q.name) or q.name in extra):
                    out.append(f"{p.name}/{q.name}")
    return out


def refuse_links(directory: Path, names: Iterable[str]) -> None:
    """RunDirError if ``directory/name`` (or an entry of it, for a folder) is a symbolic
    link: formation-traci never writes through one."""
    for name in names:
        p = Path(directory) / name
        if p.is_symlink():
            raise RunDirError(f"{p}: is a symbolic link; formation-traci never writes through one "
                              "(remove it, or choose another directory): nothing written")
        if p.is_dir():
            for q in p.iterdir():
                if q.is_symlink():
                    raise RunDirError(f"{q}: is a symbolic link; formation-traci never writes through "
                                      "one (remove it, or choose another directory): nothing written")


def clear_run(out: Path) -> None:
    """Remove the files of a previous run (checked by :func:`check_replaceable`), not the lock."""
    for p in Path(out).iterdir():
        if p.name == LOCK_NAME or p.is_symlink() or (p.name not in TOOL_FILES and not TOOL_TEMP.match(p.name)):
            continue
        if p.is_dir():
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
        try:  # never through a symbolic link, never a FIFO or device: a regular file of ours
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            why = "it is a symbolic link (never followed)" if path.is_symlink() else exc.strerror
            raise RunDirError(f"{self.directory}: cannot open {LOCK_NAME}: {why}; nothing written") from None
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise RunDirError(f"{path}: is not a regular file; nothing written")
        f = os.fdopen(fd, "a+", encoding="utf-8")
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
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        return None
    f = os.fdopen(fd, "r", encoding="utf-8")
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
    if same_run and not looks_like_run(absolute):
        raise RunDirError(f"{out}: is not a run directory (no run.json and no trajectories.parquet): "
                          "nothing written")
    if absolute.is_dir():
        refuse_links(absolute, sorted(TOOL_FILES))
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


def looks_like_run(path: Path) -> bool:
    """True if ``path`` holds a run.json or a trajectories table written by this tool (a
    damaged run without one of them still is a run)."""
    return (path / "run.json").is_file() or (path / "trajectories.parquet").is_dir()


def require_run_dir(run_dir: Path) -> Path:
    """``run_dir`` if it is an existing directory (never created), else RunDirError."""
    run_dir = Path(run_dir)
    if not run_dir.exists():
        raise RunDirError(f"{run_dir}: no such run directory")
    if not run_dir.is_dir():
        raise RunDirError(f"{run_dir}: is a file, not a run directory")
    return run_dir


def atomic_write_text(path: Path, text: str) -> None:
    """Write text to ``path`` via a new temporary file beside it and a rename: never
    half-written, never through a symbolic link at ``path`` (the rename replaces the link,
    its target is untouched) and no temporary file left behind on failure (disk full)."""
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """:func:`atomic_write_text` for bytes."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)  # e.g. disk full: no half-written temporary left behind
        except OSError:
            pass
        if isinstance(exc, OSError) and exc.filename is None:  # say which file could not be written
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise
