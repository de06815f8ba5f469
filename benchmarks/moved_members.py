"""SUMO's own cost of members placed by moveToXY instead of driven by SUMO (docs/sumo.md).

Same network, traffic and seed as benchmarks/overhead.py's twin. The five members depart as SUMO
vehicles; with ``move`` they are then placed every step by ``moveToXY`` at a constant 30 m/s in
their lanes (where SUMO drives them too), so only the placing differs; like a run's members,
each carries its route only to the end of the next edge. Prints the wall time of
``simulationStep`` alone.

    python benchmarks/moved_members.py 200 drive
    python benchmarks/moved_members.py 200 move
    python benchmarks/moved_members.py 200 move --edge-m 120000   # one 120 km edge
    python benchmarks/moved_members.py 120 floor --no-ssm

``floor`` is the least libsumo traffic a formation run through libsumo has per step, with no
control law and no recording: the members placed as with ``move`` (five ``moveToXY`` and five
``setPreviousSpeed``), subscribed as a formation run subscribes them (each member's pose and
lane; the neighbours within the record radius, 300 m, by one context subscription), both read
every step, and the event lists a run checks (collisions, teleports, arrivals, departures).
Besides SUMO's step it prints the wall time of the whole loop: ``floor`` against ``drive`` is
the smallest formation / twin ratio a formation layer built on libsumo's per-vehicle calls can
reach (issue 18's overhead target).
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("duration", type=float)
    ap.add_argument("mode", choices=["drive", "move", "floor"])
    ap.add_argument("--no-ssm", action="store_true", help="SUMO's SSM device off (BENCH_SSM=off)")
    ap.add_argument("--edge-m", type=float, default=1000.0)
    a = ap.parse_args()
    os.environ["BENCH_EDGE_M"] = str(a.edge_m)
    if a.no_ssm:
        os.environ["BENCH_SSM"] = "off"
    import overhead as ob  # noqa: E402  (reads BENCH_EDGE_M)
    import libsumo as api
    from formation_traci.scenario import parse_scenario
    from formation_traci.sumo.plan import sumo_args

    sc = parse_scenario(ob.scenario(5, a.duration, None, 1), "moved_members")
    out = Path(tempfile.mkdtemp(prefix="moved_"))
    routes = ob.twin_routes(sc, out, a.duration, 5)
    members = ob.formation_slots(5)
    api.start(["sumo"] + sumo_args(sc, ob.long_net(), routes, out, a.duration + 1))
    ids = [m["id"] for m in members]
    while not all(vid in api.vehicle.getIDList() for vid in ids):
        api.simulationStep()
    dt = sc.run.step
    k0 = int(round(api.simulation.getTime() / dt))
    x0 = {vid: api.vehicle.getPosition(vid)[0] - ob.SPEED * dt * k0 for vid in ids}
    y0 = {vid: api.vehicle.getPosition(vid)[1] for vid in ids}
    moved = a.mode != "drive"
    if moved:
        for vid in ids:
            api.vehicle.setSpeedMode(vid, 0)
            api.vehicle.setLaneChangeMode(vid, 0)
    if a.mode == "floor":
        subscribe_as_a_run(api, ids)
    t_step = 0.0
    edges, window = ob.route_edges(), {}
    t_loop = time.perf_counter()
    for k in range(k0 + 1, int(round(a.duration / dt))):
        if moved:
            advance_route_windows(api, ids, edges, ob.edge_m(), window,
                                  {v: x0[v] + ob.SPEED * dt * k for v in ids})
            for vid in ids:
                api.vehicle.moveToXY(vid, "", -1, x0[vid] + ob.SPEED * dt * k, y0[vid], 90.0, 1, 5.0)
        c = time.perf_counter()
        api.simulationStep()
        t_step += time.perf_counter() - c
        if moved:
            for vid in ids:
                api.vehicle.setPreviousSpeed(vid, ob.SPEED, 0.0)
        if a.mode == "floor":
            read_as_a_run(api)
    t_loop = time.perf_counter() - t_loop
    print(json.dumps({"mode": a.mode, "edge_m": a.edge_m, "sumo_step_s": round(t_step, 2),
                      "loop_s": round(t_loop, 2), "vehicles": api.vehicle.getIDCount()}))
    api.close()


def advance_route_windows(api, ids, edges, edge_m, window, x_front) -> None:
    """Each placed member carries its route only to the end of the next edge, as a run's
    members do (sumo/adapter.py ``_advance_route_window``): ``moveToXY`` with keepRoute = 1
    measures its distance to every lane of the route, ~100 us per call on the whole 120-edge
    route. ``edge_m``: length of an edge [m]; ``x_front``: each member's front bumper x [m]."""
    from libsumo import TraCIException

    for vid in ids:
        i = min(int(x_front[vid] // edge_m), len(edges) - 1)
        if window.get(vid) != i:
            try:
                api.vehicle.setRoute(vid, edges[i:i + 2])
                window[vid] = i
            except TraCIException:
                pass  # on the junction between two edges: the next step tries again


RECORD_RADIUS_M = 300.0


def subscribe_as_a_run(api, ids) -> None:
    """The subscriptions of a formation run (sumo/adapter.py, sumo/neighbours.py)."""
    from libsumo import constants as tc

    for vid in ids:
        api.vehicle.subscribe(vid, [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LANE_ID, tc.VAR_LANE_INDEX,
                                    tc.VAR_LANEPOSITION, tc.VAR_LANEPOSITION_LAT])
    api.vehicle.subscribeContext(ids[len(ids) // 2], tc.CMD_GET_VEHICLE_VARIABLE, RECORD_RADIUS_M,
                                 [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_ACCELERATION,
                                  tc.VAR_LANE_ID, tc.VAR_LANE_INDEX])


def read_as_a_run(api) -> None:
    """The reads a formation run makes every step: both subscriptions and the event lists."""
    api.vehicle.getAllSubscriptionResults()
    api.vehicle.getAllContextSubscriptionResults()
    sim = api.simulation
    sim.getCollisions(), sim.getStartingTeleportIDList(), sim.getArrivedIDList(), sim.getDepartedIDList()


if __name__ == "__main__":
    main()
