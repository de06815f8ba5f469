"""Formation-keeping metrics: tracking error, settling, shape error, string stability.

The tracking error of member i is eq. 2.5 of the seed, ``e = p_des - p`` with ``p_des``
from eq. 2.4; the recorder also resolves it in the virtual-car frame (``e_lon``,
``e_lat``). Time is the last axis unless ``axis`` says otherwise.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from analysis.metrics.signals import check_dt, peak_abs, rms, trapezoid_integral

__all__ = [
    "SETTLING_TOLERANCE_M",
    "COLUMN_DY_TOLERANCE_M",
    "error_norm",
    "settling_time",
    "iae",
    "offsets_in_vc_frame",
    "pair_distances",
    "desired_pair_distances",
    "shape_error",
    "formation_columns",
    "StringRatios",
    "string_stability_ratios",
]

SETTLING_TOLERANCE_M = 0.2
"""Default settling band on the error norm [m]."""

COLUMN_DY_TOLERANCE_M = 0.01
"""Members whose lateral offsets differ by at most this are in the same column [m]."""


def error_norm(e_lon, e_lat) -> np.ndarray:
    """Euclidean norm of the formation error.

    Parameters
    ----------
    e_lon : array_like
        Error along the virtual-car heading [m].
    e_lat : array_like
        Error across the virtual-car heading [m].

    Returns
    -------
    ndarray
        ``sqrt(e_lon^2 + e_lat^2)`` [m] (equal to ``sqrt(ex^2 + ey^2)``, eq. 2.5).
    """
    return np.hypot(np.asarray(e_lon, float), np.asarray(e_lat, float))


def settling_time(e, dt: float, tol: float = SETTLING_TOLERANCE_M, axis: int = -1):
    """Time after which ``|e|`` stays inside a tolerance band until the end.

    Parameters
    ----------
    e : array_like
        Error signal, e.g. the error norm, uniformly sampled [m].
    dt : float
        Sample spacing [s].
    tol : float
        Half-width of the band [m].
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        Time since the first sample [s] at which ``|e|`` last enters the band, linearly
        interpolated between the last sample outside and the first inside; 0 if it is
        inside from the start; NaN if the last sample is outside (never settles).
        Non-finite samples count as outside.

    Examples
    --------
    >>> round(float(settling_time([1.0, 0.6, 0.1, 0.05], 1.0, tol=0.2)), 9)
    1.8
    """
    check_dt(dt)
    if not tol > 0:
        raise ValueError(f"tol must be positive [m], got {tol!r}")
    m = np.abs(np.moveaxis(np.asarray(e, dtype=float), axis, -1))
    n = m.shape[-1]
    flat = m.reshape(-1, n)
    out = np.full(flat.shape[0], np.nan)
    for i, row in enumerate(flat):
        if n == 0:
            continue
        outside = ~(row <= tol)
        if not outside.any():
            out[i] = 0.0
            continue
        last = n - 1 - int(np.argmax(outside[::-1]))
        if last == n - 1:
            continue
        e_out, e_in = row[last], row[last + 1]
        frac = (e_out - tol) / (e_out - e_in) if np.isfinite(e_out) and e_out > e_in else 1.0
        out[i] = (last + frac) * dt
    return out.reshape(m.shape[:-1])[()]


def iae(e, dt: float, axis: int = -1):
    """Integral of the absolute error (trapezoidal rule).

    Parameters
    ----------
    e : array_like
        Error signal, uniformly sampled and finite [m].
    dt : float
        Sample spacing [s].
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        ``integral |e| dt`` [m s].
    """
    return trapezoid_integral(np.abs(np.asarray(e, dtype=float)), dt, axis=axis)


def offsets_in_vc_frame(x_des, y_des, x_vc, y_vc, heading_vc) -> tuple[np.ndarray, np.ndarray]:
    """Desired offsets ``(d_x, d_y)`` recovered from desired positions (eq. 2.4 inverted).

    Parameters
    ----------
    x_des : array_like
        Desired x of the member [m].
    y_des : array_like
        Desired y of the member [m].
    x_vc : array_like
        Virtual-car x at the same instants [m].
    y_vc : array_like
        Virtual-car y at the same instants [m].
    heading_vc : array_like
        Virtual-car heading theta_vc [rad].

    Returns
    -------
    (ndarray, ndarray)
        ``d_x`` (along the virtual-car heading) and ``d_y`` (to its left) [m].
    """
    dx = np.asarray(x_des, float) - np.asarray(x_vc, float)
    dy = np.asarray(y_des, float) - np.asarray(y_vc, float)
    c, s = np.cos(heading_vc), np.sin(heading_vc)
    return c * dx + s * dy, -s * dx + c * dy


def pair_distances(x, y, axis: int = -1) -> np.ndarray:
    """Distances between every pair of members.

    Parameters
    ----------
    x : array_like
        Positions, shape ``(n_members, n_t)`` with time on ``axis`` [m].
    y : array_like
        Positions, same shape as ``x`` [m].
    axis : int
        Time axis (the members axis is the other one).

    Returns
    -------
    ndarray
        Shape ``(n_pairs, n_t)``, pairs ``(i, j)``, ``i < j``, in ``np.triu_indices``
        order [m].
    """
    x = np.moveaxis(np.asarray(x, float), axis, -1)
    y = np.moveaxis(np.asarray(y, float), axis, -1)
    if x.ndim != 2 or x.shape != y.shape:
        raise ValueError(f"x and y must both have shape (n_members, n_t), got {x.shape} "
                         f"and {y.shape}")
    i, j = np.triu_indices(x.shape[0], 1)
    return np.hypot(x[i] - x[j], y[i] - y[j])


def desired_pair_distances(offsets) -> np.ndarray:
    """Desired distances between every pair of members from their offsets.

    Parameters
    ----------
    offsets : array_like
        Shape ``(n_members, 2)``: ``(d_x, d_y)`` of each member in the virtual-car frame
        [m] (eq. 2.4).

    Returns
    -------
    ndarray
        Shape ``(n_pairs,)`` in ``np.triu_indices`` order [m].
    """
    o = np.asarray(offsets, float)
    if o.ndim != 2 or o.shape[1] != 2:
        raise ValueError(f"offsets must have shape (n_members, 2), got {o.shape}")
    i, j = np.triu_indices(o.shape[0], 1)
    return np.hypot(o[i, 0] - o[j, 0], o[i, 1] - o[j, 1])


def shape_error(x, y, desired, axis: int = -1) -> np.ndarray:
    """Formation shape error: r.m.s. over member pairs of the distance error.

    Parameters
    ----------
    x : array_like
        Member positions, shape ``(n_members, n_t)``, time on ``axis`` [m].
    y : array_like
        Member positions, same shape [m].
    desired : array_like
        Desired pair distances, shape ``(n_pairs,)`` (see :func:`desired_pair_distances`)
        or ``(n_pairs, n_t)`` when they vary in time [m].
    axis : int
        Time axis.

    Returns
    -------
    ndarray
        ``eps(t) = sqrt(mean_pairs (d_ij(t) - d*_ij)^2)`` [m], shape ``(n_t,)``; zero for
        a formation that is a rigid translation/rotation of the desired one. Fewer than
        two members give NaN.
    """
    d = pair_distances(x, y, axis=axis)
    desired = np.asarray(desired, float)
    if desired.ndim == 1:
        desired = desired[:, None]
    if d.shape[0] == 0:
        return np.full(d.shape[1], np.nan)
    if desired.shape[0] != d.shape[0]:
        raise ValueError(f"desired has {desired.shape[0]} pairs, positions give {d.shape[0]}")
    return np.sqrt(np.mean((d - desired) ** 2, axis=0))


def formation_columns(offsets: Mapping[str, Sequence[float]],
                      dy_tol: float = COLUMN_DY_TOLERANCE_M) -> list[list[str]]:
    """Group members into columns: same lateral offset, front to back.

    Parameters
    ----------
    offsets : mapping of str to (float, float)
        Member id to ``(d_x, d_y)`` in the virtual-car frame [m].
    dy_tol : float
        Largest difference of ``d_y`` inside one column [m].

    Returns
    -------
    list of list of str
        Columns with at least two members, each ordered by ``d_x`` descending (the
        front member first), columns ordered by ``d_y`` descending (leftmost first).

    Examples
    --------
    >>> formation_columns({"a": (0, 0), "b": (-10, 0), "c": (10, 0), "d": (0, 3.5)})
    [['c', 'a', 'b']]
    """
    items = sorted(offsets.items(), key=lambda kv: (-float(kv[1][1]), -float(kv[1][0])))
    groups: list[list[tuple[str, float, float]]] = []
    for mid, (dx, dy) in items:
        if groups and abs(groups[-1][0][2] - float(dy)) <= dy_tol:
            groups[-1].append((mid, float(dx), float(dy)))
        else:
            groups.append([(mid, float(dx), float(dy))])
    return [[m for m, _, _ in sorted(g, key=lambda r: -r[1])] for g in groups if len(g) >= 2]


class StringRatios(NamedTuple):
    """Error amplification from each member to the next one down a column."""

    peak: np.ndarray  # -, max|e_{i+1}| / max|e_i|
    rms: np.ndarray  # -, rms(e_{i+1}) / rms(e_i)


def string_stability_ratios(e, axis: int = -1) -> StringRatios:
    """String-stability ratios along a column of members.

    Parameters
    ----------
    e : array_like
        Errors of the column members, shape ``(n_members, n_t)`` ordered front to back,
        time on ``axis`` [m].
    axis : int
        Time axis.

    Returns
    -------
    StringRatios
        ``peak[i] = max|e_{i+1}| / max|e_i|`` and ``rms[i] = rms(e_{i+1}) / rms(e_i)``,
        shape ``(n_members - 1,)`` [-]. Ratios <= 1 mean errors do not grow down the
        column. A zero denominator gives inf (or NaN for 0/0).

    Examples
    --------
    >>> string_stability_ratios([[2.0, -2.0], [1.0, 1.0]]).peak
    array([0.5])
    """
    e = np.moveaxis(np.asarray(e, float), axis, -1)
    if e.ndim != 2:
        raise ValueError(f"e must have shape (n_members, n_t), got {e.shape}")
    pk, r = peak_abs(e, axis=-1), rms(e, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return StringRatios(pk[1:] / pk[:-1], r[1:] / r[:-1])
