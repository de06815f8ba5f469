"""Lanes as SUMO has them: the geometric lane a vehicle keeps, lane centres from SUMO's shapes.

Real (OSM-derived) networks do not always connect lanes the way they lie: at the LuST
motorway's on-ramps the four-lane merge edge connects lanes 1 -> 1 and 2 -> 1 into the
three-lane edge while its lane 1 geometrically continues as lane 0 and lane 2 as lane 1
(docs/sumo.md, "Real networks"). Here a lane is followed by its geometry:

* :func:`geometric_route_lanes`: at each joint the next lane is the lane of the next edge
  whose start lies across from the end of the current one (within half a lane width); the
  connection SUMO's routing would choose is used only where it leads there (its internal
  lanes are then kept) or where no lane lies across (a lane that ends);
* :func:`lane_centre_offsets`: each lane's centre offset from the reference line, measured
  on SUMO's lane shapes (so lane widths, gaps between lanes and shape offsets are SUMO's);
* :class:`LaneShapes`: SUMO's (lane, position, lateral offset) -> x, y, to check where SUMO
  has a vehicle;
* :class:`LaneCentres`: the lane mapping everything lane-based uses (initial slots, maneuver
  lane shifts, reshape goals and entries given in lanes, in-lane tests): per route edge the
  measured lane centres, looked up at an arc length along the reference line (pure numpy).

Only sumolib is used (never libsumo or traci).
"""
from __future__ import annotations

import math
from bisect import bisect_right
from typing import Sequence

import numpy as np

JOINT_REACH = 30.0
"""The next lane's start must lie within this distance ahead of the current lane's end [m]."""


def _end_frame(shape) -> tuple[np.ndarray, np.ndarray]:
    """End point [m] and unit direction of a lane shape's last segment."""
    pts = np.asarray([p[:2] for p in shape], dtype=float)
    for k in range(len(pts) - 1, 0, -1):
        d = pts[k] - pts[k - 1]
        n = math.hypot(*d)
        if n > 1e-6:
            return pts[-1], d / n
    return pts[-1], np.array([1.0, 0.0])


def geometric_successor(lane, next_edge):
    """The lane of ``next_edge`` that starts across from the end of ``lane`` (within half its
    width, at most :data:`JOINT_REACH` ahead), or None."""
    end, t = _end_frame(lane.getShape())
    n = np.array([-t[1], t[0]])
    best, best_lat = None, math.inf
    for cand in next_edge.getLanes():
        start = np.asarray(cand.getShape()[0][:2], dtype=float)
        dx, dy = float(start[0] - end[0]), float(start[1] - end[1])  # no BLAS dot
        along, lat = dx * t[0] + dy * t[1], abs(dx * n[0] + dy * n[1])
        if -2.0 <= along <= JOINT_REACH and lat < best_lat:
            best, best_lat = cand, lat
    if best is None or best_lat > 0.5 * min(lane.getWidth(), best.getWidth()):
        return None
    return best


def _via_lanes(net, conn) -> list[str]:
    ids, via = [], conn.getViaLaneID()
    while via:  # internal lanes, possibly split at internal junctions
        ids.append(via)
        nxt = [c for c in net.getLane(via).getOutgoing() if c.getToLane().getID().startswith(":")]
        via = nxt[0].getToLane().getID() if nxt else ""
    return ids


class LaneBreak(ValueError):
    """A lane that neither continues nor connects into the next edge: ``edges`` = (edge, next)."""

    def __init__(self, message: str, edges: tuple[str, str]):
        super().__init__(message)
        self.edges = edges


def geometric_route_lanes(net, edges: Sequence[str], lane_index: int) -> list[str]:
    """Lane ids along a route keeping the geometric lane (internal lanes where the connection
    leads to it). Raises :class:`LaneBreak` where a lane neither continues nor connects."""
    first = net.getEdge(edges[0])
    if not 0 <= lane_index < first.getLaneNumber():
        raise ValueError(f"lane_index {lane_index} not on edge {edges[0]!r} ({first.getLaneNumber()} lanes)")
    lane = first.getLane(lane_index)
    ids = [lane.getID()]
    for nxt in edges[1:]:
        geo = geometric_successor(lane, net.getEdge(nxt))
        conns = [c for c in lane.getOutgoing() if c.getTo().getID() == nxt]
        to_geo = [c for c in conns if geo is not None and c.getToLane().getID() == geo.getID()]
        if to_geo:
            ids += _via_lanes(net, to_geo[0])
        elif geo is None:
            if not conns:
                raise LaneBreak(f"lane {lane.getID()!r} has no connection to edge {nxt!r}",
                                (lane.getEdge().getID(), nxt))
            end = lane.getShape()[-1]
            conn = min(conns, key=lambda c: math.dist(end, c.getToLane().getShape()[0]))
            ids += _via_lanes(net, conn)
            geo = conn.getToLane()
        lane = geo
        ids.append(lane.getID())
    return ids


