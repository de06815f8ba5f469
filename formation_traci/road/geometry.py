"""Smooth, arc-length-parametrised reference line of a road lane.

A SUMO lane is a polyline whose vertices lie on the designed road (curves are sampled every
4 m and stored to 0.1 mm). Differentiating the polyline gives headings with kinks and a
curvature made of spikes. :class:`ReferenceLine` turns the polyline into a smooth planar
curve ``c(s)`` with continuous heading, curvature and curvature rate:

1. drop points closer than ``min_segment`` to the previous kept one (zero-length internal
   lanes at edge joints, repeated end points), and split segments longer than
   ``max_segment`` into equal pieces (a long polyline segment is a straight in SUMO);
2. fit ``x(u)``, ``y(u)`` over the cumulative chord length ``u`` with a penalised
   regression spline (P-spline, Eilers & Marx 1996): quintic B-splines on uniform knots,
   penalty on the fifth differences of the coefficients. Its transfer function is about
   ``1 / (1 + (lambda_w / wavelength)^10)``, where ``lambda_w`` is the smoothing length: the
   0.1 mm rounding is removed, and road curvature (wavelength ``2 pi R``) passes unbiased;
3. reparametrise by arc length: ``s(u)`` is integrated with Gauss-Legendre quadrature, and
   its inverse ``u(s)`` is a quintic Hermite interpolant with exact first and second
   derivatives, so ``|dc/ds| = 1`` to round-off.

Heading, curvature and curvature rate are then exact derivatives of the fitted curve:
``theta = atan2(c'_y, c'_x)``, ``kappa = (c' x c'') / |c'|^3`` and its derivative, taken
analytically from the spline (no finite differences).

Outside ``[0, length]`` the line is extended straight along the end tangents (position
linear in s, heading constant, curvature and curvature rate 0). Frenet coordinates
(``to_frenet`` / ``from_frenet``) are valid within ``|d| < 1 / |kappa|``.

Only :mod:`sumolib` is used to read networks (never libsumo or traci).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Sequence, Union

import numpy as np

from .bernstein import hermite_bpoly
from .fast_line import frame_many, to_frenet_many
from .line_fit import (_DEGREE, _GAUSS_NODES, _GAUSS_WEIGHTS, LINE_FIT_DEFAULT, LineFit,
                       _fit_pspline, chord_lengths, clean_polyline)
from .line_pack import packed

if TYPE_CHECKING:  # pragma: no cover
    import sumolib.net
    from scipy.interpolate import BPoly, BSpline
    from scipy.spatial import cKDTree

NetLike = Union[str, "os.PathLike[str]", "sumolib.net.Net"]

_GAP_TOL = 0.05
"""Largest allowed gap between consecutive lane shapes of a route [m]."""


@dataclass(frozen=True, slots=True)
class LinePoint:
    """Geometry of the reference line at arc lengths s, shapes ``s.shape (+ (2,))``."""

    position: np.ndarray  # c(s) [m]
    tangent: np.ndarray  # unit tangent t(s) [-]
    normal: np.ndarray  # unit left normal n(s) = J t(s) [-]
    heading: np.ndarray  # angle of t, counter-clockwise from +x, unwrapped [rad]
    curvature: np.ndarray  # kappa(s), left turns positive [1/m]
    curvature_rate: np.ndarray  # d kappa / ds [1/m^2]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


@dataclass(frozen=True, eq=False)
class ReferenceLine:
    """Smooth planar curve c(s) parametrised by arc length s in [0, length] [m].

    Build it with :meth:`from_points` or :func:`reference_line_from_net`. All methods are
    vectorised over s (any shape); positions get a trailing axis of 2. Beyond the ends the
    line continues straight along the end tangents.

    The line is its arrays (:data:`ARRAYS`): scipy's objects of the fit (``curve``,
    ``curve_d1..3``, ``u_of_s``, ``tree``) are made from them when first asked for, and the
    evaluation runs on the packed buffer (road/line_pack.py), so a line read back from the
    road cache (sumo/road_cache.py) needs no scipy.
    """

    length: float  # arc length of the fitted curve [m]
    points: np.ndarray = field(repr=False)  # cleaned input polyline, shape (n, 2) [m]
    knots: np.ndarray = field(repr=False)  # knots of the quintic B-spline c(u) [m]
    coef: np.ndarray = field(repr=False)  # its coefficients, shape (n_coef, 2) [m]
    u_coef: np.ndarray = field(repr=False)  # Bernstein coefficients of u(s), shape (6, m) [m]
    s_nodes: np.ndarray = field(repr=False)  # arc length at the knots, shape (m+1,) [m]
    heading_nodes: np.ndarray = field(repr=False)  # unwrapped heading at s_nodes [rad]
    tree_xy: np.ndarray = field(repr=False)  # samples of c, first guess of the projection [m]
    tree_s: np.ndarray = field(repr=False)  # arc length of the tree samples [m]
    _made: dict = field(default_factory=dict, init=False, repr=False, compare=False)  # scipy objects, G

    ARRAYS = ("points", "knots", "coef", "u_coef", "s_nodes", "heading_nodes", "tree_xy",
              "tree_s")
    """The fields that are arrays (with ``length`` they are the whole line)."""

    @classmethod
    def from_points(cls, xy, fit: LineFit = LINE_FIT_DEFAULT) -> "ReferenceLine":
        """Smooth a polyline into a reference line (see the module docstring).

        Parameters
        ----------
        xy : array_like, shape (n, 2)
            Polyline vertices in driving order [m].
        fit : LineFit
            Smoothing settings.
        """
        pts = clean_polyline(xy, fit.min_segment, fit.max_segment)
        return cls.from_curve(pts, _fit_pspline(chord_lengths(pts), pts, fit))

    @classmethod
    def from_curve(cls, pts: np.ndarray, curve: "BSpline") -> "ReferenceLine":
        """The line of a fitted quintic spline c(u) (steps 3 on of the module docstring).

        Parameters
        ----------
        pts : ndarray, shape (n, 2)
            The cleaned polyline it was fitted to [m] (kept as ``points``).
        curve : scipy BSpline
            c(u) over the chord-length parameter u [m] (line_fit.py ``solve_pspline``).
        """
        from scipy.spatial import cKDTree

        d1, d2, d3 = (curve.derivative(k) for k in (1, 2, 3))
        # arc length at the knots inside [0, U], by Gauss-Legendre per knot interval
        u_nodes = np.unique(curve.t[_DEGREE:len(curve.t) - _DEGREE])
        a, b = u_nodes[:-1], u_nodes[1:]
        uq = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * _GAUSS_NODES[None, :]
        speed = np.hypot(*np.moveaxis(d1(uq), -1, 0))
        seg = 0.5 * (b - a) * (speed * _GAUSS_WEIGHTS).sum(axis=1)
        s_nodes = np.concatenate([[0.0], np.cumsum(seg)])
        c1, c2 = d1(u_nodes), d2(u_nodes)
        g = np.hypot(c1[:, 0], c1[:, 1])
        derivs = np.stack([u_nodes, 1.0 / g, -_dot(c1, c2) / g ** 4], axis=1)  # u, u', u''
        u_of_s = hermite_bpoly(s_nodes, derivs, extrapolate=True)  # BPoly.from_derivatives
        # the C library's atan2 per node: numpy's arctan2 loop is SVML on AVX-512 CPUs
        heading_nodes = np.unwrap([math.atan2(y, x) for x, y in c1.tolist()])
        length = float(s_nodes[-1])
        n_tree = max(math.ceil(length / 1.0), 2) + 1
        tree_s = np.linspace(0.0, length, n_tree)
        tree = cKDTree(curve(u_of_s(tree_s).reshape(-1)))
        line = cls(length, pts, curve.t, curve.c, u_of_s.c, u_of_s.x, heading_nodes,
                   tree.data, tree_s)
        line.keep(curve=curve, curve_d1=d1, curve_d2=d2, curve_d3=d3, u_of_s=u_of_s, tree=tree)
        return line

    def keep(self, **made) -> None:
        """Keep objects built from the line on it by name (scipy objects, road/line_pack.py's G)."""
        self._made.update(made)

    def kept(self, name: str):
        """The object :meth:`keep` kept on the line under ``name``, else None."""
        return self._made.get(name)

    def _make(self, name: str):
        got = self._made.get(name)
        if got is None:
            from scipy.interpolate import BPoly, BSpline
            from scipy.spatial import cKDTree

            if name == "curve":
                got = BSpline(self.knots, self.coef, _DEGREE, extrapolate=True)
            elif name.startswith("curve_d"):
                got = self.curve.derivative(int(name[-1]))
            elif name == "u_of_s":
                got = BPoly(self.u_coef, self.s_nodes, True)
            else:
                got = cKDTree(self.tree_xy)
            self._made[name] = got
        return got

    curve = property(lambda self: self._make("curve"), doc="c(u), u = chord-length parameter [m] (scipy BSpline)")
    curve_d1 = property(lambda self: self._make("curve_d1"), doc="dc/du [-]")
    curve_d2 = property(lambda self: self._make("curve_d2"), doc="d2c/du2 [1/m]")
    curve_d3 = property(lambda self: self._make("curve_d3"), doc="d3c/du3 [1/m^2]")
    u_of_s = property(lambda self: self._make("u_of_s"), doc="u(s), quintic Hermite [m] (scipy BPoly)")
    tree = property(lambda self: self._make("tree"), doc="cKDTree of the samples tree_xy")

    # ---------------------------------------------------------------- evaluation
    def frame(self, s) -> LinePoint:
        """Position, Frenet frame, heading, curvature and curvature rate at s.

        Parameters
        ----------
        s : float or array_like
            Arc length [m]; values outside [0, length] use the straight extension.

        Evaluated by the compiled kernel :func:`.fast_line.frame_at` (one implementation;
        the JIT-off run of the tests is its Python reference).
        """
        s = np.asarray(s, dtype=float)
        F = frame_many(packed(self), np.array(s.reshape(-1), order="C")).reshape(s.shape + (7,))
        t = F[..., 2:4]
        normal = np.stack([-t[..., 1], t[..., 0]], axis=-1)
        return LinePoint(F[..., 0:2], t, normal, F[..., 4], F[..., 5], F[..., 6])

    def position(self, s) -> np.ndarray:
        """c(s) [m], shape ``s.shape + (2,)``; s is arc length [m]."""
        return self.frame(s).position

    def heading(self, s) -> np.ndarray:
        """Tangent angle at s [m], counter-clockwise from +x, unwrapped along s [rad]."""
        return self.frame(s).heading

    def curvature(self, s) -> np.ndarray:
        """Signed curvature kappa at s [m], left turns positive [1/m]."""
        return self.frame(s).curvature

    def curvature_rate(self, s) -> np.ndarray:
        """d kappa / ds at s [m] [1/m^2]."""
        return self.frame(s).curvature_rate

    def from_frenet(self, s, d) -> np.ndarray:
        """Point at arc length s [m] and lateral offset d [m] (left positive), ``c + d n``.

        s and d broadcast; the result has shape ``broadcast(s, d).shape + (2,)``.
        """
        s, d = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(d, dtype=float))
        f = self.frame(s)
        return f.position + d[..., None] * f.normal

    def to_frenet(self, xy) -> tuple[np.ndarray, np.ndarray]:
        """Project points onto the line: arc length s [m] and lateral offset d [m].

        d is positive to the left. The nearest of 1 m-spaced samples seeds a Newton
        iteration on ``(p - c(s)) . t(s) = 0``; points past the ends project onto the
        straight extension (s < 0 or s > length). Each point iterates until its own step
        is below the tolerance (the compiled :func:`.fast_line.to_frenet_many`).

        Parameters
        ----------
        xy : array_like, shape (..., 2)
            Points [m].

        Returns
        -------
        s, d : ndarray, shape (...)
        """
        p = np.asarray(xy, dtype=float)
        if p.shape[-1] != 2:
            raise ValueError(f"xy must have a trailing axis of 2, got {p.shape}")
        shape = p.shape[:-1]
        p = np.array(p.reshape(-1, 2), order="C")
        s, d = to_frenet_many(packed(self), p, np.full(p.shape[0], np.nan))
        return s.reshape(shape), d.reshape(shape)


