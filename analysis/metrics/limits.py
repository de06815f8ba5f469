"""Operating limits of the seed's section 3.3.1 ("Assumptions and Limitations").

Each limit is a boolean mask per sample; :func:`exceedance` turns a mask into the time
spent beyond the limit and the number of separate episodes. Comparisons with NaN are
False, so a missing sample never counts as a violation.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from analysis.metrics.comfort import LAT_ACC_MEDIUM
from analysis.metrics.signals import count_episodes, time_where

__all__ = [
    "SLIP_ANGLE_LIMIT",
    "LAT_ACC_LIMIT",
    "FRICTION_USAGE_LIMIT",
    "GRAVITY",
    "Exceedance",
    "exceedance",
    "slip_mask",
    "traction_mask",
    "friction_mask",
    "lat_acc_mask",
    "friction_usage",
]

SLIP_ANGLE_LIMIT = math.radians(4.0)
"""Largest admissible tire slip angle [rad] (4 deg): seed section 3.3.1, from section
3.1.3 where the linearised magic formula (3.12) holds below 4 deg (Fig. 3.8)."""

LAT_ACC_LIMIT = LAT_ACC_MEDIUM
"""Largest admissible lateral acceleration [m/s^2] (3.6): seed section 3.3.1, the medium
comfort limit of section 3.1.2."""

FRICTION_USAGE_LIMIT = 1.0
"""Friction circle (seed eq. 3.16, section 3.1.5): ``sqrt(a_lon^2 + a_lat^2) / (mu g)``
must stay below 1 [-]."""

GRAVITY = 9.81
"""Gravitational acceleration g used in eq. 3.16 [m/s^2]."""


class Exceedance(NamedTuple):
    """Time beyond a limit and number of separate episodes."""

    time_s: float | np.ndarray  # s
    episodes: int | np.ndarray  # -


def exceedance(mask, dt: float, axis: int = -1) -> Exceedance:
    """Time and number of episodes during which a limit is exceeded.

    Parameters
    ----------
    mask : array_like of bool
        True where the limit is exceeded, uniformly sampled.
    dt : float
        Sample spacing [s].
    axis : int
        Time axis.

    Returns
    -------
    Exceedance
        ``time_s`` = ``count(mask) * dt`` [s]; ``episodes`` = number of runs of
        consecutive True samples [-].

    Examples
    --------
    >>> r = exceedance([False, True, True, False, True], 0.5)
    >>> float(r.time_s), r.episodes
    (1.5, 2)
    """
    m = np.asarray(mask, dtype=bool)
    return Exceedance(time_where(m, dt, axis=axis), count_episodes(m, axis=axis))


def slip_mask(slip_front, slip_rear, limit: float = SLIP_ANGLE_LIMIT) -> np.ndarray:
    """Samples where either tire slip angle exceeds the limit.

    Parameters
    ----------
    slip_front : array_like
        Front slip angle alpha_f, eq. 3.7 [rad].
    slip_rear : array_like
        Rear slip angle alpha_r, eq. 3.8 [rad].
    limit : float
        Limit on ``|alpha|`` [rad]; default :data:`SLIP_ANGLE_LIMIT`.

    Returns
    -------
    ndarray of bool
        ``|alpha_f| > limit or |alpha_r| > limit``.
    """
    with np.errstate(invalid="ignore"):
        return (np.abs(np.asarray(slip_front, float)) > limit) | (
            np.abs(np.asarray(slip_rear, float)) > limit)


def traction_mask(traction_force, traction_force_max) -> np.ndarray:
    """Samples where the traction force exceeds the adhesion limit.

    Parameters
    ----------
    traction_force : array_like
        Applied longitudinal force F_lf, eq. 3.13 [N].
    traction_force_max : array_like
        Adhesion limit of the driven axle, eq. 3.14 [N].

    Returns
    -------
    ndarray of bool
        ``F_lf > F_lf_max`` (seed section 3.3.1: tires must not spin).
    """
    with np.errstate(invalid="ignore"):
        return np.asarray(traction_force, float) > np.asarray(traction_force_max, float)


def friction_mask(usage, limit: float = FRICTION_USAGE_LIMIT) -> np.ndarray:
    """Samples where the friction circle is violated.

    Parameters
    ----------
    usage : array_like
        Friction usage ``sqrt(a_lon^2 + a_lat^2) / (mu g)`` [-].
    limit : float
        Limit [-]; default :data:`FRICTION_USAGE_LIMIT` (eq. 3.16).

    Returns
    -------
    ndarray of bool
        ``usage > limit``.
    """
    with np.errstate(invalid="ignore"):
        return np.asarray(usage, float) > limit


def lat_acc_mask(a_lat, limit: float = LAT_ACC_LIMIT) -> np.ndarray:
    """Samples where the lateral acceleration exceeds the limit.

    Parameters
    ----------
    a_lat : array_like
        Lateral acceleration [m/s^2].
    limit : float
        Limit on ``|a_lat|`` [m/s^2]; default :data:`LAT_ACC_LIMIT`.

    Returns
    -------
    ndarray of bool
        ``|a_lat| > limit``.
    """
    with np.errstate(invalid="ignore"):
        return np.abs(np.asarray(a_lat, float)) > limit


def friction_usage(a_lon, a_lat, mu: float, g: float = GRAVITY) -> np.ndarray:
    """Friction usage from the accelerations (seed eq. 3.16).

    Parameters
    ----------
    a_lon : array_like
        Longitudinal acceleration [m/s^2].
    a_lat : array_like
        Lateral acceleration [m/s^2].
    mu : float
        Road adhesion coefficient [-] (seed Table 3.3).
    g : float
        Gravitational acceleration [m/s^2].

    Returns
    -------
    ndarray
        ``sqrt(a_lon^2 + a_lat^2) / (mu g)`` [-].
    """
    if not (np.isfinite(mu) and mu > 0):
        raise ValueError(f"mu must be a positive adhesion coefficient, got {mu!r}")
    return np.hypot(np.asarray(a_lon, float), np.asarray(a_lat, float)) / (mu * g)
