"""Routes of a scenario resolved and checked against the network before SUMO starts.

A route is either a list of edge ids in driving order, or its two ends (``{ from = ..., to =
... }``, each an edge id or an ``[x, y]`` network position [m]) joined by sumolib's shortest
path (travel time, passenger cars). Every route is checked link by link: an edge that is not
in the network, or two consecutive edges without a connection, is a problem naming the
scenario field and the missing edge or link.
"""
from __future__ import annotations

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


def resolve_route(net, spec, field: str) -> tuple[list[str] | None, list[tuple[str, str]]]:
    """Edge ids of a route given as a list or by its ends, and the problems found.

    Parameters
    ----------
    net : sumolib.net.Net
        The network.
    spec : list of str or RouteEnds
        The scenario's route value.
    field : str
        Dotted scenario field, used in the problems.

    Returns
    -------
    edges, problems
        ``edges`` is None when the route cannot be resolved; ``problems`` are (field, message).
    """
    if isinstance(spec, RouteEnds):
        a, pa = _end_edge(net, spec.from_, field, "from")
        b, pb = _end_edge(net, spec.to, field, "to")
        problems = [p for p in (pa, pb) if p]
        if problems:
            return None, problems
        path, _ = net.getShortestPath(a, b, vClass="passenger")
        if not path:
            return None, [(field, f"no path from edge {a.getID()!r} to edge {b.getID()!r} in the network")]
        return [e.getID() for e in path], []
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
