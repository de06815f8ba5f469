"""Encounters of two oriented rectangles: same-time pairs, clearance and 2-D time to collision.

Geometry as in :mod:`analysis.metrics.footprint` (body centre, heading [rad CCW from +x], length and
width [m]). Part of the traffic interaction measures (:mod:`analysis.metrics.traffic`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["TTC2D_THRESHOLD_S", "TTC2D_HORIZON_S", "Moving", "same_time_pairs", "clearance",
           "ttc_2d", "pair_measures"]

TTC2D_THRESHOLD_S = 3.0
"""2-D time to collision below which an encounter is a conflict [s]; the TTC threshold of
SUMO's SSM device used by the runs (``--device.ssm.thresholds``)."""

TTC2D_HORIZON_S = 10.0
"""Constant-velocity extrapolation horizon of the 2-D time to collision [s]."""


class Moving(NamedTuple):
    """Oriented rectangles moving at constant velocity (each field array_like, broadcast
    together)."""

    x: object  # centre x [m]
    y: object  # centre y [m]
    heading: object  # [rad, CCW from +x]
    length: object  # [m]
    width: object  # [m]
    vx: object  # velocity x [m/s]
    vy: object  # velocity y [m/s]


def same_time_pairs(key_a, key_b) -> tuple[np.ndarray, np.ndarray]:
    """All index pairs ``(i, j)`` with ``key_a[i] == key_b[j]`` (e.g. the same time step).

    Parameters
    ----------
    key_a : array_like of int
        Key of each row of table A, shape ``(n_a,)``.
    key_b : array_like of int
        Key of each row of table B, shape ``(n_b,)``.

    Returns
    -------
    (ndarray, ndarray)
        Row indices into A and into B, one entry per matching pair, grouped by A's row
        in ascending order.

    Examples
    --------
    >>> [a.tolist() for a in same_time_pairs([0, 1], [1, 0, 1])]
    [[0, 1, 1], [1, 0, 2]]
    """
    ka = np.asarray(key_a)
    kb = np.asarray(key_b)
    order = np.argsort(kb, kind="stable")
    kb_sorted = kb[order]
    lo = np.searchsorted(kb_sorted, ka, side="left")
    hi = np.searchsorted(kb_sorted, ka, side="right")
    counts = hi - lo
    ia = np.repeat(np.arange(ka.size), counts)
    starts = np.repeat(lo - np.concatenate(([0], np.cumsum(counts)[:-1])), counts)
    ib = order[np.arange(ia.size) + starts]
    return ia, ib


_SU = np.array([1.0, -1.0, -1.0, 1.0])
_SV = np.array([1.0, 1.0, -1.0, -1.0])


def _min4(a: np.ndarray) -> np.ndarray:
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), np.minimum(a[:, 2], a[:, 3]))


class _Frames:
    """Each rectangle seen from the other's frame (shared by clearance and TTC)."""

    def __init__(self, xa, ya, ha, la, wa, xb, yb, hb, lb, wb):
        xa, ya, ha, la, wa, xb, yb, hb, lb, wb = np.broadcast_arrays(
            *(np.atleast_1d(np.asarray(v, float)) for v in (xa, ya, ha, la, wa, xb, yb, hb,
                                                            lb, wb)))
        self.hla, self.hwa, self.hlb, self.hwb = 0.5 * la, 0.5 * wa, 0.5 * lb, 0.5 * wb
        self.ca, self.sa, self.cb, self.sb = np.cos(ha), np.sin(ha), np.cos(hb), np.sin(hb)
        dx, dy = xb - xa, yb - ya
        # centre of B in A's frame, and of A in B's frame
        self.ub, self.vb = self.ca * dx + self.sa * dy, -self.sa * dx + self.ca * dy
        self.ua, self.va = -(self.cb * dx + self.sb * dy), -(-self.sb * dx + self.cb * dy)
        phi = hb - ha  # B's heading in A's frame (A's is -phi in B's frame)
        self.cp, self.sp = np.cos(phi), np.sin(phi)
        acp, asp = np.abs(self.cp), np.abs(self.sp)
        # half-extents of each rectangle projected on the other's axes
        self.rb_u = self.hlb * acp + self.hwb * asp
        self.rb_v = self.hlb * asp + self.hwb * acp
        self.ra_u = self.hla * acp + self.hwa * asp
        self.ra_v = self.hla * asp + self.hwa * acp

    def separated(self) -> np.ndarray:
        return ((np.abs(self.ub) > self.hla + self.rb_u)
                | (np.abs(self.vb) > self.hwa + self.rb_v)
                | (np.abs(self.ua) > self.hlb + self.ra_u)
                | (np.abs(self.va) > self.hwb + self.ra_v))

    def clearance(self) -> np.ndarray:
        c, s = self.cp[:, None], self.sp[:, None]
        lu, lv = self.hlb[:, None] * _SU, self.hwb[:, None] * _SV
        u, v = self.ub[:, None] + c * lu - s * lv, self.vb[:, None] + s * lu + c * lv
        d_b = np.hypot(np.maximum(np.abs(u) - self.hla[:, None], 0.0),
                       np.maximum(np.abs(v) - self.hwa[:, None], 0.0))
        lu, lv = self.hla[:, None] * _SU, self.hwa[:, None] * _SV  # A in B's frame: -phi
        u, v = self.ua[:, None] + c * lu + s * lv, self.va[:, None] - s * lu + c * lv
        d_a = np.hypot(np.maximum(np.abs(u) - self.hlb[:, None], 0.0),
                       np.maximum(np.abs(v) - self.hwb[:, None], 0.0))
        return np.where(self.separated(), np.minimum(_min4(d_b), _min4(d_a)), 0.0)

    def ttc(self, vxa, vya, vxb, vyb, horizon: float) -> np.ndarray:
        vxa, vya, vxb, vyb = (np.broadcast_to(np.asarray(v, float), self.ub.shape)
                              for v in (vxa, vya, vxb, vyb))
        rx, ry = vxb - vxa, vyb - vya  # B relative to A
        ru_a, rv_a = self.ca * rx + self.sa * ry, -self.sa * rx + self.ca * ry
        ru_b, rv_b = -(self.cb * rx + self.sb * ry), -(-self.sb * rx + self.cb * ry)
        enter = np.full(self.ub.shape, -np.inf)
        leave = np.full(self.ub.shape, np.inf)
        for half, centre, radius, u in ((self.hla, self.ub, self.rb_u, ru_a),
                                        (self.hwa, self.vb, self.rb_v, rv_a),
                                        (self.hlb, self.ua, self.ra_u, ru_b),
                                        (self.hwb, self.va, self.ra_v, rv_b)):
            lo, hi = _axis_interval(-half, half, centre - radius, centre + radius, u)
            enter, leave = np.maximum(enter, lo), np.minimum(leave, hi)
        hit = (enter <= leave) & (leave >= 0) & (enter <= horizon)
        return np.where(hit, np.maximum(enter, 0.0), np.inf)