def sideways_internal_lanes(net, edges: Sequence[str]) -> list[str]:
    """Internal lanes of the route's joints whose connection leads a lane that continues
    geometrically into another lane (e.g. LuST on-ramps: 1 -> 1 where lane 1 runs on as lane 0).
    Members are kept off them so SUMO never sees two side-by-side members merging into one lane.

    Only where another connection of the joint leads into that geometric lane (LuST: the ramp's
    0 -> 0), so a member crossing the junction always has an internal lane it may use where it
    geometrically is (``moveToXY`` maps it there; docs/sumo.md, "Members on junctions")."""
    out = []
    for a, b in zip(edges, edges[1:]):
        nxt = net.getEdge(b)
        into = {c.getToLane().getID(): c for lane in net.getEdge(a).getLanes()
                for c in lane.getOutgoing() if c.getTo().getID() == b}
        for lane in net.getEdge(a).getLanes():
            geo = geometric_successor(lane, nxt)
            if geo is None or geo.getID() not in into:
                continue
            for c in lane.getOutgoing():
                if c.getTo().getID() == b and c.getToLane().getID() != geo.getID():
                    out += _via_lanes(net, c)
    return sorted(set(out))


def geometric_route_shape(net, edges: Sequence[str], lane_index: int) -> np.ndarray:
    """Concatenated SUMO shapes of :func:`geometric_route_lanes` (n, 2) [m]; where the line
    leaves SUMO's connection it joins the two lanes' ends straight across the junction."""
    pts = []
    for lane_id in geometric_route_lanes(net, edges, lane_index):
        pts.extend(tuple(p[:2]) for p in net.getLane(lane_id).getShape())
    return np.asarray(pts, dtype=float)


def lane_centre_offsets(net, edge_id: str, line) -> np.ndarray:
    """Offset of every lane centre of an edge from the reference line [m], left positive:
    the median over the lane's SUMO shape points (and segment midpoints) projected on the line."""
    out = []
    for lane in net.getEdge(edge_id).getLanes():
        p = np.asarray([q[:2] for q in lane.getShape()], dtype=float)
        pts = np.concatenate([p, 0.5 * (p[1:] + p[:-1])])
        _, d = line.to_frenet(pts)
        out.append(float(np.median(d)))
    return np.asarray(out)


class LaneShapes:
    """SUMO lane shapes of a network, to turn SUMO's (lane, lane position, lateral offset) into
    x, y [m]. SUMO's lane position runs over the lane's nominal length; it is scaled to the
    shape's geometric length as SUMO does."""

    def __init__(self, net):
        self._net = net
        self._cache: dict[str, tuple[list, list, list, float]] = {}

    def _lane(self, lane_id: str):
        """The lane's shape points (as lists of floats x, y [m]), their cumulative length
        along the shape [m] and the scale from SUMO's lane position to that length."""
        got = self._cache.get(lane_id)
        if got is None:
            lane = self._net.getLane(lane_id)
            pts = np.asarray([p[:2] for p in lane.getShape()], dtype=float)
            cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
            scale = cum[-1] / lane.getLength() if lane.getLength() > 0 else 1.0
            got = self._cache[lane_id] = (pts[:, 0].tolist(), pts[:, 1].tolist(), cum.tolist(),
                                          float(scale))
        return got

    def shape(self, lane_id: str) -> tuple[list, list, list, float]:
        """The lane's shape points x, y [m], their length along the shape [m] (lists of
        floats) and the scale from SUMO's lane position to that length."""
        return self._lane(lane_id)

    def xy(self, lane_id: str, pos: float, lat: float) -> tuple[float, float]:
        """Point at lane position ``pos`` [m] and ``lat`` [m] left of the lane's centre line.
        (Python floats: called per member and step; the arithmetic of the numpy form, bit
        for bit, tests/test_fast_paths.py.)"""
        px, py, cum, scale = self._lane(lane_id)
        pos, lat = float(pos), float(lat)
        g = min(max(pos * scale, 0.0), cum[-1])
        k = min(max(bisect_right(cum, g) - 1, 0), len(px) - 2)
        sx, sy = px[k + 1] - px[k], py[k + 1] - py[k]
        length = math.hypot(sx, sy) or 1.0
        tx, ty = sx / length, sy / length
        along = g - cum[k]
        x, y = px[k] + tx * along, py[k] + ty * along
        return x - lat * ty, y + lat * tx


