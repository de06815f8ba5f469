"""Generic statistics over uniformly sampled signals.

Every function works along ``axis`` (default the last one) of an N-d array and returns SI
values in the unit of its input (times in s). Statistics (``rms``, ``peak_abs``,
``percentile_abs``) ignore non-finite samples and return NaN when a slice has none;
integrals need finite input (a non-finite sample makes the result NaN).
"""
from __future__ import annotations

import warnings

import numpy as np

__all__ = [
    "rms",
    "peak_abs",
    "percentile_abs",
    "trapezoid_integral",
    "time_where",
    "count_episodes",
    "contiguous_segments",
]


def _finite_or_nan(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return np.where(np.isfinite(x), x, np.nan)


def rms(x, axis: int = -1):
    """Root mean square, ignoring non-finite samples.

    Parameters
    ----------
    x : array_like
        Signal [any unit].
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        ``sqrt(mean(x**2))`` [unit of ``x``]; NaN where a slice has no finite sample.

    Examples
    --------
    >>> float(rms([3.0, -3.0]))
    3.0
    """
    x = _finite_or_nan(x)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.sqrt(np.nanmean(x * x, axis=axis))


def peak_abs(x, axis: int = -1):
    """Largest absolute value, ignoring non-finite samples.

    Parameters
    ----------
    x : array_like
        Signal [any unit].
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        ``max(|x|)`` [unit of ``x``]; NaN where a slice has no finite sample.
    """
    x = np.abs(_finite_or_nan(x))
    if x.shape[axis] == 0:
        return np.full(np.sum(x, axis=axis).shape, np.nan)[()]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmax(x, axis=axis)


def percentile_abs(x, q: float = 95.0, axis: int = -1):
    """Percentile of the absolute value, ignoring non-finite samples.

    Parameters
    ----------
    x : array_like
        Signal [any unit].
    q : float
        Percentile in [0, 100] [%]. Linear interpolation between samples (numpy default).
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        ``q``-th percentile of ``|x|`` [unit of ``x``]; NaN where a slice has no finite
        sample.
    """
    if not 0.0 <= q <= 100.0:
        raise ValueError(f"q must be in [0, 100], got {q!r}")
    x = np.abs(_finite_or_nan(x))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanpercentile(x, q, axis=axis)


def trapezoid_integral(x, dt: float, axis: int = -1):
    """Trapezoidal time integral of a uniformly sampled signal.

    Parameters
    ----------
    x : array_like
        Signal [any unit].
    dt : float
        Sample spacing [s].
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        ``integral x dt`` [unit of ``x`` times s]; 0 for fewer than two samples.
    """
    check_dt(dt)
    x = np.asarray(x, dtype=float)
    return np.trapezoid(x, dx=dt, axis=axis)


def time_where(mask, dt: float, axis: int = -1):
    """Time during which a condition holds, one sample = ``dt``.

    Parameters
    ----------
    mask : array_like of bool
        Condition per sample.
    dt : float
        Sample spacing [s].
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        ``count(mask) * dt`` [s] (each sample stands for the interval it starts).
    """
    check_dt(dt)
    return np.count_nonzero(np.asarray(mask, dtype=bool), axis=axis) * dt


def count_episodes(mask, axis: int = -1):
    """Number of separate runs of consecutive ``True`` samples.

    Parameters
    ----------
    mask : array_like of bool
        Condition per sample.
    axis : int
        Time axis.

    Returns
    -------
    ndarray or int
        Number of rising edges, counting a run that starts at the first sample.

    Examples
    --------
    >>> int(count_episodes([True, True, False, True, False, False, True]))
    3
    """
    m = np.asarray(mask, dtype=bool)
    m = np.moveaxis(m, axis, -1)
    if m.shape[-1] == 0:
        return np.zeros(m.shape[:-1], dtype=int) if m.ndim > 1 else 0
    starts = m[..., 0].astype(int) + np.count_nonzero(m[..., 1:] & ~m[..., :-1], axis=-1)
    return int(starts) if np.ndim(starts) == 0 else starts


def contiguous_segments(t, dt: float, gap_factor: float = 1.5) -> list[slice]:
    """Split a sorted 1-D time vector into runs without gaps.

    Parameters
    ----------
    t : array_like
        Sample times, sorted ascending [s].
    dt : float
        Nominal sample spacing [s].
    gap_factor : float
        A step larger than ``gap_factor * dt`` starts a new segment [-].

    Returns
    -------
    list of slice
        Index slices of ``t``, one per contiguous segment, in time order.
    """
    check_dt(dt)
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"t must be 1-D, got shape {t.shape}")
    if t.size == 0:
        return []
    breaks = np.nonzero(np.diff(t) > gap_factor * dt)[0] + 1
    bounds = np.concatenate(([0], breaks, [t.size]))
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]


def check_dt(dt: float) -> None:
    """Raise ValueError unless ``dt`` (a sample spacing [s]) is positive and finite."""
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive finite sample spacing [s], got {dt!r}")
