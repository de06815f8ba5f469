"""Communication channel between the virtual car and the members: a Reference transform.

:class:`Delay` hands member i the virtual car as it was ``delays_s[i]`` seconds ago (a whole
number of control periods; before that much history exists, the oldest copy). The recorded
virtual car (``Reference.truth``) stays the true one, so the analysis measures what the delay
costs. Plug in with ``run_scenario(..., transforms=[Delay(...)])``; no kernel changes.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from .reference import Reference


class Delay:
    """Per-member transport delay of the virtual car's state [s] (see the module docstring)."""

    def __init__(self, delays_s, dt_control: float):
        self.lag = np.round(np.asarray(delays_s, dtype=float) / dt_control).astype(int)
        if np.any(self.lag < 0):
            raise ValueError("delays must be >= 0")
        self.history: deque = deque(maxlen=int(self.lag.max(initial=0)) + 1)

    def __call__(self, ref: Reference) -> Reference:
        vc = ref.vc.copy()
        for j in range(ref.n_ctrl):
            self.history.append(ref.vc[j].copy())  # what is sent in period j
            for i, lag in enumerate(self.lag):
                vc[j, i] = self.history[max(len(self.history) - 1 - lag, 0)][i]
        return ref.with_(vc=vc)
