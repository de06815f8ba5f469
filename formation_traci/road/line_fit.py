"""Fitting a smooth curve to a lane polyline: cleaning the polyline and the penalised quintic
regression spline (P-spline, Eilers & Marx 1996) of :meth:`.geometry.ReferenceLine.from_points`
(steps 1 and 2 of the method described in :mod:`.geometry`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    import scipy.sparse as sparse
    from scipy.interpolate import BSpline

_DEGREE = 5
"""Degree of the B-spline of x(u), y(u) (quintic: curvature rate is C2)."""
_PENALTY_ORDER = 5
"""Order of the coefficient difference penalty (null space: polynomials of degree <= 4)."""
_GAUSS_NODES, _GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(8)


@dataclass(frozen=True, slots=True)
class LineFit:
    """Settings of the polyline smoothing in :meth:`ReferenceLine.from_points`."""

    smoothing_length: float  # wavelength where the fit's response is 1/2 [m]
    knot_spacing: float  # target spacing of the uniform spline knots [m]
    max_segment: float  # longer polyline segments are split into equal pieces [m]
    min_segment: float  # points closer than this to the previous point are dropped [m]


LINE_FIT_DEFAULT = LineFit(smoothing_length=40.0, knot_spacing=4.0, max_segment=5.0,
                           min_segment=1e-3)
"""Fit for SUMO shapes sampled every 4 m and rounded to 0.1 mm (``--precision 4``).

