"""Compiled (numba) evaluation of a :class:`~.geometry.ReferenceLine`.

The ReferenceLine is a quintic B-spline ``c(u)`` (u: chord-length parameter) composed with a
quintic Hermite map ``u(s)`` in Bernstein form (s: arc length), plus the unwrapped heading at
the knots and 1 m samples of ``c`` that seed the Frenet projection. :class:`FastLine` turns
that into plain float arrays that ``@njit`` code can evaluate:

* the B-spline's polynomial pieces in the power basis, one per knot interval of the base
  interval ``[0, U]``: ``c(u) = sum_j C[i, j] (u - u_i)^j`` (coefficients from the spline's
  own derivatives at the left knot, as ``PPoly.from_spline`` does); the first and last
  pieces extend beyond ``[0, U]`` exactly as scipy's ``BSpline(extrapolate=True)`` does;
* the Bernstein coefficients of ``u(s)`` as stored by the ``BPoly`` (evaluated with scipy's
  formula), the arc-length nodes and the heading at them;
* the ReferenceLine's own 1 m samples (its cKDTree data) and a ball tree over contiguous
  runs of them, so that the nearest sample (the Newton seed of ``ReferenceLine.to_frenet``)
  is found exactly, whatever the guess: the guess only makes the search cheaper.

:func:`frame_at` and :func:`to_frenet_many` are the kernels; they reproduce
``ReferenceLine.frame`` and ``ReferenceLine.to_frenet`` with the same formulas (straight
extension past the ends, unwrapped heading from the nearest knot, the same Newton step,
step clip, tolerance and iteration limit). Results agree to rounding (~1e-12 m, ~1e-14
rad; the last Newton step of the reference may add up to its 1e-10 m tolerance).

All kernels take the line as one tuple ``L = FastLine.arrays`` (numba passes it at no cost
inside compiled code; from Python the call costs about a microsecond).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.interpolate import BPoly, BSpline, PPoly

from .geometry import _DEGREE, _NEWTON_ITERATIONS, _NEWTON_TOL, ReferenceLine

LEAF_SIZE = 8
"""Samples per leaf of the ball tree over the line's samples."""

# indices into the tuple L (FastLine.arrays)
_I_SCAL = 0  # [length, max_step, sample spacing ds, newton_tol, n_newton]
_I_UK = 1  # (m+1,) breakpoints of c(u)
_I_CC = 2  # (m, 6, 2) power-basis coefficients of c(u) per interval, about _I_UM
_I_SN = 3  # (k+1,) arc-length nodes of u(s)
_I_UC = 4  # (6, k) Bernstein coefficients of u(s) (BPoly.c)
_I_HN = 5  # (k+1,) unwrapped heading at the arc-length nodes
_I_SXY = 6  # (N, 2) samples of c at samp_s (the ReferenceLine's cKDTree data)
_I_SS = 7  # (N,) arc length of the samples
_I_TI = 8  # (K, 4) int64 ball tree: lo, hi, left child, right child (-1: leaf)
_I_TF = 9  # (K, 3) ball tree: centre x, y, radius
_I_UM = 10  # (m,) expansion points (left knots) of the pieces of c(u)