# -------------------------------------------------------------------- SUMO networks
def load_net(net: NetLike) -> "sumolib.net.Net":
    """A sumolib network with internal lanes; a Net passes through unchanged.

    Parameters
    ----------
    net : str, PathLike or sumolib.net.Net
        Path of a ``.net.xml`` file, or a network already read with ``withInternal=True``.
    """
    if isinstance(net, (str, os.PathLike)):
        import sumolib

        return sumolib.net.readNet(os.fspath(net), withInternal=True)
    return net


def route_lanes(net: NetLike, edges: Sequence[str], lane_index: int) -> list[str]:
    """Lane ids a vehicle keeping its lane drives on a route, internal lanes included.

    Starts on lane ``lane_index`` of ``edges[0]`` and follows the connection of the current
    lane to the next edge (and its via lanes through the junction). Where a lane has
    several connections to the next edge, the one starting closest to its end is taken.
    The lane index may change at a joint (e.g. ``mw_up_1 -> mw_accel_2`` on ``onramp``).

    Parameters
    ----------
    net : str, PathLike or sumolib.net.Net
        The network (see :func:`load_net`).
    edges : sequence of str
        Edge ids of the route, in driving order.
    lane_index : int
        Lane index on the first edge (0 = rightmost).

    Raises
    ------
    ValueError
        If a lane has no connection to the next edge.
    """
    net = load_net(net)
    if not edges:
        raise ValueError("edges must not be empty")
    first = net.getEdge(edges[0])
    if not 0 <= lane_index < first.getLaneNumber():
        raise ValueError(f"lane_index {lane_index} not on edge {edges[0]!r} "
                         f"({first.getLaneNumber()} lanes)")
    lane = first.getLane(lane_index)
    ids = [lane.getID()]
    for nxt in edges[1:]:
        conns = [c for c in lane.getOutgoing() if c.getTo().getID() == nxt]
        if not conns:
            raise ValueError(f"lane {lane.getID()!r} has no connection to edge {nxt!r}")
        end = lane.getShape()[-1]
        conn = min(conns, key=lambda c: math.dist(end, c.getToLane().getShape()[0]))
        via = conn.getViaLaneID()
        while via:  # internal lanes, possibly split at internal junctions
            ids.append(via)
            nxt_internal = [c for c in net.getLane(via).getOutgoing()
                            if c.getToLane().getID().startswith(":")]
            via = nxt_internal[0].getToLane().getID() if nxt_internal else ""
        lane = conn.getToLane()
        ids.append(lane.getID())
    return ids


