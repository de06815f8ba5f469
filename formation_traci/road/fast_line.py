"""Compiled (numba) evaluation of a :class:`~.geometry.ReferenceLine`.

The ReferenceLine is a quintic B-spline ``c(u)`` (u: chord-length parameter) composed with a
quintic Hermite map ``u(s)`` in Bernstein form (s: arc length), plus the unwrapped heading at
the knots and 1 m samples of ``c`` that seed the Frenet projection. road/line_pack.py
(:class:`FastLine`, :func:`packed`) packs all of it into one float64 buffer ``G`` that the
kernels here evaluate:

* the B-spline's polynomial pieces in the power basis, one per knot interval of the base
  interval ``[0, U]``: ``c(u) = sum_j a_ij (u - u_i)^j``, with the coefficients
  ``PPoly.from_spline`` computes (FITPACK derivatives at the left knot); the first and last
  pieces extend beyond ``[0, U]`` exactly as scipy's ``BSpline(extrapolate=True)`` does;
* the Bernstein coefficients of ``u(s)`` as stored by the ``BPoly`` (summed with scipy's
  formula), the arc-length nodes and the unwrapped heading at them;
* the ReferenceLine's own 1 m samples (its cKDTree data), for each sample the distance to
  the nearest sample more than WINDOW samples away, and a ball tree over contiguous runs of
  samples: the nearest sample (the Newton seed of ``ReferenceLine.to_frenet``) is found
  exactly whatever the guess; a good guess only makes it cheaper (a short walk and a
  certificate instead of the tree search).

:func:`frame_many` and :func:`to_frenet_many` are ``ReferenceLine.frame`` / ``to_frenet``
(the one implementation; straight past the ends); tests/test_fast_line.py checks them against
scipy's own evaluation of the fitted pieces. One buffer, because numba
reference-counts every array passed between compiled functions; offsets are in G's header.
"""
from __future__ import annotations

import math

import numpy as np

from ..core.kernels import kernel, wrap_angle as _wrap

LEAF_SIZE = 8
"""Samples per leaf of the ball tree over the line's samples."""
WINDOW = 50
"""Half window [samples] within which the distance to a point is certified unimodal."""

# header of G: scalars, then sizes and offsets (stored as floats, exact below 2**53)
_H_LENGTH = 0  # line length [m]
_H_MAX_STEP = 1  # Newton step clip: two sample spacings [m]
_H_DS = 2  # sample spacing [m]
_H_TOL = 3  # Newton tolerance [m]
_H_N_IT = 4  # Newton iterations
_H_KAPPA = 5  # bound on |kappa| over the line [1/m]
_H_WINDOW = 6  # WINDOW
_H_INV_SN = 7  # (n_sn - 1) / (s_nodes[-1] - s_nodes[0]) (interval guess)
_H_INV_UK = 8  # (n_uk - 1) / (u_knots[-1] - u_knots[0])
_H_N_UK = 9  # number of u breakpoints (m + 1)
_H_N_SN = 10  # number of arc-length nodes
_H_N_SAMP = 11  # number of samples
_H_OFF_UK = 12  # u breakpoints (n_uk)
_H_OFF_CC = 13  # c(u) pieces: [(m, 6, 2)] ascending powers of (u - u_i)
_H_OFF_SN = 14  # arc-length nodes (n_sn)
_H_OFF_UC = 15  # u(s) Bernstein coefficients [(n_sn - 1, 6)]
_H_OFF_HN = 16  # unwrapped heading at the nodes (n_sn)
_H_OFF_SXY = 17  # samples [(n_samp, 2)]
_H_OFF_SS = 18  # arc length of the samples (n_samp)
_H_OFF_CLR = 19  # clearance of the samples (n_samp)
_H_OFF_TREE = 20  # ball tree [(n_nodes, 7)]: lo, hi, left, right (-1: leaf), cx, cy, r
_H_SIZE = 24


# ------------------------------------------------------------------------------ kernels