@dataclass(frozen=True, eq=False)
class FastLine:
    """Array form of a ReferenceLine for the numba kernels of this module."""

    length: float
    arrays: tuple  # L, see the _I_* indices

    @classmethod
    def from_reference_line(cls, line: ReferenceLine) -> "FastLine":
        curve: BSpline = line.curve
        k = curve.k
        if k != _DEGREE or np.asarray(curve.c).ndim != 2 or curve.c.shape[1] != 2:
            raise ValueError("expected a quintic planar BSpline c(u)")
        t = np.asarray(curve.t, dtype=float)
        n_coef = len(t) - k - 1
        u_knots = t[k:n_coef + 1].copy()  # base interval breakpoints, t[k] .. t[n]
        if np.any(np.diff(u_knots) <= 0.0):
            raise ValueError("the spline's base knots must be strictly increasing")
        m = len(u_knots) - 1
        # power-basis pieces about the left knot of every base interval, as
        # PPoly.from_spline computes them (FITPACK derivatives at the knots)
        coef = np.empty((m, k + 1, 2))
        for dim in range(2):
            pp = PPoly.from_spline((t, np.asarray(curve.c[:, dim], dtype=float), k))
            if not np.array_equal(pp.x[k:n_coef + 1], u_knots):
                raise ValueError("unexpected PPoly breakpoints")
            coef[:, :, dim] = pp.c[::-1, k:n_coef].T  # ascending powers
        u_mid = u_knots[:-1].copy()  # expansion points: the left knots
        bp: BPoly = line.u_of_s
        uc = np.ascontiguousarray(np.asarray(bp.c, dtype=float).reshape(bp.c.shape[0], -1))
        s_nodes = np.ascontiguousarray(bp.x, dtype=float)
        if uc.shape[1] != len(s_nodes) - 1:
            raise ValueError("u(s) must be a scalar BPoly")
        if not np.array_equal(s_nodes, line.s_nodes):
            raise ValueError("u(s) breakpoints differ from s_nodes")
        samp_xy = np.ascontiguousarray(line.tree.data, dtype=float)
        samp_s = np.ascontiguousarray(line.tree_s, dtype=float)
        ds = float(samp_s[1] - samp_s[0])
        scal = np.array([line.length, 2.0 * ds, ds, _NEWTON_TOL, float(_NEWTON_ITERATIONS)])
        ti, tf = _build_tree(samp_xy)
        arrays = (scal, u_knots, np.ascontiguousarray(coef), s_nodes, uc,
                  np.ascontiguousarray(line.heading_nodes, dtype=float), samp_xy, samp_s, ti, tf,
                  u_mid)
        return cls(float(line.length), arrays)

    # convenience wrappers (Python level) --------------------------------------------------
    def frame(self, s: float):
        """(x, y, tx, ty, heading, kappa, kappa_rate) at arc length s [m]."""
        return frame_at(self.arrays, float(s))

    def to_frenet(self, xy, s_guess=None):
        """(s, d) of points xy (n, 2); ``s_guess`` (n,) speeds up the search (NaN: none)."""
        xy = np.ascontiguousarray(xy, dtype=float).reshape(-1, 2)
        if s_guess is None:
            g = np.full(len(xy), np.nan)
        else:
            g = np.ascontiguousarray(np.broadcast_to(np.asarray(s_guess, dtype=float), (len(xy),)))
        return to_frenet_many(self.arrays, xy, g)


def _build_tree(xy: np.ndarray):
    """Ball tree over contiguous runs of samples: node (lo, hi, left, right), (cx, cy, r)."""
    nodes_i: list[list[int]] = []
    nodes_f: list[list[float]] = []

    def build(lo: int, hi: int) -> int:
        idx = len(nodes_i)
        pts = xy[lo:hi]
        c = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        r = float(np.max(np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1])))
        nodes_i.append([lo, hi, -1, -1])
        nodes_f.append([float(c[0]), float(c[1]), r * (1.0 + 1e-12) + 1e-9])
        if hi - lo > LEAF_SIZE:
            mid = (lo + hi) // 2
            left = build(lo, mid)
            right = build(mid, hi)
            nodes_i[idx][2], nodes_i[idx][3] = left, right
        return idx

    build(0, len(xy))
    return np.array(nodes_i, dtype=np.int64), np.array(nodes_f, dtype=float)


# ------------------------------------------------------------------------------ kernels


