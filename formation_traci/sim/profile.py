"""Piecewise time profiles for the virtual car's speed and yaw rate, with exact derivatives."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np


@dataclass(frozen=True, slots=True)
class Profile:
    """A scalar signal of time given at knots, held constant outside them.

    ``interp="linear"`` joins the knots with straight lines (derivative piecewise
    constant); ``interp="smooth"`` joins them with a smoothstep (C1: derivative zero at
    every knot), which keeps jerk finite.
    """

    t: tuple[float, ...]  # knot times [s], strictly increasing
    values: tuple[float, ...]  # values at the knots [signal unit]
    interp: Literal["linear", "smooth"] = "linear"

    @classmethod
    def constant(cls, value: float) -> "Profile":
        return cls((0.0,), (float(value),))

    def __call__(self, t: float) -> tuple[float, float]:
        """Value and time derivative at time t [s]."""
        ts, vs = self.t, self.values
        if len(ts) == 1 or t <= ts[0]:
            return vs[0], 0.0
        if t >= ts[-1]:
            return vs[-1], 0.0
        i = int(np.searchsorted(ts, t, side="right")) - 1
        t0, t1, v0, v1 = ts[i], ts[i + 1], vs[i], vs[i + 1]
        span = t1 - t0
        s = (t - t0) / span
        if self.interp == "linear":
            return v0 + (v1 - v0) * s, (v1 - v0) / span
        return v0 + (v1 - v0) * s * s * (3.0 - 2.0 * s), (v1 - v0) * 6.0 * s * (1.0 - s) / span