def _axis_interval(a0, a1, b0, b1, u):
    """Times at which [b0, b1] + u t overlaps [a0, a1] (closed), as (t_lo, t_hi)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / u
        lo = np.where(u > 0, (a0 - b1) * inv, (a1 - b0) * inv)
        hi = np.where(u > 0, (a1 - b0) * inv, (a0 - b1) * inv)
    still = u == 0
    if still.any():
        overlap = (b0 <= a1) & (b1 >= a0)
        lo = np.where(still, np.where(overlap, -np.inf, np.inf), lo)
        hi = np.where(still, np.where(overlap, np.inf, -np.inf), hi)
    return lo, hi


def clearance(xa, ya, ha, la, wa, xb, yb, hb, lb, wb) -> np.ndarray:
    """Minimum distance between the outlines of two oriented rectangles.

    Parameters
    ----------
    xa : array_like
        Centre x of rectangle A [m].
    ya : array_like
        Centre y of A [m].
    ha : array_like
        Heading of A [rad].
    la : array_like
        Length of A [m].
    wa : array_like
        Width of A [m].
    xb : array_like
        Centre x of rectangle B [m].
    yb : array_like
        Centre y of B [m].
    hb : array_like
        Heading of B [rad].
    lb : array_like
        Length of B [m].
    wb : array_like
        Width of B [m].

    Returns
    -------
    ndarray
        Polygon distance [m], shape of the broadcast inputs (at least 1-D): 0 when the
        rectangles touch or overlap (separating-axis test on the four edge normals),
        else the smallest distance from a corner of one to the other rectangle (for
        disjoint convex polygons the closest pair always includes a corner).

    Examples
    --------
    >>> float(clearance(0, 0, 0, 4, 2, 10, 0, 0, 4, 2)[0])
    6.0
    """
    return _Frames(xa, ya, ha, la, wa, xb, yb, hb, lb, wb).clearance()


def ttc_2d(a: Moving, b: Moving, horizon: float = TTC2D_HORIZON_S) -> np.ndarray:
    """2-D time to collision of two rectangles moving at constant velocity.

    Both outlines keep their heading and translate with their current velocity; the
    result is the first time their outlines touch (exact for rectangles: the separating-
    axis test on the four edge normals, solved per axis for the interval of overlap and
    intersected over the axes).

    Parameters
    ----------
    a : Moving
        Rectangle A (centre [m], heading [rad], length and width [m], velocity [m/s]).
    b : Moving
        Rectangle B.
    horizon : float
        Longest time looked ahead [s].

    Returns
    -------
    ndarray
        Time to first contact [s]: 0 when the outlines already overlap, ``inf`` when
        they do not touch within ``horizon`` (or move apart).

    Examples
    --------
    >>> float(ttc_2d(Moving(0, 0, 0, 4, 2, 30, 0), Moving(24, 0, 0, 4, 2, 25, 0))[0])  # 20 m at 5 m/s
    4.0
    """
    return _frames(a, b).ttc(a.vx, a.vy, b.vx, b.vy, horizon)


def pair_measures(a: Moving, b: Moving,
                  horizon: float = TTC2D_HORIZON_S) -> tuple[np.ndarray, np.ndarray]:
    """:func:`clearance` and :func:`ttc_2d` of the same pairs, sharing the geometry.

    Parameters
    ----------
    a : Moving
        Rectangle A.
    b : Moving
        Rectangle B.
    horizon : float
        Longest time looked ahead [s].

    Returns
    -------
    (ndarray, ndarray)
        Clearance [m] and 2-D time to collision [s] (``inf``: no contact within
        ``horizon``), shape of the broadcast inputs (at least 1-D).
    """
    f = _frames(a, b)
    return f.clearance(), f.ttc(a.vx, a.vy, b.vx, b.vy, horizon)


def _frames(a: Moving, b: Moving) -> "_Frames":
    return _Frames(a.x, a.y, a.heading, a.length, a.width, b.x, b.y, b.heading, b.length, b.width)


