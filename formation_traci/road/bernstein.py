"""Setting up a reference line fast (road/geometry.py, road/line_pack.py): the quintic
Hermite map u(s) in Bernstein form for every knot interval at once, and the compiled ball
tree and clearance of the line's samples. Each gives, value for value, what the per-interval
Python code it replaces gave (scipy's ``BPoly.from_derivatives``; the recursive tree build;
the clearance from a k-nearest query), in a fraction of the time: a 120 km line took 7 s
of set-up before.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from ..core.kernels import kernel

if TYPE_CHECKING:  # pragma: no cover
    from scipy.interpolate import BPoly


def hermite_bpoly(xi: np.ndarray, yi: np.ndarray, extrapolate=True) -> BPoly:
    """``BPoly.from_derivatives(xi, yi, extrapolate=extrapolate)`` for ``yi`` of shape
    (m + 1, d): d derivatives at every breakpoint, a polynomial of degree 2d - 1 per interval.
    The arithmetic of scipy's ``_construct_from_derivatives``, operation for operation, on all
    intervals at once (the powers of the interval length through the same scalar ``pow``)."""
    from scipy.interpolate import BPoly
    from scipy.special import comb, poch

    xi = np.asarray(xi, dtype=float)
    yi = np.asarray(yi, dtype=float)
    d = yi.shape[1]
    n = 2 * d
    ya, yb = yi[:-1], yi[1:]
    h_list = [float(b - a) for a, b in zip(xi[:-1].tolist(), xi[1:].tolist())]
    c = np.empty((len(h_list), n))
    for q in range(d):
        hq = np.array([h ** q for h in h_list])
        c[:, q] = ya[:, q] / poch(n - q, q) * hq
        for j in range(q):
            c[:, q] -= (-1) ** (j + q) * comb(q, j) * c[:, j]
    for q in range(d):
        hq = np.array([h ** q for h in h_list])
        c[:, -q - 1] = yb[:, q] / poch(n - q, q) * (-1) ** q * hq
        for j in range(q):
            c[:, -q - 1] -= (-1) ** (j + 1) * comb(q, j + 1) * c[:, -q + j]
    return BPoly(c.T.copy(), xi, extrapolate)


@kernel
def ball_tree(xy, leaf_size):
    """Ball tree over contiguous runs of samples xy (n, 2), nodes in pre-order: rows
    (lo, hi, left, right, cx, cy, r) (left/right -1 at a leaf)."""
    n = xy.shape[0]
    cap = 4 * (n // leaf_size + 2)
    nodes = np.empty((cap, 7))
    stack = np.empty((cap, 3), dtype=np.int64)  # lo, hi, parent * 2 + side (-1: root)
    stack[0, 0] = 0
    stack[0, 1] = n
    stack[0, 2] = -1
    top = 1
    count = 0
    while top > 0:
        top -= 1
        lo = stack[top, 0]
        hi = stack[top, 1]
        link = stack[top, 2]
        idx = count
        count += 1
        if link >= 0:
            nodes[link // 2, 2 + link % 2] = idx
        xmin = xy[lo, 0]
        xmax = xy[lo, 0]
        ymin = xy[lo, 1]
        ymax = xy[lo, 1]
        for k in range(lo + 1, hi):
            xmin = min(xmin, xy[k, 0])
            xmax = max(xmax, xy[k, 0])
            ymin = min(ymin, xy[k, 1])
            ymax = max(ymax, xy[k, 1])
        cx = 0.5 * (xmin + xmax)
        cy = 0.5 * (ymin + ymax)
        r = 0.0
        for k in range(lo, hi):
            dk = np.hypot(xy[k, 0] - cx, xy[k, 1] - cy)
            if dk > r:
                r = dk
        nodes[idx, 0] = lo
        nodes[idx, 1] = hi
        nodes[idx, 2] = -1
        nodes[idx, 3] = -1
        nodes[idx, 4] = cx
        nodes[idx, 5] = cy
        nodes[idx, 6] = r * (1.0 + 1e-12) + 1e-9
        if hi - lo > leaf_size:
            mid = (lo + hi) // 2
            stack[top, 0] = mid  # right first: the left subtree is numbered first
            stack[top, 1] = hi
            stack[top, 2] = 2 * idx + 1
            stack[top + 1, 0] = lo
            stack[top + 1, 1] = mid
            stack[top + 1, 2] = 2 * idx
            top += 2
    return nodes[:count].copy()


@kernel
def _dist(xy, i, j):
    dx = xy[j, 0] - xy[i, 0]
    dy = xy[j, 1] - xy[i, 1]
    return math.sqrt(dx * dx + dy * dy)


@kernel
def clearance(xy, window, bound):
    """Distance [m] from every sample of xy (n, 2) to the nearest sample more than
    ``window`` samples away along the line, inf where none is closer than ``bound`` [m];
    0 everywhere when the line has fewer than 2 window + 2 samples (no certificate). A grid
    of cells of bound / 4: starting from the samples just outside the window, only cells
    nearer than the best distance so far are searched."""
    n = xy.shape[0]
    out = np.full(n, np.inf)
    if n < 2 * window + 2:
        out[:] = 0.0
        return out
    cs = bound / 4.0
    x0 = xy[:, 0].min()
    y0 = xy[:, 1].min()
    nx = int((xy[:, 0].max() - x0) / cs) + 1
    ny = int((xy[:, 1].max() - y0) / cs) + 1
    cx = np.empty(n, dtype=np.int64)
    cy = np.empty(n, dtype=np.int64)
    key = np.empty(n, dtype=np.int64)
    for i in range(n):
        cx[i] = min(int((xy[i, 0] - x0) / cs), nx - 1)
        cy[i] = min(int((xy[i, 1] - y0) / cs), ny - 1)
        key[i] = cy[i] * nx + cx[i]
    order = np.argsort(key, kind="mergesort")
    skey = key[order]
    margin = 1e-9 * cs + 1e-9
    for i in range(n):
        best = np.inf
        if i - window - 1 >= 0:
            best = min(best, _dist(xy, i, i - window - 1))
        if i + window + 1 < n:
            best = min(best, _dist(xy, i, i + window + 1))
        px = xy[i, 0]
        py = xy[i, 1]
        for gy in range(max(cy[i] - 4, 0), min(cy[i] + 5, ny)):
            ey = max(0.0, max(y0 + gy * cs - py, py - (y0 + (gy + 1) * cs)))
            for gx in range(max(cx[i] - 4, 0), min(cx[i] + 5, nx)):
                ex = max(0.0, max(x0 + gx * cs - px, px - (x0 + (gx + 1) * cs)))
                if math.sqrt(ex * ex + ey * ey) - margin >= best:
                    continue
                kk = gy * nx + gx
                a = np.searchsorted(skey, kk)
                while a < n and skey[a] == kk:
                    j = order[a]
                    a += 1
                    if abs(j - i) > window:
                        dd = _dist(xy, i, j)
                        if dd < best:
                            best = dd
        if best < bound:
            out[i] = best
    return out