@kernel
def _interval(G, off, n, xv, inv):
    """scipy's find_interval over the n breakpoints x = G[off:off + n]: x[i] <= xv < x[i+1],
    closed at the right end, the first / last interval outside (xv not NaN). The breakpoints
    are close to uniform: start from the linear guess and walk; bisect if that gets long."""
    x0 = G[off]
    if xv <= x0:
        return 0
    if xv >= G[off + n - 1]:
        return n - 2
    i = int((xv - x0) * inv)
    if i > n - 2:
        i = n - 2
    if i < 0:
        i = 0
    for _ in range(8):
        if xv < G[off + i]:
            i -= 1
        elif xv >= G[off + i + 1]:
            i += 1
        else:
            return i
    lo = 0
    hi = n - 1  # x[lo] <= xv < x[hi]
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if xv >= G[off + mid]:
            lo = mid
        else:
            hi = mid
    return lo


@kernel
def _curve(G, s):
    """c(u(s)) and the u-derivatives c', c'', c''' at s clipped to [0, length]; returns
    (sc, interval of sc in s_nodes, x0, y0, x1, y1, x2, y2, x3, y3)."""
    length = G[_H_LENGTH]
    sc = s
    if sc < 0.0:
        sc = 0.0
    elif sc > length:
        sc = length
    # u(s): the BPoly's quintic in Bernstein form, summed as scipy's evaluate_bpoly1 does
    off_sn = int(G[_H_OFF_SN])
    si = _interval(G, off_sn, int(G[_H_N_SN]), sc, G[_H_INV_SN])
    t = (sc - G[off_sn + si]) / (G[off_sn + si + 1] - G[off_sn + si])
    t1 = 1.0 - t
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    q2 = t1 * t1
    q3 = q2 * t1
    q4 = q3 * t1
    cu = int(G[_H_OFF_UC]) + 6 * si
    u = q4 * t1 * G[cu]
    u += 5.0 * t * q4 * G[cu + 1]
    u += 10.0 * t2 * q3 * G[cu + 2]
    u += 10.0 * t3 * q2 * G[cu + 3]
    u += 5.0 * t4 * t1 * G[cu + 4]
    u += t4 * t * G[cu + 5]
    # c(u) and derivatives by Horner on the power-basis piece
    off_uk = int(G[_H_OFF_UK])
    i = _interval(G, off_uk, int(G[_H_N_UK]), u, G[_H_INV_UK]) if u == u else 0
    du = u - G[off_uk + i]
    c = int(G[_H_OFF_CC]) + 12 * i  # a_j (x, y) at c + 2 j
    x0 = G[c + 10]
    y0 = G[c + 11]
    x1 = 5.0 * G[c + 10]
    y1 = 5.0 * G[c + 11]
    x2 = 20.0 * G[c + 10]
    y2 = 20.0 * G[c + 11]
    x3 = 60.0 * G[c + 10]
    y3 = 60.0 * G[c + 11]
    x0 = x0 * du + G[c + 8]
    y0 = y0 * du + G[c + 9]
    x1 = x1 * du + 4.0 * G[c + 8]
    y1 = y1 * du + 4.0 * G[c + 9]
    x2 = x2 * du + 12.0 * G[c + 8]
    y2 = y2 * du + 12.0 * G[c + 9]
    x3 = x3 * du + 24.0 * G[c + 8]
    y3 = y3 * du + 24.0 * G[c + 9]
    x0 = x0 * du + G[c + 6]
    y0 = y0 * du + G[c + 7]
    x1 = x1 * du + 3.0 * G[c + 6]
    y1 = y1 * du + 3.0 * G[c + 7]
    x2 = x2 * du + 6.0 * G[c + 6]
    y2 = y2 * du + 6.0 * G[c + 7]
    x3 = x3 * du + 6.0 * G[c + 6]
    y3 = y3 * du + 6.0 * G[c + 7]
    x0 = x0 * du + G[c + 4]
    y0 = y0 * du + G[c + 5]
    x1 = x1 * du + 2.0 * G[c + 4]
    y1 = y1 * du + 2.0 * G[c + 5]
    x2 = x2 * du + 2.0 * G[c + 4]
    y2 = y2 * du + 2.0 * G[c + 5]
    x0 = x0 * du + G[c + 2]
    y0 = y0 * du + G[c + 3]
    x1 = x1 * du + G[c + 2]
    y1 = y1 * du + G[c + 3]
    x0 = x0 * du + G[c]
    y0 = y0 * du + G[c + 1]
    return sc, si, x0, y0, x1, y1, x2, y2, x3, y3


