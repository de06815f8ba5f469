"""Error-scheduled proportional gain, eq (3.34), with the seed's tables as presets."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.kernels import kernel


@dataclass(frozen=True, slots=True)
class GainSchedule:
    """K(e) = (G_max - G_min) / exp(|e| K_min) + G_min, eq (3.34).

    The gain is G_max at zero error and decays to G_min for large errors. Units of the
    gains are those of (controller output) / (error): 1/s for the speed loop (a_r per m/s),
    dimensionless for the steering-rate loop (rad/s per rad/s).
    """

    g_min: float  # gain for large errors
    g_max: float  # gain at zero error
    k_min: float  # decay rate [1/(error unit)]


SPEED_GAINS_CAR = GainSchedule(g_min=0.27, g_max=8.0, k_min=1.0)
"""Table 3.4: linear-velocity schedule for the passenger car."""
SPEED_GAINS_POOR = GainSchedule(g_min=0.2, g_max=3.0, k_min=1.0)
"""Table 3.12: the deliberately poor linear-velocity schedule of case 3.3.2.2."""
SPEED_GAINS_TRUCK = GainSchedule(g_min=0.05, g_max=1.3, k_min=1.0)
"""Table 3.6: linear-velocity schedule for the small truck."""
YAW_GAINS = GainSchedule(g_min=1.0, g_max=9.0, k_min=10.0)
"""Table 3.7: angular-velocity schedule."""
YAW_GAINS_RETUNED = GainSchedule(g_min=0.7, g_max=3.0, k_min=10.0)
"""Table 3.8: re-tuned angular-velocity schedule (used in section 3.3)."""

GAIN_PRESETS: dict[str, GainSchedule] = {
    "table_3_4": SPEED_GAINS_CAR,
    "table_3_6": SPEED_GAINS_TRUCK,
    "table_3_7": YAW_GAINS,
    "table_3_8": YAW_GAINS_RETUNED,
    "table_3_12": SPEED_GAINS_POOR,
}


@kernel
def scheduled_gain(error, g_min, g_max, k_min):
    """K(e) = (G_max - G_min) exp(-|e| K_min) + G_min, eq (3.34) (scalar or array e)."""
    return (g_max - g_min) * np.exp(-np.abs(error) * k_min) + g_min


@kernel
def p_law(reference, actual, g_min, g_max, k_min):
    """The scheduled proportional law K(e) e with e = reference - actual (3.32-3.33, 3.35-3.37)."""
    e = reference - actual
    return scheduled_gain(e, g_min, g_max, k_min) * e


SPEED_G_MIN, SPEED_G_MAX, SPEED_K_MIN, YAW_G_MIN, YAW_G_MAX, YAW_K_MIN = range(6)
"""Columns of the members' gain rows (sim/fleet.py Fleet.gains): g_min, g_max, k_min of the
speed loop's schedule, then of the yaw loop's."""


@kernel
def speed_law(gains, i, reference, actual):
    """Member i's speed loop (3.32-3.34) on its gain row: a_r [m/s^2] from the speeds [m/s]."""
    return p_law(reference, actual, gains[i, SPEED_G_MIN], gains[i, SPEED_G_MAX],
                 gains[i, SPEED_K_MIN])


@kernel
def yaw_law(gains, i, reference, actual):
    """Member i's steering-rate loop (3.37) on its gain row [rad/s] from the yaw rates [rad/s]."""
    return p_law(reference, actual, gains[i, YAW_G_MIN], gains[i, YAW_G_MAX], gains[i, YAW_K_MIN])


FOLLOW_ERROR_MAX = 5.0
"""Largest speed error [m/s] over which a member's speed law is asked for its acceleration
(:func:`law_peak`): a reference the member can follow only further behind is not followed."""
FOLLOW_SHARE = 0.9
"""Share of a speed law's peak output the virtual car may ask of the members [-]: at the peak
the member's speed error would have no room left to grow."""


def law_peak(g_min: float, g_max: float, k_min: float, e_max: float = FOLLOW_ERROR_MAX) -> float:
    """Largest |K(e) e| of the scheduled law (3.34) for speed errors |e| <= ``e_max`` [m/s]:
    the largest acceleration [m/s^2] the law asks while the member lags or leads its speed
    reference by at most e_max (Table 3.6's truck: 0.513 m/s^2 at e = 1.12 m/s, docs/model.md)."""
    e = np.linspace(0.0, e_max, 50001)
    return float(np.max(np.abs(scheduled_gain(e, g_min, g_max, k_min) * e)))


def as_float(x):
    """x as a float64 array (numba compiles one signature for arrays, one for floats)."""
    a = np.asarray(x, dtype=np.float64)
    return float(a) if a.ndim == 0 else np.ascontiguousarray(a)


def gain(error, sched: GainSchedule):
    """Scheduled gain K(error), eq (3.34); broadcasts over ``error``."""
    return scheduled_gain(as_float(error), sched.g_min, sched.g_max, sched.k_min)


def apply(reference, actual, sched: GainSchedule):
    """:func:`p_law` with the gains of ``sched`` (arrays or floats, broadcast)."""
    r, a = np.broadcast_arrays(np.asarray(reference, float), np.asarray(actual, float))
    return p_law(as_float(r), as_float(a), sched.g_min, sched.g_max, sched.k_min)
