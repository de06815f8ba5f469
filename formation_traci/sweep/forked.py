"""Case processes forked from a server that has imported what a case imports.

A case process spends ~1.7-2 s importing numpy, numba, scipy, pandas, pyarrow, pydantic,
libsumo and this package before its run starts: a third of a short case. Python's
``forkserver`` start method keeps one server process per sweep that imports these once
(:data:`PRELOAD`, before any case runs, with no thread started); each case is a fresh
process forked from it. So every case still has its own process, interpreter state and
libsumo (nothing of one case reaches another: the server never runs a case), started in
milliseconds instead of seconds. The case process is what ``python -m
formation_traci.sweep.case SPEC_JSON`` would be: its own session (the supervisor signals its
group), standard output and error appended to the case log, the sweep's current environment
and working directory, the exit code of :func:`formation_traci.sweep.case.main`.

Where this cannot hold, the supervisor starts the process as before (sweep/launch.py): on a
platform without ``fork`` (Windows), in a daemonic process (a Dask worker by default), when a
variable read at import or interpreter start (``NUMBA_*``, ``PYTHON*``) differs from the
server's, with ``FORMATION_TRACI_CASE_START=exec``, or once the server has failed to start a
case (it could not import what it preloads, say): :func:`unusable_reason` says which.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

ENV = "FORMATION_TRACI_CASE_START"
"""``fork`` (default: from the preloaded server) or ``exec`` (a new interpreter per case)."""

PRELOAD = (
    "numpy", "numba", "numba.np.arrayobj", "numba.np.npyimpl", "pandas", "pyarrow.parquet",
    "pyarrow.dataset", "pyarrow.pandas_compat", "xml.sax.expatreader", "libsumo", "sumolib",
    "formation_traci.sweep.case", "formation_traci.runner", "formation_traci.run.road_parts",
    "formation_traci.sumo.road_cache", "formation_traci.sumo.fcd", "formation_traci.sumo.driven",
    "formation_traci.sim.warm", "analysis.api", "analysis.report.run_report",
    "analysis.metrics.propagation",
)
"""Modules the server imports once: what a case process imports (a module missing here is
imported by the case itself, as before)."""

_IMPORT_TIME_VARS = ("NUMBA_", "PYTHON")
"""Environment variables read when a module is imported: the server's must be the sweep's."""

_lock = threading.Lock()
_failed: list[str] = []  # why the server could not start a case (then: new interpreters)
_context = None  # multiprocessing's forkserver context, once started
_server_env: dict[str, str] = {}


def _import_time_env(env) -> dict[str, str]:
    return {k: v for k, v in env.items() if k.startswith(_IMPORT_TIME_VARS)}


def usable() -> bool:
    """True if cases can be forked from the preloaded server here and now."""
    return unusable_reason() is None


def unusable_reason() -> str | None:
    """Why cases cannot be forked here and now (None: they can)."""
    if _failed:
        return f"the server failed to start a case: {_failed[0]}"
    if os.environ.get(ENV, "fork") != "fork":
        return f"{ENV}={os.environ[ENV]}"
    import multiprocessing
    if not hasattr(os, "fork") or "forkserver" not in multiprocessing.get_all_start_methods():
        return "no fork on this platform"
    if multiprocessing.current_process().daemon:  # a Dask worker: may not have children of its own
        return "a daemonic process"
    env = _import_time_env(os.environ)
    if _context is not None and env != _server_env:
        changed = sorted(k for k in env.keys() | _server_env.keys() if env.get(k) != _server_env.get(k))
        return f"changed since the server started: {', '.join(changed)}"
    return None


def _server():
    """The forkserver context, its preload set before the server's first start."""
    global _context, _server_env
    with _lock:
        if _context is None:
            import multiprocessing
            ctx = multiprocessing.get_context("forkserver")
            ctx.set_forkserver_preload(list(PRELOAD))
            _server_env = _import_time_env(os.environ)
            _context = ctx
        return _context


def give_up(exc: BaseException) -> None:
    """The server failed to start a case (``exc``): later cases start as new interpreters."""
    _failed.append(f"{type(exc).__name__}: {exc}")


_STATUS_LOCK = threading.Lock()
"""Held while a forked process's exit status is read or a process starts. The forkserver
sends a child's status once, over a pipe: two threads reading it at the same time (a
supervising thread's wait and multiprocessing's ``Process.start``, which polls every other
child) leave one of them at the pipe's end, and multiprocessing then takes the child's exit
code for 255."""


class ForkedCase:
    """A case process forked from the server, with the part of ``subprocess.Popen``'s
    interface the supervisor uses: ``pid``, ``poll()``, ``wait(timeout)``, ``send_signal``.
    ``target`` and ``args``: what the process runs (default :func:`case_entry` with the
    case's spec, its log, the sweep's environment and directory)."""

    def __init__(self, spec_json: str, log_path: str, target=None, args=None):
        ctx = _server()
        self._proc = ctx.Process(target=target or case_entry, name="formation-traci-case",
                                 args=args if args is not None
                                 else (spec_json, log_path, dict(os.environ), os.getcwd()))
        with _STATUS_LOCK:  # start() polls the other children
            self._proc.start()
        self.pid = self._proc.pid

    def poll(self) -> int | None:
        with _STATUS_LOCK:
            return self._proc.exitcode

    def wait(self, timeout: float | None = None) -> int:
        from multiprocessing.connection import wait as readable
        readable([self._proc.sentinel], timeout)  # the status is there (or the server is gone)
        code = self.poll()
        if code is None:
            raise subprocess.TimeoutExpired("case process", timeout)
        return code

    def send_signal(self, sig: int) -> None:
        os.kill(self.pid, sig)


def case_entry(spec_json: str, log_path: str, env: dict, cwd: str) -> None:
    """The forked case process: its own session, the log as its output, the sweep's
    environment and directory, then the case (exit code that of ``case.main``)."""
    os.setsid()  # its own process group: the supervisor's signals reach it and its children
    signal.signal(signal.SIGINT, signal.default_int_handler)  # the server ignores Ctrl-C
    fd = os.open(log_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    null = os.open(os.devnull, os.O_RDONLY)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(null, 0)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    os.close(null)
    os.environ.clear()
    os.environ.update(env)
    os.chdir(cwd)
    from . import case
    sys.argv = [case.__file__, spec_json]  # as `python -m`'s: the run directory's lock names it
    code = case.main([spec_json])
    _interpreter_exit()
    sys.exit(code)


def _interpreter_exit() -> None:
    """What an interpreter does at its exit and a forked process skips (multiprocessing ends it
    with ``os._exit``): wait for the threads still running (a part file being written), run
    the ``atexit`` functions, flush. Neither step has a public API: these are CPython's own
    ``threading._shutdown`` and ``atexit._run_exitfuncs``, the calls of its finalisation,
    looked up here and nowhere else."""
    import atexit
    for module, name in ((threading, "_shutdown"), (atexit, "_run_exitfuncs")):
        step = getattr(module, name, None)
        if step is not None:
            step()
    sys.stdout.flush()
    sys.stderr.flush()