def route_shape(net: NetLike, edges: Sequence[str], lane_index: int) -> tuple[np.ndarray, float]:
    """Concatenated centreline of the lanes of :func:`route_lanes`.

    Returns
    -------
    xy : ndarray, shape (n, 2)
        All lane shape points in order (duplicates kept; :func:`clean_polyline` drops
        them) [m].
    sumo_length : float
        Sum of the SUMO lane lengths, internal lanes included (each at least 0.1 m) [m].

    Raises
    ------
    ValueError
        If consecutive lane shapes are more than 0.05 m apart.
    """
    net = load_net(net)
    pts: list[tuple[float, float]] = []
    total = 0.0
    for lane_id in route_lanes(net, edges, lane_index):
        lane = net.getLane(lane_id)
        shape = [tuple(p[:2]) for p in lane.getShape()]
        if pts and math.dist(pts[-1], shape[0]) > _GAP_TOL:
            raise ValueError(f"gap of {math.dist(pts[-1], shape[0]):.3f} m before lane "
                             f"{lane_id!r}")
        pts.extend(shape)
        total += lane.getLength()
    return np.asarray(pts, dtype=float), total


def reference_line_from_net(net: NetLike, edges: Sequence[str], lane_index: int,
                            fit: LineFit = LINE_FIT_DEFAULT) -> ReferenceLine:
    """Reference line along one lane of a SUMO route.

    Parameters
    ----------
    net : str, PathLike or sumolib.net.Net
        The network (see :func:`load_net`).
    edges : sequence of str
        Route edge ids in driving order, e.g. ``["entry", "main"]``.
    lane_index : int
        Lane index on the first edge (0 = rightmost); followed through the connections.
    fit : LineFit
        Smoothing settings.

    Notes
    -----
    s = 0 is the start of the lane on ``edges[0]``. The line's length is the geometric
    length; SUMO counts zero-length internal lanes as 0.1 m, so SUMO's route length can
    exceed it by 0.1 m per such joint.
    """
    xy, _ = route_shape(net, edges, lane_index)
    return ReferenceLine.from_points(xy, fit)


