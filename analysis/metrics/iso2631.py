"""ISO 2631-1 weighted r.m.s. acceleration, crest factor and vibration total value.

The frequency weighting itself (ISO 2631-1:1997 Annex A, its digital form and the
sample-rate rule that decides when a weighted value is reported) is in
:mod:`analysis.metrics.iso2631_weighting`; its names are re-exported here. The weighted value is
reported when the digital Wd is valid up to :data:`WD_MIN_UPPER_HZ` (8 Hz, i.e. ``fs`` >=
about 66 Hz) and the record lasts :data:`MIN_DURATION_S`; otherwise it is NaN and the
result says why.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from analysis.metrics.iso2631_weighting import (ISO_FREQ_RANGE_HZ, WD, WD_TABLE, WD_TABLE_HZ,
                                                WD_TOLERANCE, WK, WeightingParams, analog_response,
                                                analog_sections, digital_response, digital_sos,
                                                min_sample_rate, valid_upper_frequency)
from analysis.metrics.signals import check_dt

__all__ = [
    "WeightingParams",
    "WD",
    "WK",
    "ISO_FREQ_RANGE_HZ",
    "WD_TABLE_HZ",
    "WD_TABLE",
    "WD_TOLERANCE",
    "WD_MIN_UPPER_HZ",
    "MIN_DURATION_S",
    "COMFORT_K_XY",
    "WeightedRMS",
    "analog_sections",
    "analog_response",
    "digital_sos",
    "digital_response",
    "valid_upper_frequency",
    "min_sample_rate",
    "weight",
    "weighted_rms",
    "vibration_total_value",
    "CREST_FACTOR_LIMIT",
    "MTVV_TAU_S",
    "running_rms_max",
    "vibration_dose_value",
]


WD_MIN_UPPER_HZ = 8.0
"""Lowest acceptable upper edge of the valid band [Hz]. Up to 8 Hz Wd weighs at least
0.25 (Table 3); above it content is attenuated by 12 dB or more."""

MIN_DURATION_S = 10.0
"""Shortest record for a weighted r.m.s. [s]: five periods of the 0.5 Hz lower edge of
the ISO range (our choice; ISO 2631-1 5.5 asks for a duration giving reasonable
statistical precision)."""

CREST_FACTOR_LIMIT = 9.0
"""Crest factor above which the basic r.m.s. method may underestimate the effect of
occasional shocks (ISO 2631-1:1997 6.2.1): then the additional methods of 6.3 (MTVV, VDV)
are reported with it [-]."""

MTVV_TAU_S = 1.0
"""Integration time of the running r.m.s. of the MTVV (ISO 2631-1:1997 6.3.1: 1 s) [s]."""

COMFORT_K_XY = 1.0
"""Multiplying factor k for x and y at the seat surface for comfort [-]
(ISO 2631-1:1997 8.2)."""


@dataclass(frozen=True, slots=True)
class WeightedRMS:
    """Result of :func:`weighted_rms`."""

    value: float | np.ndarray  # m/s^2, NaN when not reportable
    crest_factor: float | np.ndarray  # -, peak |a_w| / a_w (ISO 2631-1 6.2: basic method if <= 9)
    band_hz: tuple[float, float]  # Hz, band in which the digital Wd is within tolerance
    full_band: bool  # the band reaches the ISO upper limit of 80 Hz
    reason: str | None  # why ``value`` is NaN or partial, None if fully compliant
    mtvv: float | np.ndarray = np.nan  # m/s^2, maximum transient vibration value (6.3.1)
    vdv: float | np.ndarray = np.nan  # m/s^1.75, fourth power vibration dose value (6.3.2)


def weight(a, dt: float, axis: int = -1, p: WeightingParams = WD) -> np.ndarray:
    """Frequency-weighted acceleration.

    Parameters
    ----------
    a : array_like
        Acceleration, uniformly sampled and finite [m/s^2].
    dt : float
        Sample spacing [s].
    axis : int
        Time axis.
    p : WeightingParams
        Weighting parameters; default :data:`WD`.

    Returns
    -------
    ndarray
        Weighted acceleration ``a_w(t)`` [m/s^2]. The filter starts in the steady state
        of the first sample (as if the signal had been constant before the record), so a
        constant offset produces no start-up transient.
    """
    check_dt(dt)
    a = np.asarray(a, dtype=float)
    sos = digital_sos(1.0 / dt, p)
    am = np.moveaxis(a, axis, -1)
    if am.shape[-1] == 0:
        return a.copy()
    flat = am.reshape(-1, am.shape[-1])  # (m, n)
    zi = signal.sosfilt_zi(sos)[:, None, :] * flat[None, :, :1]  # (n_sections, m, 2)
    y, _ = signal.sosfilt(sos, flat, axis=-1, zi=zi)
    y = y.reshape(am.shape)
    return np.moveaxis(y, -1, axis)


def weighted_rms(a, dt: float, axis: int = -1, p: WeightingParams = WD) -> WeightedRMS:
    """Frequency-weighted r.m.s. acceleration (ISO 2631-1:1997 6.1).

    Parameters
    ----------
    a : array_like
        Acceleration along one horizontal axis, uniformly sampled [m/s^2].
    dt : float
        Sample spacing [s].
    axis : int
        Time axis.
    p : WeightingParams
        Weighting parameters; default :data:`WD`.

    Returns
    -------
    WeightedRMS
        ``a_w = sqrt(mean(a_w(t)^2))`` [m/s^2] with its valid band. ``value`` is NaN, and
        ``reason`` says why, when the sample rate, the duration or non-finite samples do
        not allow the evaluation (see the module docstring for the rule). When the band
        stops below 80 Hz, ``value`` is given and ``reason`` says the band is partial.

    Examples
    --------
    >>> t = np.arange(0.0, 60.0, 0.01)
    >>> r = weighted_rms(np.sin(2 * np.pi * 1.0 * t), 0.01)
    >>> round(float(r.value / (1 / np.sqrt(2))), 2)  # Wd(1 Hz) = 1.011 (Table 3)
    1.01
    """
    check_dt(dt)
    a = np.asarray(a, dtype=float)
    fs = 1.0 / dt
    f_valid = valid_upper_frequency(fs, p)
    band = (ISO_FREQ_RANGE_HZ[0], min(ISO_FREQ_RANGE_HZ[1], f_valid))
    full = f_valid >= ISO_FREQ_RANGE_HZ[1]
    shape = np.delete(a.shape, axis % a.ndim) if a.ndim > 1 else ()
    nan = np.full(shape, np.nan)[()]

    def _none(reason: str) -> WeightedRMS:
        return WeightedRMS(nan, nan, band, full, reason)

    if f_valid < WD_MIN_UPPER_HZ:
        return _none(
            f"sample rate {fs:g} Hz: the digital Wd is within {WD_TOLERANCE:.0%} of "
            f"ISO 2631-1 Annex A only up to {f_valid:.3g} Hz, below the required "
            f"{WD_MIN_UPPER_HZ:g} Hz (needs fs >= {min_sample_rate(WD_MIN_UPPER_HZ, p):.0f} Hz)")
    n = a.shape[axis]
    if n * dt < MIN_DURATION_S * (1.0 - 1e-9):
        return _none(f"record of {n} samples ({n * dt:.4g} s) is shorter than the "
                     f"{MIN_DURATION_S:g} s needed for a weighted r.m.s.")
    n_bad = int(np.count_nonzero(~np.isfinite(a)))
    if n_bad:
        return _none(f"{n_bad} non-finite samples: the weighting filter needs a "
                     "continuous signal")
    aw = weight(a, dt, axis=axis, p=p)
    value = np.sqrt(np.mean(aw * aw, axis=axis))
    with np.errstate(divide="ignore", invalid="ignore"):
        crest = np.max(np.abs(aw), axis=axis) / value
    mtvv = running_rms_max(aw, dt, axis=axis)
    vdv = vibration_dose_value(aw, dt, axis=axis)
    reason = None if full else (
        f"partial band {band[0]:g}-{band[1]:.3g} Hz: sample rate {fs:g} Hz is below the "
        f"{min_sample_rate(ISO_FREQ_RANGE_HZ[1], p):.0f} Hz needed for the full "
        f"{ISO_FREQ_RANGE_HZ[0]:g}-{ISO_FREQ_RANGE_HZ[1]:g} Hz ISO band; content above "
        f"{band[1]:.3g} Hz is under-weighted")
    return WeightedRMS(value[()], crest[()], band, full, reason, mtvv, vdv)


def running_rms_max(aw, dt: float, tau: float = MTVV_TAU_S, axis: int = -1):
    """Maximum transient vibration value, MTVV (ISO 2631-1:1997 6.3.1, eq 3-4).

    Parameters
    ----------
    aw : array_like
        Frequency-weighted acceleration a_w(t) [m/s^2], uniformly sampled.
    dt : float
        Sample spacing [s].
    tau : float
        Integration time of the running r.m.s. [s]; the standard's 1 s.
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        ``max over t0 of sqrt(1/tau * integral_{t0 - tau}^{t0} a_w(t)^2 dt)`` [m/s^2], the
        linear (rectangular window) running r.m.s.; over a record shorter than tau, its r.m.s.

    Examples
    --------
    >>> float(running_rms_max(np.r_[np.zeros(500), np.full(100, 2.0), np.zeros(500)], 0.01))
    2.0
    """
    a = np.moveaxis(np.asarray(aw, dtype=float), axis, -1)
    n = max(1, int(round(tau / dt)))
    if a.shape[-1] <= n:
        return np.sqrt(np.mean(a * a, axis=-1))[()]
    c = np.cumsum(np.concatenate([np.zeros(a.shape[:-1] + (1,)), a * a], axis=-1), axis=-1)
    win = (c[..., n:] - c[..., :-n]) / n
    return np.sqrt(np.maximum(np.max(win, axis=-1), 0.0))[()]


def vibration_dose_value(aw, dt: float, axis: int = -1):
    """Fourth power vibration dose value, VDV (ISO 2631-1:1997 6.3.2, eq 5).

    Parameters
    ----------
    aw : array_like
        Frequency-weighted acceleration a_w(t) [m/s^2], uniformly sampled.
    dt : float
        Sample spacing [s].
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        ``(integral a_w(t)^4 dt)^(1/4)`` [m/s^1.75] over the record (rectangle rule).

    Examples
    --------
    >>> round(float(vibration_dose_value(np.ones(1600), 0.01)), 6)  # 16 s of 1 m/s^2: 16^(1/4)
    2.0
    """
    a = np.asarray(aw, dtype=float)
    return (np.sum(a ** 4, axis=axis) * dt) ** 0.25


def vibration_total_value(awx, awy, kx: float = COMFORT_K_XY, ky: float = COMFORT_K_XY):
    """Vibration total value of two horizontal axes (ISO 2631-1:1997 6.5).

    Parameters
    ----------
    awx : array_like
        Weighted r.m.s. along x [m/s^2].
    awy : array_like
        Weighted r.m.s. along y [m/s^2].
    kx : float
        Multiplying factor for x [-]; 1 for comfort at the seat surface (8.2).
    ky : float
        Multiplying factor for y [-]; 1 for comfort at the seat surface (8.2).

    Returns
    -------
    ndarray or float
        ``a_v = sqrt(kx^2 awx^2 + ky^2 awy^2)`` [m/s^2].
    """
    awx = np.asarray(awx, dtype=float)
    awy = np.asarray(awy, dtype=float)
    return np.sqrt((kx * awx) ** 2 + (ky * awy) ** 2)[()]