With it (measured in ``tests/test_road.py``), the curvature of R = 150..1000 m arcs is
recovered within 0.12 % (ends included), the heading within 2e-5 rad, positions within
0.2 mm, and the curvature rate 1/A^2 of an A = 400 m clothoid within 1 % (3 % in the 40 m
at either end of the line). Curvature changes sharper than about 40 m (the kinks of
kappa' at clothoid ends) are rounded over about that length.
"""



def clean_polyline(xy, min_segment: float, max_segment: float) -> np.ndarray:
    """Drop near-duplicate points and split long segments of a polyline.

    Parameters
    ----------
    xy : array_like, shape (n, 2)
        Polyline vertices [m].
    min_segment : float
        A point closer than this to the previous kept point is dropped [m].
    max_segment : float
        A segment longer than this is split into ``ceil(length / max_segment)`` equal
        pieces [m]. SUMO drives polyline segments straight, so this adds no error.

    Returns
    -------
    ndarray, shape (m, 2)
        Cleaned polyline [m].
    """
    pts = np.asarray(xy, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"xy must have shape (n, 2), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("xy contains non-finite values")
    if not (0.0 < min_segment < max_segment):
        raise ValueError("need 0 < min_segment < max_segment")
    kept = [pts[0]]
    for p in pts[1:]:
        if math.dist(p, kept[-1]) > min_segment:
            kept.append(p)
    if len(kept) < 2:
        raise ValueError("xy needs at least two distinct points")
    out = [kept[0][None, :]]
    for a, b in zip(kept[:-1], kept[1:]):
        n = max(1, math.ceil(math.dist(a, b) / max_segment))
        f = np.arange(1, n + 1)[:, None] / n
        out.append(a + f * (b - a))
    return np.concatenate(out)


def chord_lengths(pts: np.ndarray) -> np.ndarray:
    """Cumulative chord length u [m] at the vertices of a polyline pts (n, 2) [m]."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])


def _difference_matrix(n: int, order: int) -> sparse.csr_matrix:
    import scipy.sparse as sparse

    d = sparse.identity(n, format="csr")
    for _ in range(order):
        d = d[1:] - d[:-1]
    return d


def pspline_system(u: np.ndarray, pts: np.ndarray, fit: LineFit):
    """The normal equations of the penalised quintic regression spline of pts (n, 2) over
    parameter u [m]: ``(knots, lhs, rhs)``, lhs a scipy.sparse matrix (n_coef, n_coef), rhs
    (n_coef, 2). Rows added to it (road/smoothing.py pins the line to its tolerance band) keep
    its bandwidth. scipy is imported here: a line read from the road cache is not fitted."""
    from scipy.interpolate import BSpline

    total = float(u[-1])
    m = max(math.ceil(total / fit.knot_spacing), 1)
    h = total / m
    knots = np.arange(-_DEGREE, m + _DEGREE + 1) * h  # uniform, extended past both ends
    knots[_DEGREE] = 0.0
    knots[m + _DEGREE] = total
    basis = BSpline.design_matrix(np.clip(u, 0.0, total), knots, _DEGREE)
    n_coef = m + _DEGREE
    pen = _difference_matrix(n_coef, _PENALTY_ORDER)
    density = len(u) / m  # data points per knot interval
    lam = density * (fit.smoothing_length / (2.0 * np.pi * h)) ** (2 * _PENALTY_ORDER)
    lhs = basis.T @ basis + lam * (pen.T @ pen)  # scipy.sparse's own loops: no BLAS
    return knots, lhs, np.asarray(basis.T @ pts)


def solve_pspline(knots: np.ndarray, lhs, rhs: np.ndarray) -> BSpline:
    """The spline c(u) of the system of :func:`pspline_system` (or one with rows added)."""
    from scipy.interpolate import BSpline

    bands = [lhs.diagonal(-k) for k in range(max(_DEGREE, _PENALTY_ORDER) + 1)]  # its bandwidth
    coef = solve_banded_spd(bands, rhs)
    return BSpline(knots, coef, _DEGREE, extrapolate=True)


def _fit_pspline(u: np.ndarray, pts: np.ndarray, fit: LineFit) -> BSpline:
    """Penalised quintic regression spline of pts (n, 2) over parameter u [m]."""
    return solve_pspline(*pspline_system(u, pts, fit))


def solve_banded_spd(bands, rhs) -> np.ndarray:
    """x of A x = rhs for a symmetric positive definite banded A, by Cholesky in plain floats.

    ``bands[k][i]`` is A[i + k, i] (the k-th sub-diagonal, k = 0..p); ``rhs`` is (n, r). Every
    sum runs in one fixed order in Python floats (IEEE double, correctly rounded), so the
    result is the same bit for bit on every processor: no BLAS or LAPACK kernel (whose
    reductions differ with the CPU's vector width) and no numpy reduction is called.
    """
    p = len(bands) - 1
    a = [[float(v) for v in band] for band in bands]
    n = len(a[0])
    low = [[0.0] * (p + 1) for _ in range(n)]  # low[i][k] = L[i, i - k]
    for i in range(n):
        row = low[i]
        for k in range(min(i, p), -1, -1):
            j = i - k
            other = low[j]
            acc = a[k][j]
            for m in range(k + 1, min(j + k, p) + 1):  # sum over c = i - m < j of L[i,c] L[j,c]
                acc -= row[m] * other[m - k]
            if k:
                row[k] = acc / other[0]
            elif acc <= 0.0:
                raise ValueError("the smoothing system is not positive definite")
            else:
                row[0] = math.sqrt(acc)
    b = np.asarray(rhs, dtype=float)
    x = [[float(v) for v in r] for r in b.reshape(n, -1)]
    for i in range(n):  # L y = b
        row, xi = low[i], x[i]
        for m in range(1, min(i, p) + 1):
            xm = x[i - m]
            for c in range(len(xi)):
                xi[c] -= row[m] * xm[c]
        for c in range(len(xi)):
            xi[c] /= row[0]
    for i in range(n - 1, -1, -1):  # L^T x = y
        xi = x[i]
        for m in range(1, min(n - 1 - i, p) + 1):
            lm, xm = low[i + m][m], x[i + m]
            for c in range(len(xi)):
                xi[c] -= lm * xm[c]
        for c in range(len(xi)):
            xi[c] /= low[i][0]
    return np.array(x, dtype=float).reshape(b.shape)
