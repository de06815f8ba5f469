"""SUMO's own cost of members placed by moveToXY instead of driven by SUMO (docs/sumo.md).

Same network, traffic and seed as benchmarks/overhead.py's twin. The five members depart as SUMO
vehicles; with ``move`` they are then placed every step by ``moveToXY`` at a constant 30 m/s in
their lanes (where SUMO drives them too), so only the placing differs. Prints the wall time of
``simulationStep`` alone.

    python benchmarks/moved_members.py 200 drive
    python benchmarks/moved_members.py 200 move
    python benchmarks/moved_members.py 200 move --edge-m 120000   # one 120 km edge
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
    ap.add_argument("mode", choices=["drive", "move"])
    ap.add_argument("--edge-m", type=float, default=1000.0)
    a = ap.parse_args()
    os.environ["BENCH_EDGE_M"] = str(a.edge_m)
    import overhead as ob  # noqa: E402  (reads BENCH_EDGE_M)
    import libsumo as api
    from formation_traci.scenario import parse_scenario
    from formation_traci.sim.sumo_plan import sumo_args

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
    if a.mode == "move":
        for vid in ids:
            api.vehicle.setSpeedMode(vid, 0)
            api.vehicle.setLaneChangeMode(vid, 0)
    t_step = 0.0
    for k in range(k0 + 1, int(round(a.duration / dt))):
        if a.mode == "move":
            for vid in ids:
                api.vehicle.moveToXY(vid, "", -1, x0[vid] + ob.SPEED * dt * k, y0[vid], 90.0, 1, 5.0)
        c = time.perf_counter()
        api.simulationStep()
        t_step += time.perf_counter() - c
        if a.mode == "move":
            for vid in ids:
                api.vehicle.setPreviousSpeed(vid, ob.SPEED, 0.0)
    print(json.dumps({"mode": a.mode, "edge_m": a.edge_m, "sumo_step_s": round(t_step, 2),
                      "vehicles": api.vehicle.getIDCount()}))
    api.close()


if __name__ == "__main__":
    main()
