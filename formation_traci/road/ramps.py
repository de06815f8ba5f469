"""On-ramps along a route, read from the network: where ramp traffic joins the lanes a
formation drives on, and the lanes it comes from.

A route edge's lane is *ramp-fed* when every lane leading into it (through the junction's
internal lanes) comes from an edge off the route. Two kinds of join follow:

* **an acceleration lane**: a ramp-fed lane that does not run on as a lane of its own (its
  geometric successor, :func:`~.lanes.geometric_successor`, is none, or is also where a through
  lane runs on; SUMO's bundled ``onramp`` network and the LuST motorway's on-ramps). The ramp
  traffic moves from it into the through lane beside it, on the road's side (the *merge lane*),
  anywhere along its length, and must have moved by its end;
* **a direct join**: a lane fed both from the route and from a ramp (a priority or zipper
  merge at the junction); the merge lane is that lane and the acceleration length 0.

A ramp-fed lane that runs on as a lane of its own (a lane gain) needs no merge and is not listed.
The lanes upstream of a join that carry its ramp traffic (the ramp's lanes and the junction's
internal lanes, up to ``horizon_m``) are its *feeders*: a vehicle at lane position p [m] on a
feeder is ``distance - p`` [m] from the start of the join.

Only sumolib is used (never libsumo or traci).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from .lanes import geometric_successor

HORIZON_M = 600.0
"""How far upstream of a join its feeder lanes are collected [m]."""


@dataclass(frozen=True, slots=True)
class RampJoin:
    """Where ramp traffic joins a route (module docstring)."""

    edge_index: int  # the route edge where the join starts (its index in the route) [-]
    added_lane: str  # the acceleration lane's id ("" for a direct join)
    merge_lane: str  # the through lane's id the ramp traffic moves into
    merge_index: int  # its index on the join's edge (SUMO's, 0 rightmost) [-]
    merge_width_m: float  # its width [m]
    length_m: float  # the acceleration lane's length, over several edges if it spans them [m]
    feeders: tuple[tuple[str, float], ...]  # (lane id, its start's distance to the join [m])
    left_merges: bool = False  # the through lane left of the merge lane runs into a lane it also
    # runs into (SUMO's connections): the two merge at the join's end, a shift left gains nothing


def _origin(lane) -> str:
    """The id of the normal edge ``lane`` is fed from (itself for a normal lane; internal
    lanes are followed upstream)."""
    seen = 0
    while lane.getEdge().getFunction() == "internal" and seen < 8:
        inc = lane.getIncoming()
        if not inc:
            break
        lane, seen = inc[0], seen + 1
    return lane.getEdge().getID()


def _sources(lane) -> set[str]:
    """The normal edges feeding ``lane``."""
    return {_origin(i) for i in lane.getIncoming()}


def _feeders(lane, route: set[str], horizon_m: float) -> tuple[tuple[str, float], ...]:
    """Lanes off the route upstream of ``lane`` within ``horizon_m``, each with the distance from
    its start to ``lane``'s start [m]."""
    out, todo, seen = [], [(i, 0.0) for i in lane.getIncoming()], set()
    while todo:
        cand, below = todo.pop()
        if cand.getID() in seen or _origin(cand) in route:
            continue
        seen.add(cand.getID())
        dist = below + cand.getLength()
        out.append((cand.getID(), dist))
        if dist < horizon_m:
            todo += [(i, dist) for i in cand.getIncoming()]
    return tuple(sorted(out))


def _runs_on(lane, nxt, through) -> bool:
    """Does ``lane`` run on into ``nxt`` as a lane no through lane runs on as?"""
    geo = geometric_successor(lane, nxt)
    if geo is None:
        return False
    return all(geometric_successor(t, nxt) is not geo for t in through)


def _accel_length(net, edges: Sequence[str], k: int, lane) -> float:
    """Length of the acceleration lane starting at ``lane`` on route edge k, following it over
    the next edges while it runs on beside the through lanes [m]."""
    total = lane.getLength()
    for nxt_id in edges[k + 1:]:
        nxt = net.getEdge(nxt_id)
        through = [t for t in lane.getEdge().getLanes() if t is not lane]
        if not _runs_on(lane, nxt, through):
            break
        lane = geometric_successor(lane, nxt)
        total += lane.getLength()
    return total


def _left_merges(merge, through: list, nxt) -> bool:
    """Do the merge lane and the through lane left of it run into one lane of the next route
    edge ``nxt`` (SUMO's connections; LuST's on-ramps: the acceleration lane runs on and the two
    lanes beside it become one)?"""
    left = {t.getIndex(): t for t in through}.get(merge.getIndex() + 1)
    if left is None or nxt is None:
        return False
    into = [{c.getToLane().getID() for c in ln.getOutgoing() if c.getToLane().getEdge() is nxt}
            for ln in (merge, left)]
    return bool(into[0] & into[1])


def _merge_lane(lane, through: list):
    """The through lane beside ``lane`` on the road's side (the next index up, else down)."""
    by_index = {t.getIndex(): t for t in through}
    i = lane.getIndex()
    return by_index.get(i + 1) or by_index.get(i - 1)


def ramp_joins(net, edges: Sequence[str], horizon_m: float = HORIZON_M) -> list[RampJoin]:
    """Every join of ramp traffic along the route ``edges`` (ids in driving order), in order.

    ``net``: a sumolib network read with its internal lanes (``withInternal=True``)."""
    route, out = set(edges), []
    for k in range(1, len(edges)):
        edge, prev = net.getEdge(edges[k]), edges[k - 1]
        fed = {lane.getID(): _sources(lane) for lane in edge.getLanes()}
        through = [lane for lane in edge.getLanes() if prev in fed[lane.getID()]]
        if not through:
            continue
        nxt = net.getEdge(edges[k + 1]) if k + 1 < len(edges) else None
        for lane in edge.getLanes():
            src = fed[lane.getID()]
            off_route = src - route
            if not off_route:
                continue
            if prev in src:  # a direct join into a through lane
                out.append(RampJoin(k, "", lane.getID(), lane.getIndex(), lane.getWidth(), 0.0,
                                    _feeders(lane, route, horizon_m)))
            elif nxt is None or not _runs_on(lane, nxt, through):
                merge = _merge_lane(lane, through)
                if merge is not None:
                    out.append(RampJoin(k, lane.getID(), merge.getID(), merge.getIndex(), merge.getWidth(),
                                        _accel_length(net, edges, k, lane),
                                        _feeders(lane, route, horizon_m),
                                        _left_merges(merge, through, nxt)))
    return out