@kernel
def frame_at(G, s):
    """ReferenceLine.frame(s) for one arc length s [m].

    Returns (x, y, tx, ty, heading, kappa, kappa_rate): position [m], unit tangent,
    unwrapped heading [rad], curvature [1/m], d kappa / ds [1/m^2]. Past the ends the line
    is straight (position linear in s, heading constant, kappa = kappa_rate = 0).
    """
    nan = np.nan
    if s != s:
        return nan, nan, nan, nan, nan, nan, nan
    sc, si, x0, y0, x1, y1, x2, y2, x3, y3 = _curve(G, s)
    g = math.sqrt(x1 * x1 + y1 * y1)
    tx = x1 / g
    ty = y1 / g
    cr12 = x1 * y2 - y1 * x2
    g3 = g * g * g
    kappa = cr12 / g3
    dkappa_du = (x1 * y3 - y1 * x3) / g3 - 3.0 * cr12 * (x1 * x2 + y1 * y2) / (g3 * g * g)
    kappa_rate = dkappa_du / g
    # unwrapped heading: the node np.searchsorted(s_nodes, sc) (side left) picks, clipped
    off_sn = int(G[_H_OFF_SN])
    n_sn = int(G[_H_N_SN])
    idx = si if G[off_sn + si] == sc else si + 1
    if idx > n_sn - 1:
        idx = n_sn - 1
    ref = G[int(G[_H_OFF_HN]) + idx]
    heading = ref + _wrap(math.atan2(ty, tx) - ref)
    ext = s - sc
    px = x0 + ext * tx
    py = y0 + ext * ty
    if s != sc:
        kappa = 0.0
        kappa_rate = 0.0
    return px, py, tx, ty, heading, kappa, kappa_rate


@kernel
def _point_at(G, s):
    """What the projection needs of frame_at (same arithmetic): x, y, tx, ty, kappa."""
    sc, si, x0, y0, x1, y1, x2, y2, x3, y3 = _curve(G, s)
    g = math.sqrt(x1 * x1 + y1 * y1)
    tx = x1 / g
    ty = y1 / g
    kappa = (x1 * y2 - y1 * x2) / (g * g * g)
    ext = s - sc
    if s != sc:
        kappa = 0.0
    return x0 + ext * tx, y0 + ext * ty, tx, ty, kappa


@kernel
def _nearest_sample(G, px, py, s_guess, stack):
    """Index of the line sample nearest to (px, py), exactly (the ReferenceLine's cKDTree
    query). With a guess: walk downhill from the guess's sample and accept the local minimum
    when certified; otherwise (or without a guess) search the ball tree.
    ``stack``: int64 scratch longer than twice the tree depth."""
    n = int(G[_H_N_SAMP])
    sxy = int(G[_H_OFF_SXY])
    best = np.inf
    best_i = 0
    if s_guess == s_guess:
        gi = (s_guess - G[int(G[_H_OFF_SS])]) / G[_H_DS]
        if gi < 0.0:
            j = 0
        elif gi > n - 1:
            j = n - 1
        else:
            j = int(gi + 0.5)
        dx = G[sxy + 2 * j] - px
        dy = G[sxy + 2 * j + 1] - py
        best = dx * dx + dy * dy
        best_i = j
        for step in (-1, 1):  # walk downhill to a local minimum of the sample distance
            while True:
                jn = best_i + step
                if jn < 0 or jn >= n:
                    break
                dx = G[sxy + 2 * jn] - px
                dy = G[sxy + 2 * jn + 1] - py
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    best_i = jn
                else:
                    break
        # certificate that it is the nearest of all samples: (1) within +-W samples the
        # squared distance along the curve is convex (its second derivative 1 - kappa
        # (p - c).n > 0 when kappa_max (d + (W + 1) ds) < 1), so a discrete local minimum is
        # the minimum there; (2) a sample more than W away is at least clear - d from p
        # (triangle inequality), more than d when 2 d < clear
        dmin = math.sqrt(best)
        if (G[_H_KAPPA] * (dmin + (G[_H_WINDOW] + 1.0) * G[_H_DS]) < 0.5
                and 2.0 * dmin + 1e-9 < G[int(G[_H_OFF_CLR]) + best_i]):
            return best_i
    tr = int(G[_H_OFF_TREE])
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = tr + 7 * stack[top]
        dx = G[node + 4] - px
        dy = G[node + 5] - py
        lb = math.sqrt(dx * dx + dy * dy) - G[node + 6]
        if lb > 0.0 and lb * lb > best:
            continue
        left = int(G[node + 2])
        if left < 0:
            for j in range(int(G[node]), int(G[node + 1])):
                dx = G[sxy + 2 * j] - px
                dy = G[sxy + 2 * j + 1] - py
                d2 = dx * dx + dy * dy
                if d2 < best or (d2 == best and j < best_i):
                    best = d2
                    best_i = j
        else:
            right = int(G[node + 3])
            nl = tr + 7 * left
            nr = tr + 7 * right
            dlx = G[nl + 4] - px
            dly = G[nl + 5] - py
            drx = G[nr + 4] - px
            dry = G[nr + 5] - py
            if dlx * dlx + dly * dly <= drx * drx + dry * dry:  # nearer child searched first
                stack[top] = right
                stack[top + 1] = left
            else:
                stack[top] = left
                stack[top + 1] = right
            top += 2
    return best_i


