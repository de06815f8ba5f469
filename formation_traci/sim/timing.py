"""Wall-clock time per phase of the step loop, accumulated into run.json's ``timing_s``."""
from __future__ import annotations

import time


class PhaseClock:
    """``lap(phase)`` adds the time since the previous lap to ``totals[phase]`` [s]."""

    def __init__(self, totals: dict[str, float]):
        self.totals = totals
        self.last = time.perf_counter()

    def start(self) -> None:
        self.last = time.perf_counter()

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.totals[phase] = self.totals.get(phase, 0.0) + (now - self.last)
        self.last = now
