"""A ReferenceLine packed into the float64 buffer ``G`` the kernels of road/fast_line.py
evaluate (layout: fast_line's header ``_H_*``), and the per-line cache :func:`packed`.

``ReferenceLine.frame`` / ``to_frenet`` evaluate through this buffer, so this module reads
the line's fitted pieces by attribute and does not import road/geometry.py."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from .bernstein import ball_tree, clearance
from .fast_line import (_H_KAPPA, _H_N_SAMP, _H_OFF_CC, _H_OFF_CLR, _H_OFF_HN, _H_OFF_SN,
                        _H_OFF_SS, _H_OFF_SXY, _H_OFF_TREE, _H_OFF_UC, _H_OFF_UK, _H_SIZE,
                        LEAF_SIZE, WINDOW, frame_at, frame_many, to_frenet_many)
from .line_fit import _DEGREE

_NEWTON_ITERATIONS = 50
"""Newton steps of the Frenet projection at most."""
_NEWTON_TOL = 1e-10
"""The projection stops when a Newton step is below this [m]."""


@dataclass(frozen=True, eq=False)
class FastLine:
    """A ReferenceLine packed into one float64 buffer ``G`` for the kernels of road/fast_line.py."""

    length: float
    G: np.ndarray

    @classmethod
    def from_reference_line(cls, line) -> "FastLine":
        """Pack a :class:`~.geometry.ReferenceLine` (its fitted spline, u(s), nodes, samples)."""
        from scipy.interpolate import PPoly

        curve = line.curve  # scipy BSpline
        k = curve.k
        if k != _DEGREE or np.asarray(curve.c).ndim != 2 or curve.c.shape[1] != 2:
            raise ValueError("expected a quintic planar BSpline c(u)")
        t = np.asarray(curve.t, dtype=float)
        n_coef = len(t) - k - 1
        u_knots = t[k:n_coef + 1].copy()  # base interval breakpoints t[k] .. t[n]
        if np.any(np.diff(u_knots) <= 0.0):
            raise ValueError("the spline's base knots must be strictly increasing")
        m = len(u_knots) - 1
        coef = np.empty((m, k + 1, 2))
        for dim in range(2):
            pp = PPoly.from_spline((t, np.asarray(curve.c[:, dim], dtype=float), k))
            if not np.array_equal(pp.x[k:n_coef + 1], u_knots):
                raise ValueError("unexpected PPoly breakpoints")
            coef[:, :, dim] = pp.c[::-1, k:n_coef].T  # ascending powers about the left knot
        bp = line.u_of_s  # scipy BPoly
        uc = np.asarray(bp.c, dtype=float).reshape(bp.c.shape[0], -1)
        s_nodes = np.asarray(bp.x, dtype=float)
        if uc.shape != (k + 1, len(s_nodes) - 1):
            raise ValueError("u(s) must be a scalar quintic BPoly")
        if not np.array_equal(s_nodes, line.s_nodes):
            raise ValueError("u(s) breakpoints differ from s_nodes")
        samp_xy = np.asarray(line.tree_xy, dtype=float)
        samp_s = np.asarray(line.tree_s, dtype=float)
        ds = float(samp_s[1] - samp_s[0])
        tree = ball_tree(samp_xy, LEAF_SIZE)
        parts = [
            (_H_OFF_UK, u_knots), (_H_OFF_CC, coef), (_H_OFF_SN, s_nodes), (_H_OFF_UC, uc.T),
            (_H_OFF_HN, np.asarray(line.heading_nodes, dtype=float)), (_H_OFF_SXY, samp_xy),
            (_H_OFF_SS, samp_s), (_H_OFF_CLR, _clearance(samp_xy, WINDOW)),
            (_H_OFF_TREE, tree),
        ]
        G = np.zeros(_H_SIZE + sum(np.size(a) for _, a in parts))
        G[:_H_N_SAMP + 1] = [line.length, 2.0 * ds, ds, _NEWTON_TOL, float(_NEWTON_ITERATIONS),
                             0.0, float(WINDOW),
                             (len(s_nodes) - 1) / (s_nodes[-1] - s_nodes[0]),
                             (len(u_knots) - 1) / (u_knots[-1] - u_knots[0]),
                             len(u_knots), len(s_nodes), len(samp_s)]
        off = _H_SIZE
        for h, a in parts:
            G[h] = off
            G[off:off + np.size(a)] = np.ascontiguousarray(a, dtype=float).ravel()
            off += np.size(a)
        # bound on |kappa| for the projection's certificate, from the packed line itself
        kappa = frame_many(G, np.linspace(0.0, line.length, 4 * len(samp_s) + 1))[:, 5]
        G[_H_KAPPA] = 1.25 * float(np.max(np.abs(kappa))) + 1e-9
        return cls(float(line.length), G)

    # Python-level conveniences ------------------------------------------------------------
    def frame(self, s: float):
        """(x, y, tx, ty, heading, kappa, kappa_rate) at arc length s [m]."""
        return frame_at(self.G, float(s))

    def to_frenet(self, xy, s_guess=None):
        """(s, d) of points xy (n, 2) [m]; ``s_guess`` (n,) (e.g. last step's s; NaN: none)
        only makes the search cheaper, the result is the same."""
        xy = np.asarray(xy, dtype=float)
        if xy.ndim != 2 or xy.shape[1] != 2 or not xy.flags.c_contiguous or not xy.flags.writeable:
            xy = np.array(xy, dtype=float, order="C").reshape(-1, 2)
        n = xy.shape[0]
        g = np.empty(n)
        g[:] = np.nan if s_guess is None else s_guess
        return to_frenet_many(self.G, xy, g)


def _clearance(xy: np.ndarray, window: int) -> np.ndarray:
    """Distance from every sample to the nearest sample more than ``window`` samples away
    (inf if none is within 4 window spacings: then only the tree search is used; compiled,
    road/bernstein.py)."""
    ds = float(np.hypot(*(xy[1] - xy[0]))) if len(xy) > 1 else 1.0
    return clearance(np.ascontiguousarray(xy, dtype=float), window, 4.0 * window * max(ds, 1e-9))


def packed(line) -> np.ndarray:
    """The buffer G of a ReferenceLine (built once per line and kept on it, or read back
    with it from the road cache); a FastLine or a G buffer passes through."""
    if isinstance(line, np.ndarray):
        return line
    if isinstance(line, FastLine):
        return line.G
    G = line.kept("G")
    if G is None:
        G = FastLine.from_reference_line(line).G
        line.keep(G=G)
    return G


def keep_packed(line, G: np.ndarray) -> None:
    """Keep ``G``, the buffer :func:`packed` built for ``line`` in an earlier process (read
    back from the road cache, sumo/road_cache.py), on the ReferenceLine ``line``."""
    line.keep(G=G)