@njit(cache=True, error_model="numpy")
def _wrap(a):
    """np.pi - np.mod(np.pi - a, 2 pi): wrap to (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


@njit(cache=True, error_model="numpy")
def _interval(x, xv):
    """scipy's find_interval: x[i] <= xv < x[i+1], closed at the right end, extrapolating
    with the first / last interval (xv must not be NaN)."""
    n = x.shape[0]
    if xv <= x[0]:
        return 0
    if xv >= x[n - 1]:
        return n - 2
    lo = 0
    hi = n - 1  # x[lo] <= xv < x[hi]
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if xv >= x[mid]:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, error_model="numpy")
def _u_of_s(L, sc):
    """u(s) for s in [0, length] (BPoly, Bernstein basis, scipy's evaluate_bpoly1); also the
    interval index of s."""
    xs = L[_I_SN]
    c = L[_I_UC]
    i = _interval(xs, sc)
    s = (sc - xs[i]) / (xs[i + 1] - xs[i])
    s1 = 1.0 - s
    k = c.shape[0] - 1
    res = 0.0
    comb = 1.0
    for j in range(k + 1):
        res += comb * math.pow(s, float(j)) * math.pow(s1, float(k - j)) * c[j, i]
        comb *= 1.0 * (k - j) / (j + 1.0)
    return res, i


@njit(cache=True, error_model="numpy")
def frame_at(L, s):
    """ReferenceLine.frame(s) for one arc length s [m].

    Returns (x, y, tx, ty, heading, kappa, kappa_rate): position [m], unit tangent,
    unwrapped heading [rad], curvature [1/m], d kappa / ds [1/m^2]. Past the ends the line
    is straight (position linear in s, heading constant, kappa = kappa_rate = 0).
    """
    nan = np.nan
    if s != s:
        return nan, nan, nan, nan, nan, nan, nan
    length = L[_I_SCAL][0]
    sc = s
    if sc < 0.0:
        sc = 0.0
    elif sc > length:
        sc = length
    u, si = _u_of_s(L, sc)
    uk = L[_I_UK]
    C = L[_I_CC]
    i = _interval(uk, u) if u == u else 0
    du = u - L[_I_UM][i]
    # c, c', c'', c''' by Horner on the power-basis piece
    x0 = C[i, 5, 0]
    y0 = C[i, 5, 1]
    x1 = 5.0 * C[i, 5, 0]
    y1 = 5.0 * C[i, 5, 1]
    x2 = 20.0 * C[i, 5, 0]
    y2 = 20.0 * C[i, 5, 1]
    x3 = 60.0 * C[i, 5, 0]
    y3 = 60.0 * C[i, 5, 1]
    x0 = x0 * du + C[i, 4, 0]
    y0 = y0 * du + C[i, 4, 1]
    x1 = x1 * du + 4.0 * C[i, 4, 0]
    y1 = y1 * du + 4.0 * C[i, 4, 1]
    x2 = x2 * du + 12.0 * C[i, 4, 0]
    y2 = y2 * du + 12.0 * C[i, 4, 1]
    x3 = x3 * du + 24.0 * C[i, 4, 0]
    y3 = y3 * du + 24.0 * C[i, 4, 1]
    x0 = x0 * du + C[i, 3, 0]
    y0 = y0 * du + C[i, 3, 1]
    x1 = x1 * du + 3.0 * C[i, 3, 0]
    y1 = y1 * du + 3.0 * C[i, 3, 1]
    x2 = x2 * du + 6.0 * C[i, 3, 0]
    y2 = y2 * du + 6.0 * C[i, 3, 1]
    x3 = x3 * du + 6.0 * C[i, 3, 0]
    y3 = y3 * du + 6.0 * C[i, 3, 1]
    x0 = x0 * du + C[i, 2, 0]
    y0 = y0 * du + C[i, 2, 1]
    x1 = x1 * du + 2.0 * C[i, 2, 0]
    y1 = y1 * du + 2.0 * C[i, 2, 1]
    x2 = x2 * du + 2.0 * C[i, 2, 0]
    y2 = y2 * du + 2.0 * C[i, 2, 1]
    x0 = x0 * du + C[i, 1, 0]
    y0 = y0 * du + C[i, 1, 1]
    x1 = x1 * du + C[i, 1, 0]
    y1 = y1 * du + C[i, 1, 1]
    x0 = x0 * du + C[i, 0, 0]
    y0 = y0 * du + C[i, 0, 1]

    g = math.hypot(x1, y1)
    tx = x1 / g
    ty = y1 / g
    cr12 = x1 * y2 - y1 * x2
    g3 = math.pow(g, 3.0)
    kappa = cr12 / g3
    dkappa_du = (x1 * y3 - y1 * x3) / g3 - 3.0 * cr12 * (x1 * x2 + y1 * y2) / math.pow(g, 5.0)
    kappa_rate = dkappa_du / g
    # unwrapped heading: np.searchsorted(s_nodes, sc) (side left), clipped
    sn = L[_I_SN]
    idx = si if sn[si] == sc else si + 1
    if idx > sn.shape[0] - 1:
        idx = sn.shape[0] - 1
    ref = L[_I_HN][idx]
    heading = ref + _wrap(math.atan2(ty, tx) - ref)
    ext = s - sc
    px = x0 + ext * tx
    py = y0 + ext * ty
    if s != sc:
        kappa = 0.0
        kappa_rate = 0.0
    return px, py, tx, ty, heading, kappa, kappa_rate


@njit(cache=True, error_model="numpy")
def _nearest_sample(L, px, py, s_guess):
    """Index of the line sample nearest to (px, py): exact (ball tree), seeded by the guess."""
    sxy = L[_I_SXY]
    ti = L[_I_TI]
    tf = L[_I_TF]
    n = sxy.shape[0]
    best = np.inf
    best_i = 0
    if s_guess == s_guess:
        ds = L[_I_SCAL][2]
        g = (s_guess - L[_I_SS][0]) / ds
        if g < 0.0:
            j = 0
        elif g > n - 1:
            j = n - 1
        else:
            j = int(g + 0.5)
        dx = sxy[j, 0] - px
        dy = sxy[j, 1] - py
        best = dx * dx + dy * dy
        best_i = j
        # walk downhill along the samples (a cheap, usually final, bound)
        for step in (-1, 1):
            while True:
                jn = best_i + step
                if jn < 0 or jn >= n:
                    break
                dx = sxy[jn, 0] - px
                dy = sxy[jn, 1] - py
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    best_i = jn
                else:
                    break
    stack = np.empty(64, dtype=np.int64)
    top = 0
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        dx = tf[node, 0] - px
        dy = tf[node, 1] - py
        lb = math.sqrt(dx * dx + dy * dy) - tf[node, 2]
        if lb > 0.0 and lb * lb > best:
            continue
        lo = ti[node, 0]
        hi = ti[node, 1]
        left = ti[node, 2]
        if left < 0:
            for j in range(lo, hi):
                dx = sxy[j, 0] - px
                dy = sxy[j, 1] - py
                d2 = dx * dx + dy * dy
                if d2 < best or (d2 == best and j < best_i):
                    best = d2
                    best_i = j
        else:
            right = ti[node, 3]
            # push the farther child first: the nearer one is searched first
            dlx = tf[left, 0] - px
            dly = tf[left, 1] - py
            drx = tf[right, 0] - px
            dry = tf[right, 1] - py
            if dlx * dlx + dly * dly <= drx * drx + dry * dry:
                stack[top] = right
                stack[top + 1] = left
            else:
                stack[top] = left
                stack[top + 1] = right
            top += 2
    return best_i


@njit(cache=True, error_model="numpy")
def to_frenet_one(L, px, py, s_guess):
    """ReferenceLine.to_frenet for one point: (s, d). ``s_guess`` (NaN: none) only seeds the
    search for the nearest 1 m sample, which seeds the same Newton iteration as the
    reference: step (p - c(s)).t / (1 - kappa d), clipped to 2 sample spacings."""
    if px != px or py != py:
        return np.nan, np.nan
    sc = L[_I_SCAL]
    max_step = sc[1]
    tol = sc[3]
    n_it = int(sc[4])
    s = L[_I_SS][_nearest_sample(L, px, py, s_guess)]
    for _ in range(n_it):
        x, y, tx, ty, hd, kappa, kr = frame_at(L, s)
        rx = px - x
        ry = py - y
        along = rx * tx + ry * ty
        d = rx * (-ty) + ry * tx
        denom = 1.0 - kappa * d
        if not denom > 0.1:
            denom = 1.0
        step = along / denom
        if step < -max_step:
            step = -max_step
        elif step > max_step:
            step = max_step
        s = s + step
        if abs(step) < tol:
            break
    x, y, tx, ty, hd, kappa, kr = frame_at(L, s)
    d = (px - x) * (-ty) + (py - y) * tx
    return s, d


@njit(cache=True, error_model="numpy")
def to_frenet_many(L, xy, s_guess):
    """to_frenet_one for points xy (n, 2) with guesses s_guess (n,) (NaN: none): (s, d)."""
    n = xy.shape[0]
    s = np.empty(n)
    d = np.empty(n)
    for i in range(n):
        s[i], d[i] = to_frenet_one(L, xy[i, 0], xy[i, 1], s_guess[i])
    return s, d


@njit(cache=True, error_model="numpy")
def frame_many(L, s):
    """frame_at over an array s (n,): (n, 7) columns x, y, tx, ty, heading, kappa, kappa_rate."""
    out = np.empty((s.shape[0], 7))
    for i in range(s.shape[0]):
        r = frame_at(L, s[i])
        for j in range(7):
            out[i, j] = r[j]
    return out
