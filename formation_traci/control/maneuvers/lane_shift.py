"""Formation maneuvers as Reference transforms: slots that move over time.

:class:`LaneShift` moves one member's lateral slot offset dy from ``dy_from`` to ``dy_to`` [m]
between ``t0`` and ``t0 + duration`` [s] with a smoothstep (C1: lateral speed zero at both
ends), giving the kernels dy, dy' and dy'' so the desired point's velocity and acceleration
stay exact (control/formation.py rigid_target_at, road/targets.py road_target_at). Plug in
with ``run_scenario(..., transforms=[LaneShift(...)])``; no kernel changes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..reference import Reference


@dataclass(frozen=True)
class LaneShift:
    """Member ``member`` (index) shifts its slot sideways (see the module docstring)."""

    member: int
    dy_from: float  # [m]
    dy_to: float  # [m]
    t0: float  # [s]
    duration: float  # [s]

    def offset(self, t: float) -> tuple[float, float, float]:
        """dy [m], dy' [m/s], dy'' [m/s^2] at time t [s]."""
        T, span = self.duration, self.dy_to - self.dy_from
        s = min(max((t - self.t0) / T, 0.0), 1.0)
        moving = 0.0 < (t - self.t0) < T
        return (self.dy_from + span * s * s * (3.0 - 2.0 * s),
                span * 6.0 * s * (1.0 - s) / T if moving else 0.0,
                span * 6.0 * (1.0 - 2.0 * s) / T ** 2 if moving else 0.0)

    def __call__(self, ref: Reference) -> Reference:
        slots = ref.slots.copy()
        for j in range(ref.n_ctrl):
            slots[j, self.member, 1], slots[j, self.member, 3], slots[j, self.member, 5] = \
                self.offset(ref.t + j * ref.dt)
        return ref.with_(slots=slots)
