"""SIGINT and SIGTERM: every run ends as ``interrupted`` (exit 130), whatever it is doing.

While a run is being set up (imports, checks, compiling, SUMO start, warm-up) a signal raises
:class:`Interrupted` at once, so nothing waits for the warm-up to end. Once the run steps, a
signal only sets a flag that the loop checks after every step, so the step in progress is
recorded whole; the finishing code (flushing, run.json) is never interrupted.

A signal that lands while Python runs inside a C library's callback (numba's kernel cache is
filled through llvmlite's ctypes callbacks while kernels compile or load) cannot raise there:
ctypes would print the exception and drop it. The handler then sends the signal again
:data:`REDELIVER_S` later, until it lands outside such a callback.
"""
from __future__ import annotations

import contextlib
import os
import signal
import threading

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""Signals that end a run as ``interrupted``: Ctrl-C, ``kill``, and a closed terminal (SIGHUP,
handled like SIGTERM)."""


REDELIVER_S = 0.02
"""Delay [s] of a signal sent again because it landed inside a C callback."""

_CALLBACKS = (("llvmlite", "_raw_object_cache_notify"), ("llvmlite", "_raw_object_cache_getbuffer"))
"""(package, function) of the ctypes callbacks a signal may land in while a run is set up."""


def in_c_callback(frame) -> bool:
    """True when ``frame`` (a signal handler's) runs inside one of :data:`_CALLBACKS`."""
    while frame is not None:
        code = frame.f_code
        if any(code.co_name == name and f"{os.sep}{pkg}{os.sep}" in code.co_filename
               for pkg, name in _CALLBACKS):
            return True
        frame = frame.f_back
    return False


def _redeliver(signum: int) -> None:
    timer = threading.Timer(REDELIVER_S, os.kill, (os.getpid(), signum))
    timer.daemon = True
    timer.start()


class Interrupted(KeyboardInterrupt):
    """A SIGINT or SIGTERM arrived; ``signame`` says which."""

    def __init__(self, signame: str = "SIGINT"):
        super().__init__(f"{signame} received")
        self.signame = signame


def raise_interrupted(signum, frame) -> None:
    """Signal handler: raise :class:`Interrupted` (both SIGINT and SIGTERM)."""
    if in_c_callback(frame):
        return _redeliver(signum)
    raise Interrupted(signal.Signals(signum).name)


def _exit_130(signum, frame) -> None:
    if in_c_callback(frame):
        return _redeliver(signum)
    os.write(2, f"interrupted: {signal.Signals(signum).name} received\n".encode())
    raise SystemExit(130)


def exit_130_on_signals() -> None:
    """Start-up of a command (nothing exists yet): SIGINT/SIGTERM leave at once with 130."""
    if threading.current_thread() is threading.main_thread():
        for sig in SIGNALS:
            signal.signal(sig, _exit_130)


class StopFlag:
    """Set by SIGINT/SIGTERM; while ``raising`` is true the handler also raises Interrupted."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signame: str | None = None
        self.raising = True

    def is_set(self) -> bool:
        return self.event.is_set()

    def handler(self, signum, frame) -> None:
        self.signame = signal.Signals(signum).name
        self.event.set()
        if self.raising:
            if in_c_callback(frame):  # an exception raised here would be printed and dropped
                _redeliver(signum)
                return
            self.raising = False  # once: the clean-up that follows is never interrupted again
            raise Interrupted(self.signame)


@contextlib.contextmanager
def stop_on_signals():
    """Install :class:`StopFlag` as the SIGINT/SIGTERM handler (main thread only; elsewhere
    the flag is returned but never set by a signal)."""
    flag = StopFlag()
    if threading.current_thread() is not threading.main_thread():
        flag.raising = False
        yield flag
        return
    previous = {sig: signal.signal(sig, flag.handler) for sig in SIGNALS}
    try:
        yield flag
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h)


@contextlib.contextmanager
def raising_signals():
    """SIGINT and SIGTERM both raise :class:`Interrupted` (a KeyboardInterrupt) inside the
    block, so code that cleans up on Ctrl-C does the same on SIGTERM (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, raise_interrupted) for sig in SIGNALS}
    try:
        yield
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h)