def lane_offsets(net: NetLike, edge_id: str, ref_lane_index: int) -> np.ndarray:
    """Signed lateral offset of every lane centre of an edge from a reference lane centre.

    The offset of lane k is the distance between the centrelines, left positive:
    ``+(w_ref/2 + sum of the widths in between + w_k/2)`` for k > ref (SUMO numbers lanes
    from the right) and the negative for k < ref. With 3.5 m lanes and ref = 1 this is
    (-3.5, 0, 3.5). Use it as the lateral offset dy of a formation slot on lane k.

    Parameters
    ----------
    net : str, PathLike or sumolib.net.Net
        The network (see :func:`load_net`).
    edge_id : str
        Edge id.
    ref_lane_index : int
        Index of the reference lane on that edge.

    Returns
    -------
    ndarray, shape (n_lanes,)
        Offset of lane k at index k [m].
    """
    edge = load_net(net).getEdge(edge_id)
    widths = np.array([ln.getWidth() for ln in edge.getLanes()], dtype=float)
    if not 0 <= ref_lane_index < len(widths):
        raise ValueError(f"ref_lane_index {ref_lane_index} not on edge {edge_id!r} "
                         f"({len(widths)} lanes)")
    centre = np.cumsum(widths) - 0.5 * widths  # from the right border, growing to the left
    return centre - centre[ref_lane_index]
