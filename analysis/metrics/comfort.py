"""Ride-comfort metrics: acceleration bands, longitudinal limit, jerk.

Comfort limits are the seed's (formation_control_thesis, section 3.1.2 and 3.1.5); the
ISO 2631-1 frequency-weighted value lives in :mod:`analysis.metrics.iso2631`.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.signal import savgol_filter

from analysis.metrics.signals import check_dt

__all__ = [
    "LAT_ACC_COMFORTABLE",
    "LAT_ACC_MEDIUM",
    "LAT_ACC_UNCOMFORTABLE",
    "LAT_BAND_EDGES",
    "LAT_BAND_NAMES",
    "LON_ACC_COMFORT",
    "JERK_WINDOW_S",
    "JERK_POLYORDER",
    "savgol_window_samples",
    "jerk",
    "jerk_window_mean",
    "emergency_mask",
    "band_times",
]

LAT_ACC_COMFORTABLE = 1.8
"""Upper lateral-acceleration limit of the "comfortable" level [m/s^2] (seed section
3.1.2, after its reference [37])."""

LAT_ACC_MEDIUM = 3.6
"""Upper lateral-acceleration limit of the "medium comfortable" level [m/s^2] (seed
section 3.1.2); also the design limit of section 3.3.1."""

LAT_ACC_UNCOMFORTABLE = 5.0
"""Upper lateral-acceleration limit of the "uncomfortable" level [m/s^2] (seed section
3.1.2); above it the seed names no level, we call it "beyond"."""

LAT_BAND_EDGES: tuple[float, ...] = (0.0, LAT_ACC_COMFORTABLE, LAT_ACC_MEDIUM,
                                     LAT_ACC_UNCOMFORTABLE, math.inf)
"""Edges of the lateral comfort bands on ``|a_lat|`` [m/s^2]; band k is
``[edge_k, edge_k+1)`` (seed section 3.1.2)."""

LAT_BAND_NAMES: tuple[str, ...] = ("comfortable", "medium", "uncomfortable", "beyond")
"""Names of the bands delimited by :data:`LAT_BAND_EDGES`."""

LON_ACC_COMFORT = 2.0
"""Longitudinal acceleration below which a ride is comfortable [m/s^2] (seed section
3.1.5, after its references [44-46])."""

JERK_WINDOW_S = 0.5
"""Default Savitzky-Golay window span for jerk, first to last sample [s]."""

JERK_MEAN_WINDOW_S = 1.0
"""Averaging window of the ISO 15622 jerk bound [s]."""

JERK_ACC_LIMIT = 2.5
"""ISO 15622 (ACC) bound on the jerk averaged over :data:`JERK_MEAN_WINDOW_S` [m/s^3]."""

EMERGENCY_SETTLE_S = 3.0
"""After an emergency brake ends, this long is still counted as part of it [s] (the members'
speed loops settle)."""

JERK_POLYORDER = 3
"""Default Savitzky-Golay polynomial order for jerk [-]. With the 0.5 s window, order 3
keeps the jerk amplitude of a sinusoid within 0.1 % at 0.5 Hz and 1.2 % at 1 Hz; order 2
(a local straight-line slope) loses 6 % and 23 %."""


def savgol_window_samples(window_s: float, dt: float, polyorder: int) -> int:
    """Odd number of samples whose span best matches a window length.

    Parameters
    ----------
    window_s : float
        Wanted span from the first to the last sample of the window [s].
    dt : float
        Sample spacing [s].
    polyorder : int
        Polynomial order; the window has at least ``polyorder + 2`` samples (rounded up to
        odd) so the fit is a least-squares one.

    Returns
    -------
    int
        Window length in samples (odd). Its span is ``(n - 1) * dt``.
    """
    check_dt(dt)
    if not window_s > 0:
        raise ValueError(f"window_s must be positive [s], got {window_s!r}")
    if polyorder < 1:
        raise ValueError(f"polyorder must be >= 1 for a derivative, got {polyorder!r}")
    n = int(round(window_s / dt)) + 1
    if n % 2 == 0:
        n += 1
    smallest = polyorder + 2 if (polyorder + 2) % 2 else polyorder + 3
    return max(n, smallest)


def jerk(a, dt: float, window_s: float = JERK_WINDOW_S, polyorder: int = JERK_POLYORDER,
         axis: int = -1) -> np.ndarray:
    """Jerk as the Savitzky-Golay derivative of an acceleration signal.

    Parameters
    ----------
    a : array_like
        Acceleration, uniformly sampled and finite [m/s^2].
    dt : float
        Sample spacing [s] (``delta`` of :func:`scipy.signal.savgol_filter`).
    window_s : float
        Window span, first to last sample [s]; see :func:`savgol_window_samples`.
    polyorder : int
        Order of the local polynomial [-].
    axis : int
        Time axis.

    Returns
    -------
    ndarray
        ``da/dt`` [m/s^3], same shape as ``a``. Edges use a polynomial fit to the edge
        window (``mode="interp"``).

    Raises
    ------
    ValueError
        If the signal is shorter than the window.

    Notes
    -----
    Savitzky and Golay, Anal. Chem. 36 (1964) 1627. The filter attenuates fast content:
    for the default 0.5 s / order 3 the gain on a sinusoid's derivative is 0.999 at 0.5 Hz,
    0.988 at 1 Hz and 0.85 at 2 Hz.

    Examples
    --------
    >>> t = np.arange(0.0, 2.0, 0.01)
    >>> float(np.round(jerk(3.0 * t, 0.01)[100], 6))
    3.0
    """
    a = np.asarray(a, dtype=float)
    n = savgol_window_samples(window_s, dt, polyorder)
    if a.shape[axis] < n:
        raise ValueError(
            f"signal has {a.shape[axis]} samples, shorter than the {n}-sample "
            f"({(n - 1) * dt:g} s) Savitzky-Golay window")
    return savgol_filter(a, n, polyorder, deriv=1, delta=dt, axis=axis, mode="interp")


def band_times(a, dt: float, edges=LAT_BAND_EDGES, axis: int = -1) -> np.ndarray:
    """Time spent with ``|a|`` in each band ``[edges[k], edges[k+1])``.

    Parameters
    ----------
    a : array_like
        Acceleration [m/s^2]; non-finite samples count in no band.
    dt : float
        Sample spacing [s]; each sample stands for the interval it starts.
    edges : sequence of float
        Increasing band edges [m/s^2]; default the seed's lateral comfort bands
        (:data:`LAT_BAND_EDGES`, section 3.1.2).
    axis : int
        Time axis.

    Returns
    -------
    ndarray
        Shape ``a.shape`` without ``axis`` plus a last axis of ``len(edges) - 1`` bands:
        time per band [s].
    """
    check_dt(dt)
    edges = np.asarray(edges, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError(f"edges must be a strictly increasing sequence, got {edges!r}")
    mag = np.abs(np.moveaxis(np.asarray(a, dtype=float), axis, -1))
    lo, hi = edges[:-1], edges[1:]
    inside = (mag[..., None, :] >= lo[:, None]) & (mag[..., None, :] < hi[:, None])
    return np.count_nonzero(inside, axis=-1) * dt


def jerk_window_mean(a, dt: float, window_s: float = JERK_MEAN_WINDOW_S) -> np.ndarray:
    """Jerk averaged over ``window_s`` [m/s^3]: (a(t + window) - a(t)) / window, ISO 15622.

    Parameters
    ----------
    a : array_like
        Acceleration samples [m/s^2], evenly spaced.
    dt : float
        Sample spacing [s].
    window_s : float
        Averaging window [s]; default 1 s.

    Returns
    -------
    ndarray
        Entry i belongs to the window starting at sample i; the last ``window_s / dt``
        entries are NaN, and so is every window with a NaN at either end.

    Examples
    --------
    >>> float(jerk_window_mean(np.arange(0.0, 3.0, 0.1) * 2.0, 0.1)[0])
    2.0
    """
    a = np.asarray(a, dtype=float)
    n = max(1, int(round(window_s / dt)))
    out = np.full(a.size, np.nan)
    if a.size > n:
        out[:-n] = (a[n:] - a[:-n]) / (n * dt)
    return out


def emergency_mask(t, starts, ends, settle_s: float = EMERGENCY_SETTLE_S,
                   window_s: float = JERK_MEAN_WINDOW_S) -> np.ndarray:
    """True at times ``t`` [s] whose jerk window touches an emergency brake.

    Parameters
    ----------
    t : array_like
        Window start times [s].
    starts : array_like
        Times of the ``emergency_brake`` events [s].
    ends : array_like
        Times of the ``emergency_end`` events [s]; an emergency runs from a start to the
        next end after it (or the end of the record).
    settle_s : float
        Time after an end still counted as part of the emergency [s].
    window_s : float
        Length of the jerk window [s].

    Returns
    -------
    ndarray of bool
        True where ``start - window_s < t < end + settle_s`` for some emergency.
    """
    t = np.asarray(t, dtype=float)
    mask = np.zeros(t.size, dtype=bool)
    ends = np.sort(np.asarray(ends, dtype=float))
    for s0 in np.sort(np.asarray(starts, dtype=float)):
        later = ends[ends >= s0]
        e0 = later[0] if later.size else np.inf
        mask |= (t > s0 - window_s) & (t < e0 + settle_s)
    return mask