class LaneCentres:
    """Lane centres along a route as SUMO has them (or uniform lanes without a network).

    Per route edge, in driving order: the arc length where it starts on the reference line
    ``s0`` [m], the offset of each lane centre from the reference line ``offsets`` [m], left
    positive (:func:`lane_centre_offsets`), and the index of the reference lane on it ``ref``
    (the geometric lane, :func:`geometric_route_lanes`). At an arc length s the edge is the
    last one starting at or before s (the first before the route starts). Lanes beyond an
    edge's outermost lane continue ``lane_width`` [m] apart.

    A slot ``k`` lanes left of the reference lane lies at ``centre(r + k) - centre(r)`` on the
    edge where it is (:meth:`across`: on the first edge for the initial slots, 0 for
    the reference lane itself), so lane-based offsets share the reference line's frame.
    """

    def __init__(self, s0, offsets, ref, lane_width: float):
        self.s0 = np.asarray(s0, dtype=float)
        self.lane_width = float(lane_width)
        m = max(len(o) for o in offsets)
        self.n = np.array([len(o) for o in offsets])
        self.table = np.full((len(offsets), m), np.inf)  # padded: no lane there
        for e, o in enumerate(offsets):
            self.table[e, :len(o)] = o
        self.ref = np.asarray(ref, dtype=int)

    @classmethod
    def uniform(cls, lane_width: float, lanes: int = 41) -> "LaneCentres":
        """Lanes ``lane_width`` [m] apart everywhere, the reference lane at offset 0."""
        k = np.arange(lanes) - lanes // 2
        return cls([-np.inf], [k * float(lane_width)], [lanes // 2], lane_width)

    def edge_at(self, s):
        """Index of the route edge at arc length(s) s [m] (array or scalar)."""
        return np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, len(self.s0) - 1)

    def centre(self, e, k):
        """Offset [m] of lane k (SUMO's index; extrapolated beyond the edge's lanes) of edge e."""
        e, k = np.asarray(e), np.asarray(k)
        last = self.n[e] - 1
        inside = self.table[e, np.clip(k, 0, last)]
        return np.where(k < 0, self.table[e, 0] + k * self.lane_width,
                        np.where(k > last, inside + (k - last) * self.lane_width, inside))

    def lane(self, s, d):
        """(edge, lane) indices of the lane whose centre is nearest to lateral offset d [m] at
        arc length s [m]; s and d broadcast."""
        s, d = np.broadcast_arrays(np.asarray(s, float), np.asarray(d, float))
        e = self.edge_at(s)
        return e, np.argmin(np.abs(self.table[e] - d[..., None]), axis=-1)

    def across(self, lanes, s):
        """Lateral offset [m] of the slot ``lanes`` lanes left of the reference lane at arc
        length s [m] (module docstring of this class)."""
        e = self.edge_at(s)
        r = self.ref[e]
        return self.centre(e, r + np.asarray(lanes)) - self.centre(e, r)

    def shift(self, s, d, lanes):
        """Lateral offset [m] after moving ``lanes`` lanes to the left from d [m] at arc
        length s [m]: from the centre of d's lane to the centre of the target lane, keeping
        d's place within its lane."""
        e, k = self.lane(s, d)
        return d + self.centre(e, k + np.asarray(lanes)) - self.centre(e, k)

    def same_lane(self, s, d, d_ref):
        """Is each offset d [m] in the lane of d_ref [m] (nearest lane centres at arc length s)?"""
        return self.lane(s, d)[1] == self.lane(s, d_ref)[1]

    def off_centre(self, s, d):
        """Distance [m] of each offset d from its nearest lane centre at arc length s [m]."""
        e, k = self.lane(s, d)
        return np.abs(np.asarray(d, float) - self.table[e, k])
