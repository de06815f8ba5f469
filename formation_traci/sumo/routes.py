"""Routes of a scenario resolved and checked against the network before SUMO starts.

A route is either a list of edge ids in driving order, or its two ends (``{ from = ..., to =
... }``, each an edge id or an ``[x, y]`` network position [m], optionally through ``via``
points) joined along the mainline: the shortest path (length, passenger cars) over
edges of the start edge's road class (its SUMO type and priority; the last edge may be of
another class), so a motorway route never leaves at an off-ramp and re-enters at the next
on-ramp because that is shorter. Only where no such path exists, or the reference lane cannot
follow it, sumolib's shortest path over any edge is taken; where the lane follows neither,
the problem names the path chosen and its first edge pair without a lane connection. Every
route is checked link by link: an edge that is not in the network, or two consecutive edges
without a connection, is a problem naming the scenario field and the missing edge or link.
"""
from __future__ import annotations

import heapq

from ..road.lanes import LaneBreak, geometric_route_lanes
from ..scenario.schema import RouteEnds

SNAP_RADIUS = 50.0
"""An ``[x, y]`` route end is snapped to the nearest non-internal edge within this distance [m]."""


def _end_edge(net, end, field: str, which: str):
    """Edge of one route end (edge id or [x, y]); (edge, problem)."""
    if isinstance(end, str):
        if not net.hasEdge(end):
            return None, (field, f"{which} edge {end!r} is not in the network")
        return net.getEdge(end), None
    x, y = end
    near = [(d, e) for e, d in net.getNeighboringEdges(x, y, SNAP_RADIUS) if e.getFunction() != "internal"]
    if not near:
        return None, (field, f"no edge within {SNAP_RADIUS:.0f} m of the {which} position ({x}, {y})")
    return min(near, key=lambda t: (t[0], t[1].getID()))[1], None


def _road_class(edge) -> tuple[str, int]:
    return edge.getType(), edge.getPriority()


def mainline_path(a, b) -> list | None:
    """Shortest path (length [m]) from edge a to edge b over edges of a's road class (SUMO
    type and priority; b may differ) that passenger cars may use; ties go by edge id. None if
    there is none."""
    cls = _road_class(a)
    best = {a.getID(): 0.0}
    prev = {}
    heap = [(0.0, a.getID(), a)]
    while heap:
        cost, eid, e = heapq.heappop(heap)
        if e is b:
            path = [e]
            while path[-1].getID() in prev:
                path.append(prev[path[-1].getID()])
            return path[::-1]
        if cost > best[eid]:
            continue
        for nxt in sorted(e.getOutgoing(), key=lambda x: x.getID()):
            if not nxt.allows("passenger") or (nxt is not b and _road_class(nxt) != cls):
                continue
            c = cost + nxt.getLength()
            if c < best.get(nxt.getID(), float("inf")):
                best[nxt.getID()], prev[nxt.getID()] = c, e
                heapq.heappush(heap, (c, nxt.getID(), nxt))
    return None


def _segment(net, a, b) -> list[list]:
    """Candidate paths from a to b, the mainline first."""
    main = mainline_path(a, b)
    short, _ = net.getShortestPath(a, b, vClass="passenger")
    out = [p for p in (main, list(short) if short else None) if p]
    return [p for i, p in enumerate(out) if p not in out[:i]]


def _lane_break(net, edges: list[str], lane: int | None):
    """The (edge, next edge) where lane ``lane`` of the first edge cannot be followed, or None."""
    if lane is None or lane >= net.getEdge(edges[0]).getLaneNumber():
        return None  # no reference lane (a flow), or one the road set-up reports itself
    try:
        geometric_route_lanes(net, edges, lane)
    except LaneBreak as exc:
        return exc.edges
    return None


def _by_ends(net, spec: RouteEnds, field: str, lane: int | None):
    ends, problems = [], []
    for which, end in (("from", spec.from_), *((f"via {i}", v) for i, v in enumerate(spec.via)),
                       ("to", spec.to)):
        e, p = _end_edge(net, end, field, which)
        ends.append(e)
        problems += [p] if p else []
    if problems:
        return None, problems
    paths = [[ends[0]]]
    for a, b in zip(ends, ends[1:]):
        seg = _segment(net, a, b)
        if not seg:
            return None, [(field, f"no path from edge {a.getID()!r} to edge {b.getID()!r} in the network")]
        paths = [p + s[1:] for p in paths for s in seg]
    routes = [[e.getID() for e in p] for p in paths]
    for edges in routes:
        if _lane_break(net, edges, lane) is None:
            return edges, []
    x, y = _lane_break(net, routes[0], lane)
    return None, [(field, f"lane {lane} of edge {routes[0][0]!r} cannot follow the path chosen from "
                          f"{routes[0][0]!r} to {routes[0][-1]!r} ({' -> '.join(routes[0])}): no lane "
                          f"connection from edge {x!r} to edge {y!r} (give the edges, or via points)")]


def resolve_route(net, spec, field: str, lane: int | None = None) -> tuple[list[str] | None, list[tuple[str, str]]]:
    """Edge ids of a route given as a list or by its ends, and the problems found.

    Parameters
    ----------
    net : sumolib.net.Net
        The network.
    spec : list of str or RouteEnds
        The scenario's route value.
    field : str
        Dotted scenario field, used in the problems.
    lane : int, optional
        The reference lane on the first edge (road.route): a route by its ends is one this
        lane can follow (road/lanes.py); None for a flow's route.

    Returns
    -------
    edges, problems
        ``edges`` is None when the route cannot be resolved; ``problems`` are (field, message).
    """
    if isinstance(spec, RouteEnds):
        return _by_ends(net, spec, field, lane)
    return list(spec), check_route(net, list(spec), field)


def check_route(net, edges: list[str], field: str) -> list[tuple[str, str]]:
    """Problems of an edge list: unknown edges, consecutive edges without a connection."""
    missing = [e for e in edges if not net.hasEdge(e)]
    if missing:
        return [(field, f"edges not in the network: {missing}")]
    problems = []
    for a, b in zip(edges, edges[1:]):
        if b not in {e.getID() for e in net.getEdge(a).getOutgoing()}:
            problems.append((field, f"no connection from edge {a!r} to edge {b!r} (missing link {a} -> {b})"))
    return problems
