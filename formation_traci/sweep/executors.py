"""Where case tasks run: a local thread pool, or a Dask distributed cluster.

Both run the same task, :func:`~formation_traci.sweep.launch.launch_case`, which starts one
process per case; threads (or Dask worker threads) only supervise those processes. Each
executor calls ``on_row(spec, row)`` in the calling thread as cases finish, and returns
True if it was interrupted (Ctrl-C): the stop flag is then raised, running cases stop at
their next step and are collected, cases not started are left pending.
"""
from __future__ import annotations

import os
import threading
import uuid
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path
from typing import Callable

from run_contract.errors import SweepError

from .case import CaseSpec
from .launch import GRACE_S, dask_case, launch_case
from .row import empty_row

OnRow = Callable[[CaseSpec, dict], None]
DRAIN_S = GRACE_S + 15.0
"""How long an interrupted sweep waits for its running cases to stop [s]."""


def _error_row(spec: CaseSpec, exc: BaseException) -> dict:
    return empty_row(spec.case.model_dump(mode="json"), "failed",
                     f"task failed: {type(exc).__name__}: {exc}")


def run_local(specs: list[CaseSpec], workers: int | None, timeout_s: float | None,
              on_row: OnRow) -> bool:
    """Run the cases on this machine, ``workers`` at a time.

    Parameters
    ----------
    specs : list of CaseSpec
        Cases to run.
    workers : int or None
        Cases at once; default ``os.cpu_count()``.
    timeout_s : float or None
        Wall-clock limit per case [s].
    on_row : callable
        ``on_row(spec, row)``, called in this thread as each case finishes.

    Returns
    -------
    bool
        True if interrupted by Ctrl-C (running cases were stopped and collected).
    """
    stop = threading.Event()
    n = max(1, workers or os.cpu_count() or 1)
    pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="sweep-case")
    futs: dict = {}
    done: set = set()

    def collect(fut) -> None:
        done.add(fut)
        if fut.cancelled():
            return
        exc = fut.exception()
        row = _error_row(futs[fut], exc) if exc is not None else fut.result()
        if row is not None:
            on_row(futs[fut], row)

    try:
        for s in specs:
            futs[pool.submit(launch_case, s, stop.is_set, timeout_s)] = s
        for fut in as_completed(futs):
            collect(fut)
        return False
    except KeyboardInterrupt as exc:
        stop.set()
        for fut in futs:
            fut.cancel()
        try:
            for fut in as_completed([f for f in futs if f not in done], timeout=DRAIN_S):
                collect(fut)
        except TimeoutError:
            pass
        return getattr(exc, "signame", "SIGINT")  # truthy: interrupted, by this signal
    finally:
        pool.shutdown(wait=False, cancel_futures=True)


def _client(scheduler: str):
    from distributed import Client

    try:
        if Path(scheduler).is_file():
            return Client(scheduler_file=str(scheduler))
        return Client(scheduler)
    except Exception as exc:  # unreachable, malformed address, or not a scheduler file
        if isinstance(exc, KeyboardInterrupt):
            raise
        raise SweepError(scheduler, [("scheduler", f"cannot connect to the Dask scheduler: "
                                                   f"{type(exc).__name__}: {exc}".rstrip(": "))]) from None


def run_dask(specs: list[CaseSpec], scheduler: str, timeout_s: float | None,
             on_row: OnRow) -> bool:
    """Run the cases on a Dask cluster.

    Parameters
    ----------
    specs : list of CaseSpec
        Cases to run.
    scheduler : str
        ``tcp://HOST:PORT`` or the path of a scheduler file.
    timeout_s : float or None
        Wall-clock limit per case [s].
    on_row : callable
        ``on_row(spec, row)``, called in this thread as each case finishes.

    Returns
    -------
    bool
        True if interrupted by Ctrl-C (running cases were stopped and collected).
    """
    from distributed import Event, as_completed as dask_completed

    client = _client(scheduler)
    stop_name = f"formation-traci-sweep-stop-{uuid.uuid4().hex}"
    stop = Event(stop_name, client=client)
    token = uuid.uuid4().hex[:8]
    futs = {client.submit(dask_case, s.model_dump(mode="json"), stop_name, timeout_s, pure=False,
                          key=f"sweep-{s.case.id}-{token}", priority=-s.case.index): s
            for s in specs}
    done: set = set()

    def collect(fut) -> None:
        done.add(fut)
        if fut.status == "finished":
            row = fut.result()
        elif fut.status == "cancelled":
            return
        else:
            try:
                exc = fut.exception(timeout=10)
            except Exception as err:  # lost with its worker, or unreadable
                exc = err
            row = _error_row(futs[fut], exc)
        if row is not None:
            on_row(futs[fut], row)

    try:
        for fut in dask_completed(list(futs)):
            collect(fut)
        return False
    except KeyboardInterrupt as exc:
        stop.set()  # tasks not started return None; running ones stop their case process
        try:
            for fut in dask_completed([f for f in futs if f not in done], timeout=DRAIN_S):
                collect(fut)
        except Exception:  # timeout (or a second Ctrl-C handled by the caller)
            pass
        return getattr(exc, "signame", "SIGINT")  # truthy: interrupted, by this signal
    finally:
        client.cancel([f for f in futs if f not in done])
        client.close()
