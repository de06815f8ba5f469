"""``motorway100``: a straight 4-lane motorway of 100 km with an interchange every 10 km.

The long road of penetration and scale studies (PlaFoSim's reference road is a 100 km, 4-lane
motorway). Layout along +x (y = 0 is the left border of the carriageway, lanes to its right):

* mainline edges of 1 km, ``mw_<start in m>`` (``mw_0`` .. ``mw_99000``), 4 lanes, 130 km/h;
* at each interchange ``j = 1 .. 9``, x0 = 10 km * j:

  ======================  ================  =========================================
  edge                    x [m]             what it is
  ======================  ================  =========================================
  ``mw_<x0-1000>``        x0-1000 .. x0-250  4 lanes (750 m)
  ``mw_<x0-250>``         x0-250 .. x0       5 lanes, lane 0 the deceleration lane
  ``off_<j>``             x0 .. x0+400       1-lane off-ramp leaving lane 0 tangentially
  ``mw_<x0>``             x0 .. x0+1000      4 lanes
  ``on_<j>``              x0+600 .. x0+1000  1-lane on-ramp arriving tangentially
  ``mw_<x0+1000>``        x0+1000 .. x0+1300 5 lanes, lane 0 the acceleration lane
  ``mw_<x0+1300>``        x0+1300 .. x0+2000 4 lanes (700 m)
  ======================  ================  =========================================

The ramps are the cubic curves of the ``onramp`` and ``offramp`` networks (15 m from the
motorway's right border at their free end, 6.4 deg there, zero angle and curvature where they
join), so a ramp vehicle's path has no kink. ``main_route()`` needs nothing of the build
(a run reads it at start-up); the network itself is made by ``python -m sumo_nets.build``.
"""
from __future__ import annotations

LANES = 4
LENGTH_M = 100_000
EDGE_M = 1000
INTERCHANGE_EVERY_M = 10_000
DECEL_M = 250.0
ACCEL_M = 300.0
RAMP_DX_M = 400.0
RAMP_OFFSET_M = 15.0
ON_RAMP_JOIN_M = 1000.0  # where the on-ramp joins, after the interchange's start x0 [m]


def _ramp_shape(x_start: float, joining: bool) -> list[tuple[float, float]]:
    """Left border of a ramp lane over x_start .. x_start + 400 m [m]: y = -4 * 3.5 - 15 w^3,
    w = 1 - u joining (tangent at its end), w = u leaving (tangent at its start)."""
    from .build import LANE_WIDTH, SHAPE_STEP

    n = int(-(-RAMP_DX_M // SHAPE_STEP))
    pts = []
    for i in range(n + 1):
        u = i / n
        w = (1.0 - u) if joining else u
        pts.append((x_start + u * RAMP_DX_M, -LANES * LANE_WIDTH - RAMP_OFFSET_M * w ** 3))
    return pts


def _mainline_cuts() -> list[tuple[int, int]]:
    """(start x, lanes) of every mainline edge, in driving order; the last edge ends at 100 km."""
    cuts = []
    for x in range(0, LENGTH_M, EDGE_M):
        j, within = divmod(x, INTERCHANGE_EVERY_M)
        if 1 <= j and within == 0:  # the interchange's km: x0 .. x0 + 1000 stays one edge
            cuts.append((x, LANES))
        elif within == INTERCHANGE_EVERY_M - EDGE_M and x + EDGE_M < LENGTH_M:  # the km before x0
            cuts += [(x, LANES), (x + EDGE_M - int(DECEL_M), LANES + 1)]
        elif within == EDGE_M and j >= 1:  # the km after x0: the acceleration lane, then 4 lanes
            cuts += [(x, LANES + 1), (x + int(ACCEL_M), LANES)]
        else:
            cuts.append((x, LANES))
    return cuts


def _connections(a, b) -> list:
    """Through lanes of consecutive mainline edges (``build.Edge``): the right lane of a 5-lane
    edge is the deceleration lane (it leads off) or the acceleration lane (it ends)."""
    from .build import Connection

    na, nb = a.num_lanes, b.num_lanes
    if na == nb:
        return [Connection(a.id, b.id, k, k) for k in range(na)]
    if nb > na:
        return [Connection(a.id, b.id, k, k + 1) for k in range(na)]
    return [Connection(a.id, b.id, k + 1, k) for k in range(nb)]


def motorway100():
    """The network (``build.Network``) for sumo_nets/build.py."""
    from .build import RAMP_PRIORITY, RAMP_SPEED, Connection, Edge, Network, Node

    cuts = _mainline_cuts()
    ends = [x for x, _ in cuts[1:]] + [LENGTH_M]
    nodes = {0: Node("n0", 0, 0, "dead_end"), LENGTH_M: Node(f"n{LENGTH_M}", LENGTH_M, 0, "dead_end")}
    for x in ends[:-1]:
        nodes[x] = Node(f"n{x}", x, 0)
    edges = []
    for (x, n), end in zip(cuts, ends):
        accel = n > LANES and x % INTERCHANGE_EVERY_M == EDGE_M
        note = "" if n == LANES else "; lane 0 acceleration lane" if accel else "; lane 0 deceleration lane"
        edges.append(Edge(f"mw_{x}", f"n{x}", f"n{end}", n, acceleration_lanes=(0,) if accel else (),
                          comment=f"x = {x} .. {end}{note}"))
    conns = [c for a, b in zip(edges, edges[1:]) for c in _connections(a, b)]
    ramp_nodes, ramp_edges = [], []
    for j in range(1, LENGTH_M // INTERCHANGE_EVERY_M):
        x0 = j * INTERCHANGE_EVERY_M
        off = _ramp_shape(float(x0), joining=False)
        on = _ramp_shape(x0 + ON_RAMP_JOIN_M - RAMP_DX_M, joining=True)
        ramp_nodes += [Node(f"off_{j}_end", *off[-1], "dead_end"), Node(f"on_{j}_start", *on[0], "dead_end")]
        ramp_edges += [
            Edge(f"off_{j}", f"n{x0}", f"off_{j}_end", 1, speed=RAMP_SPEED, priority=RAMP_PRIORITY, shape=off,
                 comment=f"off-ramp {j}, leaves lane 0 of mw_{x0 - int(DECEL_M)} at x = {x0}"),
            Edge(f"on_{j}", f"on_{j}_start", f"n{x0 + int(ON_RAMP_JOIN_M)}", 1, speed=RAMP_SPEED,
                 priority=RAMP_PRIORITY, shape=on,
                 comment=f"on-ramp {j}, joins lane 0 of mw_{x0 + int(ON_RAMP_JOIN_M)} at x = {x0 + int(ON_RAMP_JOIN_M)}"),
        ]
        conns += [Connection(f"mw_{x0 - int(DECEL_M)}", f"off_{j}", 0, 0),
                  Connection(f"on_{j}", f"mw_{x0 + int(ON_RAMP_JOIN_M)}", 0, 0)]
    return Network(
        name="motorway100",
        description=("straight 4-lane motorway, 100 km along +x in 1 km edges, an off-ramp at every 10 km "
                     "(250 m deceleration lane) and an on-ramp 1 km after it (300 m acceleration lane)"),
        nodes=[nodes[x] for x in sorted(nodes)] + ramp_nodes,
        edges=edges + ramp_edges,
        connections=conns,
    )


def main_route() -> list[str]:
    """The mainline's edges from x = 0 to 100 km."""
    return [f"mw_{x}" for x, _ in _mainline_cuts()]
