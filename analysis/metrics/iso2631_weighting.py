"""ISO 2631-1 frequency weighting: the analog Wd/Wk filters and their digital form.

The weighting is built as the standard defines it (ISO 2631-1:1997 Annex A; parameters
also tabulated in ISO 8041): a cascade of

* band limiting: 2nd-order high pass at ``f1`` and 2nd-order low pass at ``f2``
  (both Butterworth, ``Q1 = Q2 = 1/sqrt(2)``),
* acceleration-velocity transition ``(1 + s/w3) / (1 + s/(Q4 w4) + s^2/w4^2)``,
* upward step ``(s^2 + s w5/Q5 + w5^2) / (s^2 + s w6/Q6 + w6^2)`` (identity when
  ``f5 = f6 = inf``, as for Wd),
* gain ``K``,

each section mapped to the recording's sample rate with the bilinear transform
(:func:`scipy.signal.bilinear_zpk`) and run as second-order sections.

Sample-rate rule
----------------
The bilinear transform warps frequency: the digital gain at ``f`` is the analog gain at
``(fs/pi) tan(pi f/fs)``. ``valid_upper_frequency(fs)`` is the highest frequency up to
which the digital Wd stays within :data:`WD_TOLERANCE` (5 %) of the analog Wd, starting
at 0.5 Hz; it is about ``fs / 8.2`` for ``fs`` up to 200 Hz. The weighted value is
reported when that frequency reaches :data:`WD_MIN_UPPER_HZ` (8 Hz, i.e. ``fs`` >= about
66 Hz) and the record lasts :data:`MIN_DURATION_S`; it covers the full ISO band
(0.5-80 Hz, clause 1) only when it reaches 80 Hz (``fs`` >= about 823 Hz). Otherwise the
value is NaN and the result says why. A "2.5 x the upper frequency" rule is not enough
here: at ``f = fs/2.5`` the bilinear map reads the analog curve at 2.4 ``f``, so the Wd
gain (~1/f above 2 Hz) would be low by a factor 2.4.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

__all__ = ["WeightingParams", "WD", "WK", "ISO_FREQ_RANGE_HZ", "WD_TABLE_HZ", "WD_TABLE",
           "WD_TOLERANCE", "analog_sections", "analog_response", "digital_sos",
           "digital_response", "valid_upper_frequency", "min_sample_rate"]


@dataclass(frozen=True, slots=True)
class WeightingParams:
    """Parameters of one ISO 2631-1 / ISO 8041 frequency weighting (Annex A)."""

    f1: float  # Hz, high-pass band limit
    q1: float  # -, its quality factor
    f2: float  # Hz, low-pass band limit
    q2: float  # -, its quality factor
    f3: float  # Hz, a-v transition zero (inf: no transition)
    f4: float  # Hz, a-v transition pole pair
    q4: float  # -, its quality factor
    f5: float  # Hz, upward-step zero pair (inf: no step)
    q5: float  # -
    f6: float  # Hz, upward-step pole pair (inf: no step)
    q6: float  # -
    k: float  # -, gain


WD = WeightingParams(f1=0.4, q1=1 / math.sqrt(2), f2=100.0, q2=1 / math.sqrt(2),
                     f3=2.0, f4=2.0, q4=0.63, f5=math.inf, q5=1.0, f6=math.inf, q6=1.0,
                     k=1.0)
"""Wd: horizontal (x, y) whole-body acceleration, seated/standing/recumbent
(ISO 2631-1:1997 6.4 and Annex A; the same parameters are tabulated in ISO 8041)."""

WK = WeightingParams(f1=0.4, q1=1 / math.sqrt(2), f2=100.0, q2=1 / math.sqrt(2),
                     f3=12.5, f4=12.5, q4=0.63, f5=2.37, q5=0.91, f6=3.35, q6=0.91,
                     k=1.0)
"""Wk: vertical (z) acceleration (same source). Not used by ``analyze_run`` (no vertical
signal is recorded); kept so the upward-step section is exercised by tests."""

ISO_FREQ_RANGE_HZ = (0.5, 80.0)
"""Frequency range for health, comfort and perception [Hz] (ISO 2631-1:1997 clause 1)."""

WD_TABLE_HZ = np.array([
    0.1, 0.125, 0.16, 0.2, 0.25, 0.315, 0.4, 0.5, 0.63, 0.8, 1.0, 1.25, 1.6, 2.0, 2.5,
    3.15, 4.0, 5.0, 6.3, 8.0, 10.0, 12.5, 16.0, 20.0, 25.0, 31.5, 40.0, 50.0, 63.0, 80.0,
    100.0, 125.0, 160.0, 200.0, 250.0, 315.0, 400.0])
"""Nominal one-third-octave centre frequencies of ISO 2631-1:1997 Table 3 [Hz]."""

WD_TABLE = np.array([
    62.4, 97.3, 158, 243, 365, 530, 713, 853, 944, 992, 1011, 1008, 968, 890, 776, 642,
    512, 409, 323, 253, 212, 161, 125, 100, 80.0, 63.2, 49.4, 38.8, 29.5, 21.1, 14.1,
    8.63, 4.55, 2.43, 1.26, 0.64, 0.31]) / 1000.0
"""Wd weighting factors of ISO 2631-1:1997 Table 3 (printed x 1000) [-]. The printed
10 Hz value (212) is 5 % above what the standard's own Annex A formulas give (201.7); the
neighbours agree with the formulas to 0.6 %."""

WD_TOLERANCE = 0.05
"""Allowed relative deviation of the digital Wd gain from the analog one inside the
reported band [-] (our choice, about 0.4 dB)."""


def _sections_s(p: WeightingParams) -> list[tuple[np.ndarray, np.ndarray]]:
    tp = 2.0 * math.pi
    w1, w2 = tp * p.f1, tp * p.f2
    secs = [
        (np.array([1.0, 0.0, 0.0]), np.array([1.0, w1 / p.q1, w1 * w1])),  # high pass
        (np.array([w2 * w2]), np.array([1.0, w2 / p.q2, w2 * w2])),  # low pass
    ]
    if math.isfinite(p.f4):
        w4 = tp * p.f4
        num = [w4 * w4 / (tp * p.f3), w4 * w4] if math.isfinite(p.f3) else [w4 * w4]
        secs.append((np.array(num), np.array([1.0, w4 / p.q4, w4 * w4])))
    if math.isfinite(p.f5) and math.isfinite(p.f6):
        w5, w6 = tp * p.f5, tp * p.f6
        secs.append((np.array([1.0, w5 / p.q5, w5 * w5]), np.array([1.0, w6 / p.q6, w6 * w6])))
    return secs


def analog_sections(p: WeightingParams = WD) -> list[tuple[np.ndarray, np.ndarray]]:
    """Analog sections of a weighting, as polynomials in ``s``.

    Parameters
    ----------
    p : WeightingParams
        Weighting parameters; default :data:`WD`.

    Returns
    -------
    list of (ndarray, ndarray)
        ``(b, a)`` numerator and denominator coefficients, descending powers of ``s``
        [s in rad/s], for high pass, low pass, a-v transition and upward step (the last
        two only when defined). The gain ``p.k`` is not included.
    """
    return _sections_s(p)


def analog_response(f, p: WeightingParams = WD) -> np.ndarray:
    """Complex frequency response of the analog weighting.

    Parameters
    ----------
    f : array_like
        Frequencies [Hz].
    p : WeightingParams
        Weighting parameters; default :data:`WD`.

    Returns
    -------
    ndarray
        ``H(j 2 pi f)`` including the gain ``p.k`` [-].
    """
    w = 2.0 * math.pi * np.atleast_1d(np.asarray(f, dtype=float))
    h = np.full(w.shape, p.k, dtype=complex)
    for b, a in _sections_s(p):
        h *= signal.freqs(b, a, worN=w)[1]
    return h


def _check_fs(fs: float) -> None:
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"fs must be a positive sample rate [Hz], got {fs!r}")


@functools.lru_cache(maxsize=64)
def _sos_cached(fs: float, p: WeightingParams) -> np.ndarray:
    zs, ps, k = [], [], p.k
    for b, a in _sections_s(p):
        z, pp, kk = signal.tf2zpk(b, a)
        zd, pd, kd = signal.bilinear_zpk(z, pp, kk, fs)
        zs.append(zd)
        ps.append(pd)
        k *= kd
    return signal.zpk2sos(np.concatenate(zs), np.concatenate(ps), k)


def digital_sos(fs: float, p: WeightingParams = WD) -> np.ndarray:
    """Second-order sections of the bilinear-transformed weighting.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    p : WeightingParams
        Weighting parameters; default :data:`WD`.

    Returns
    -------
    ndarray
        ``(n_sections, 6)`` array for :func:`scipy.signal.sosfilt`.
    """
    _check_fs(fs)
    return _sos_cached(float(fs), p).copy()


def digital_response(f, fs: float, p: WeightingParams = WD) -> np.ndarray:
    """Complex frequency response of the digital weighting.

    Parameters
    ----------
    f : array_like
        Frequencies below ``fs / 2`` [Hz].
    fs : float
        Sample rate [Hz].
    p : WeightingParams
        Weighting parameters; default :data:`WD`.

    Returns
    -------
    ndarray
        ``H(exp(j 2 pi f / fs))`` [-].
    """
    f = np.atleast_1d(np.asarray(f, dtype=float))
    return signal.sosfreqz(digital_sos(fs, p), worN=f, fs=fs)[1]


@functools.lru_cache(maxsize=64)
def _valid_upper_cached(fs: float, p: WeightingParams, tol: float) -> float:
    lo = ISO_FREQ_RANGE_HZ[0]
    hi = 0.999 * fs / 2.0
    if hi <= lo:
        return 0.0
    f = np.geomspace(lo, hi, 4000)
    ratio = np.abs(digital_response(f, fs, p)) / np.abs(analog_response(f, p))
    bad = np.nonzero(np.abs(ratio - 1.0) > tol)[0]
    if bad.size == 0:
        return float(hi)
    return 0.0 if bad[0] == 0 else float(f[bad[0] - 1])


def valid_upper_frequency(fs: float, p: WeightingParams = WD,
                          tol: float = WD_TOLERANCE) -> float:
    """Highest frequency up to which the digital weighting matches the analog one.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    p : WeightingParams
        Weighting parameters; default :data:`WD`.
    tol : float
        Allowed relative gain deviation [-]; default :data:`WD_TOLERANCE`.

    Returns
    -------
    float
        Largest ``f`` [Hz] such that ``|Hd/Ha - 1| <= tol`` on all of ``[0.5 Hz, f]``
        (checked on a 4000-point log grid); 0 if it fails already at 0.5 Hz.
    """
    _check_fs(fs)
    return _valid_upper_cached(float(fs), p, float(tol))


@functools.lru_cache(maxsize=16)
def min_sample_rate(f_upper: float, p: WeightingParams = WD,
                    tol: float = WD_TOLERANCE) -> float:
    """Smallest sample rate whose valid band reaches ``f_upper``.

    Parameters
    ----------
    f_upper : float
        Wanted upper edge of the valid band [Hz].
    p : WeightingParams
        Weighting parameters; default :data:`WD`.
    tol : float
        Allowed relative gain deviation [-].

    Returns
    -------
    float
        Sample rate [Hz], found by bisection to 0.1 %.
    """
    lo, hi = 2.0 * f_upper, 2.0 * f_upper
    while valid_upper_frequency(hi, p, tol) < f_upper:
        lo, hi = hi, 2.0 * hi
    while hi - lo > 1e-3 * hi:
        mid = 0.5 * (lo + hi)
        if valid_upper_frequency(mid, p, tol) >= f_upper:
            hi = mid
        else:
            lo = mid
    return hi