@kernel
def _newton_step(G, s, px, py, max_step):
    """One step of ReferenceLine.to_frenet's Newton iteration on (p - c(s)).t = 0."""
    x, y, tx, ty, kappa = _point_at(G, s)
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
    return step


@kernel
def to_frenet_one(G, px, py, s_guess):
    """ReferenceLine.to_frenet for one point: (s, d). ``s_guess`` (NaN: none) only speeds up
    the exact search for the nearest 1 m sample; from it the Newton iteration is the
    reference's: step (p - c(s)).t / (1 - kappa d) (denominator 1 where <= 0.1), clipped to
    two sample spacings, until a step is below 1e-10 m or after 50 steps."""
    if px != px or py != py:
        return np.nan, np.nan
    stack = np.empty(128, dtype=np.int64)
    s = G[int(G[_H_OFF_SS]) + _nearest_sample(G, px, py, s_guess, stack)]
    max_step = G[_H_MAX_STEP]
    tol = G[_H_TOL]
    for _ in range(int(G[_H_N_IT])):
        step = _newton_step(G, s, px, py, max_step)
        s = s + step
        if abs(step) < tol:
            break
    x, y, tx, ty, kappa = _point_at(G, s)
    return s, (px - x) * (-ty) + (py - y) * tx


@kernel
def to_frenet_many(G, xy, s_guess):
    """to_frenet_one for points xy (n, 2) with guesses s_guess (n,) (NaN: none): (s, d).

    The points iterate in lockstep, each until its own convergence (so each gets exactly
    to_frenet_one's iterates): independent points overlap in the CPU pipeline."""
    n = xy.shape[0]
    s = np.empty(n)
    d = np.empty(n)
    stack = np.empty(128, dtype=np.int64)
    active = np.empty(n, dtype=np.int64)
    max_step = G[_H_MAX_STEP]
    tol = G[_H_TOL]
    off_ss = int(G[_H_OFF_SS])
    na = 0
    for i in range(n):
        px = xy[i, 0]
        py = xy[i, 1]
        if px != px or py != py:
            s[i] = np.nan
            d[i] = np.nan
        else:
            s[i] = G[off_ss + _nearest_sample(G, px, py, s_guess[i], stack)]
            active[na] = i
            na += 1
    for _ in range(int(G[_H_N_IT])):
        if na == 0:
            break
        k = 0
        for a in range(na):
            i = active[a]
            step = _newton_step(G, s[i], xy[i, 0], xy[i, 1], max_step)
            s[i] = s[i] + step
            if not abs(step) < tol:
                active[k] = i
                k += 1
        na = k
    for i in range(n):
        if s[i] == s[i]:
            x, y, tx, ty, kappa = _point_at(G, s[i])
            d[i] = (xy[i, 0] - x) * (-ty) + (xy[i, 1] - y) * tx
        else:
            d[i] = np.nan
    return s, d


@kernel
def frame_many(G, s):
    """frame_at over an array s (n,): (n, 7) columns x, y, tx, ty, heading, kappa, kappa_rate."""
    out = np.empty((s.shape[0], 7))
    for i in range(s.shape[0]):
        r = frame_at(G, s[i])
        for j in range(7):
            out[i, j] = r[j]
    return out
