"""Supervise one case process: the task both executors run (a thread here, or a Dask task).

The case runs as ``python -m formation_traci.sweep.case SPEC_JSON`` would, in its own process
and session, so every case has a fresh process and its own libsumo, whatever runs the task:
forked from a server that has imported what a case imports (sweep/forked.py), or a new
interpreter where that cannot hold. The supervisor turns every way the process can end into a
row: the row it wrote, or ``failed`` with the exit code or signal and the last line of its log.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable

from run_contract.rundir import RUN_FINISHED, is_locked

from . import forked
from .case import CASE_JSON, CaseSpec, write_case_json
from .row import empty_row

POLL_S = 0.2
"""How often the supervisor checks the process, the stop flag and the timeout [s]."""
GRACE_S = 15.0
"""After SIGINT/SIGTERM the run stops at its next step and is analysed; after this the
process is killed [s]."""


def case_command(spec_json: str) -> list[str]:
    """Command line of a case process (the interpreter running this code).

    Parameters
    ----------
    spec_json : str
        The :class:`CaseSpec` as JSON text.

    Returns
    -------
    list of str
        ``[sys.executable, "-m", "formation_traci.sweep.case", spec_json]``.
    """
    return [sys.executable, "-m", "formation_traci.sweep.case", spec_json]


_DEFAULT_COMMAND = case_command
"""A replaced :func:`case_command` (tests put other programs in a case's place) is run as given."""


def start_case(spec_json: str, log, log_path: Path):
    """Start the case process: forked from the preloaded server (sweep/forked.py) when it can
    be and the command is :func:`case_command`'s, else ``subprocess.Popen`` of the command.

    Parameters
    ----------
    spec_json : str
        The :class:`CaseSpec` as JSON text.
    log : file
        The case log, open for appending (the process's standard output and error).
    log_path : Path
        Its path (a forked process opens it itself).

    Returns
    -------
    subprocess.Popen or forked.ForkedCase
        The process: ``pid``, ``poll()``, ``wait(timeout)``, ``send_signal(sig)``.
    """
    if case_command is _DEFAULT_COMMAND and forked.usable():
        try:
            return forked.ForkedCase(spec_json, str(log_path))
        except Exception as exc:  # the server did not start or died: new interpreters from now on
            forked.give_up(exc)
    return subprocess.Popen(case_command(spec_json), stdin=subprocess.DEVNULL, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)


def _supervise(proc, should_stop: Callable[[], bool] | None,
               timeout_s: float | None) -> tuple[int, bool, bool]:
    t0 = time.monotonic()
    kill_at, stopped, timed_out = None, False, False
    while True:
        try:
            return proc.wait(timeout=POLL_S), stopped, timed_out
        except subprocess.TimeoutExpired:
            pass
        now = time.monotonic()
        if kill_at is None and should_stop is not None and should_stop():
            stopped, kill_at = True, now + GRACE_S
            signal_group(proc, signal.SIGINT)
        elif kill_at is None and timeout_s is not None and now - t0 > timeout_s:
            timed_out, kill_at = True, now + GRACE_S
            signal_group(proc, signal.SIGTERM)
        elif kill_at is not None and now > kill_at:
            signal_group(proc, signal.SIGKILL)


def signal_group(proc: subprocess.Popen, sig: int) -> None:
    """Send ``sig`` to the case process and everything it started (its own session and
    process group), so no SUMO or helper outlives the case.

    Parameters
    ----------
    proc : subprocess.Popen or forked.ForkedCase
        The case process, in its own session (``start_new_session=True``, or forked.py's
        ``setsid``).
    sig : int
        The signal.

    Returns
    -------
    None
    """
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        try:
            proc.send_signal(sig)
        except ProcessLookupError:
            pass


def _last_line(log_path: Path) -> str:
    try:
        with open(log_path, "rb") as f:
            f.seek(max(0, f.seek(0, os.SEEK_END) - 4096))
            lines = [ln.strip() for ln in f.read().decode("utf-8", "replace").splitlines()]
    except OSError:
        return ""
    lines = [ln for ln in lines if ln and not ln.startswith("--- ")]
    return lines[-1][:300] if lines else ""


def _exit_reason(rc: int, log_path: Path) -> str:
    if rc < 0:
        try:
            what = f"killed by {signal.Signals(-rc).name}"
        except ValueError:
            what = f"killed by signal {-rc}"
    else:
        what = f"exited with code {rc}" if rc else "exited without writing its row"
    last = _last_line(log_path)
    return f"case process {what}" + (f"; last output: {last}" if last else "") + f" (log: {log_path})"


def _read_row(case_dir: Path, case_id: str) -> dict | None:
    try:
        doc = json.loads((case_dir / CASE_JSON).read_text(encoding="utf-8"))
        row = doc["row"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return row if isinstance(row, dict) and row.get("case_id") == case_id else None


def _recorded_stop(case_dir: Path) -> dict:
    """What the run.json of a case process that ended without its row says of the run (a run
    that stopped and was recorded, then was killed in its analysis): its ``t_end_s`` and a
    note for the reason; nothing when there is no finished run.json."""
    try:
        meta = json.loads((case_dir / "run.json").read_text(encoding="utf-8"))
        status, t_end = meta["status"], float(meta["t_end"])
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    if status == "running":  # killed while it stepped: the last step recorded is not its end
        return {}
    return {"t_end_s": t_end,
            "note": f"its run ended {status} at t = {t_end:g} s and is recorded (run.json); "
                    "its analysis did not finish"}


def launch_case(case_spec: dict | CaseSpec, should_stop: Callable[[], bool] | None = None,
                timeout_s: float | None = None) -> dict[str, Any] | None:
    """Run one case in a fresh process and return its summary row.

    Parameters
    ----------
    case_spec : dict or CaseSpec
        The case and its paths.
    should_stop : callable, optional
        Polled every :data:`POLL_S`; once true the case process gets SIGINT (its run stops
        at the end of the step and is recorded as interrupted), and SIGKILL after
        :data:`GRACE_S`. True before the start: the case is not started.
    timeout_s : float, optional
        Wall-clock limit [s]: then SIGTERM, SIGKILL after :data:`GRACE_S`; status failed.

    Returns
    -------
    dict or None
        The row (also in ``<case_dir>/case.json``) with ``wall_s``, ``host`` and ``pid`` of
        the case process; None if the case was not started because of ``should_stop``.
    """
    spec = CaseSpec.model_validate(case_spec)
    if should_stop is not None and should_stop():
        return None
    case, case_dir, log_path = spec.case.model_dump(mode="json"), Path(spec.case_dir), Path(spec.log_path)
    holder = is_locked(case_dir)
    if holder:  # an earlier sweep's case process still runs there: never a second one beside it
        row = empty_row(case, "failed", f"not started: the case is still running in another process "
                                        f"({holder}); run the sweep again once it has ended")
        row.update(wall_s=0.0, host=socket.gethostname(), pid=None)
        return row
    t0, pid = time.monotonic(), None
    try:
        log_path.parent.mkdir(parents=True, exist_ok=True)
        (case_dir / CASE_JSON).unlink(missing_ok=True)  # a stale row must not be read back
        with open(log_path, "a", encoding="utf-8") as log:
            stamp = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
            log.write(f"--- {spec.case.id}: started {stamp} on {socket.gethostname()}\n")
            log.flush()
            proc = start_case(spec.model_dump_json(), log, log_path)
            pid = proc.pid
            try:
                rc, stopped, timed_out = _supervise(proc, should_stop, timeout_s)
            finally:
                if proc.poll() is None:  # the supervisor failed or was interrupted: stop the case
                    signal_group(proc, signal.SIGINT)
                    try:
                        proc.wait(timeout=GRACE_S)
                    except subprocess.TimeoutExpired:
                        signal_group(proc, signal.SIGKILL)
                        proc.wait()
    except Exception as exc:
        row = empty_row(case, "failed", f"could not run the case process: {type(exc).__name__}: {exc}")
    else:
        row = _read_row(case_dir, spec.case.id) if rc == 0 else None
        if row is None:  # no row: the process failed or was killed, its run maybe recorded
            recorded = _recorded_stop(case_dir)
            reason = _exit_reason(rc, log_path)
            row = empty_row(case, "failed", f"{reason}; {recorded['note']}" if recorded else reason)
            row["t_end_s"] = recorded.get("t_end_s")
        if timed_out:
            row.update(status="failed", reason=f"timeout: still running after {timeout_s:g} s; "
                                               f"{row['reason'] or 'stopped'}")
        elif stopped and row["status"] not in RUN_FINISHED:
            row.update(status="interrupted", reason=f"sweep interrupted; {row['reason'] or 'stopped'}")
    row.update(wall_s=time.monotonic() - t0, host=socket.gethostname(), pid=pid)
    try:
        write_case_json(case_dir, spec, row)
    except OSError:
        pass  # the row still reaches the summary
    return row


def dask_case(case_spec: dict, stop_event: str, timeout_s: float | None) -> dict[str, Any] | None:
    """The Dask task: :func:`launch_case` with a ``distributed.Event`` as the stop flag.

    Parameters
    ----------
    case_spec : dict
        The :class:`CaseSpec` as a dict.
    stop_event : str
        Name of the ``distributed.Event`` the sweep sets on Ctrl-C (polled once a second).
    timeout_s : float or None
        Wall-clock limit of the case [s].

    Returns
    -------
    dict or None
        As :func:`launch_case`.
    """
    from distributed import Event

    event = Event(stop_event)
    state = {"t": -1e9, "set": False}

    def should_stop() -> bool:
        now = time.monotonic()
        if now - state["t"] >= 1.0:  # one scheduler round trip per second at most
            state["t"] = now
            try:
                state["set"] = bool(event.is_set())
            except Exception:
                pass
        return state["set"]

    return launch_case(case_spec, should_stop, timeout_s)
