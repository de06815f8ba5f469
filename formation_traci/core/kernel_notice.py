"""What the user is told while the package's kernels compile (the first run after install, or
after the package changed: a cold numba cache).

* the notice, once, when numba starts compiling one of our kernels, with how long it takes
  at most (:data:`QUIET_S`, :data:`BUSY_S`: measured, benchmarks/RESULTS.md);
* a kernel whose compilation fails: one line naming it and the error (the error itself goes on
  as before: the run fails, its run.json and error.txt say why);
* a compilation longer than :data:`SLOW_S`: one line then and every :data:`SLOW_S` after
  (compiling is not stopped: an interrupt stops it; kernels compiled so far stay cached);
* :func:`finished` (sim/warm.py, after the other scenario kinds' kernels): the time it took.

Time compiling counts from a top-level compilation's start to its end (nested ones inside),
summed over the process.
"""
from __future__ import annotations

import sys
import threading
import time

from numba.core import event

QUIET_S = 75
"""The longest compilation of a cold start measured on a quiet 2-core machine [s]: a road run's
kernels (with the fused step's) and the maneuver, [comm] and free-space ones
(sim/warm.py): 60-62 s measured from a fresh clone (the README's first command, quiet), so
~75 s with a margin (benchmarks/RESULTS.md)."""
BUSY_S = 160
"""The longest measured, on the 2-core machine running two test suites beside it (the README's
first command from a fresh clone) [s]."""
SLOW_S = 200.0
"""Compiling longer than this [s] is said to be slow (and again every as many seconds)."""
NOTICE = "formation-traci: compiling the numba kernels (first run only, cached afterwards)"
"""The notice's first words (tests and benchmarks/startup.py look for them)."""


def _now() -> float:
    return time.monotonic()


class CompileWatch(event.Listener):
    """numba's ``numba:compile`` events of our kernels: the notice, failures, slowness."""

    def __init__(self, out=None, slow_s: float = SLOW_S):
        self.out = out
        self.slow_s = slow_s
        self.printed = False  # the notice (a kernel of ours compiled in this process)
        self.depth = 0  # nested compilations under way
        self.started = None  # monotonic time the current top-level compilation started
        self.spent = 0.0  # [s] compiling, top-level compilations that ended
        self.warned = 0  # slow notices printed
        self.failed = None  # the innermost kernel whose compilation failed, until it is said
        self._thread = None
        self._stop = threading.Event()

    def _say(self, text: str) -> None:
        print(text, file=self.out or sys.stderr, flush=True)

    def compiling_s(self) -> float:
        """Seconds spent compiling our kernels in this process so far."""
        run = 0.0 if self.started is None else _now() - self.started
        return self.spent + run

    def on_start(self, ev):
        disp = (ev.data or {}).get("dispatcher")
        mod = getattr(getattr(disp, "py_func", None), "__module__", "") or ""
        if self.depth == 0 and not mod.startswith("formation_traci"):
            return  # not ours (a law rebound from outside the package is ours: formation_traci.*)
        if self.depth == 0:
            self.started = _now()
        self.depth += 1
        if not self.printed:
            self.printed = True
            self._say(f"{NOTICE}: at most ~{QUIET_S} s on a quiet 2-core machine, "
                      f"~{BUSY_S} s on a busy one")
            self._thread = threading.Thread(target=self._watch, name="compile-watch", daemon=True)
            self._thread.start()

    def on_end(self, ev):
        if self.depth == 0:
            return  # not ours
        self.depth -= 1
        # the exception a compilation ended with (numba's Event.is_failed reads it backwards)
        exc = (getattr(ev, "_exc_details", None) or (None, None, None))[1]
        if exc is not None and self.failed is None:  # the innermost failure ends first
            f = getattr((ev.data or {}).get("dispatcher"), "py_func", None)
            self.failed = f"{getattr(f, '__module__', '?')}.{getattr(f, '__qualname__', '?')}"
        if self.depth:
            return
        self.spent += _now() - self.started
        self.started = None
        if exc is not None:
            lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
            self._say(f"formation-traci: compiling kernel {self.failed} failed after "
                      f"{self.compiling_s():.1f} s: {type(exc).__name__}: {(lines or [''])[0][:300]}")
        self.failed = None

    def _watch(self) -> None:
        """Says once every :attr:`slow_s` of compiling that it is still going on."""
        while not self._stop.wait(0.5):
            if self.started is not None and self.compiling_s() >= self.slow_s * (self.warned + 1):
                self.warned += 1
                self._say(f"formation-traci: still compiling the numba kernels after "
                          f"{self.compiling_s():.0f} s, longer than the ~{BUSY_S} s measured on a "
                          f"busy 2-core machine: the machine is loaded or slow (Ctrl-C stops the "
                          f"run; the kernels compiled so far stay cached)")

    def finished(self) -> None:
        """The compilation is over (every scenario kind's kernels): says how long it took."""
        self._stop.set()
        if self.printed:
            self._say(f"formation-traci: the numba kernels compiled in {self.compiling_s():.1f} s "
                      f"(this run's and the maneuver, [comm] and free-space ones; cached for "
                      f"later runs)")


WATCH = CompileWatch()
event.register("numba:compile", WATCH)
