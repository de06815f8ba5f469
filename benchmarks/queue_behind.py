"""The queue behind the formation in the benchmark's formation run and in its twin (RESULTS.md).

Prints, every 60 s, the number of vehicles within 300 m behind the rearmost member and their
mean speed: in the formation run from its recording, in the twin (overhead.py's: the members
as SUMO vehicles) from SUMO. The two runs never get the same realisation of the random
traffic, which is why overhead.py varies the seed across pairs.

    python benchmarks/queue_behind.py formation 600 --seed 1
    python benchmarks/queue_behind.py twin 600 --seed 1
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

BEHIND_M = 300.0
EVERY_S = 60.0


def line(t, lanes, n, v):
    print(f"t = {t:5.0f} s  member lanes {lanes}  behind {BEHIND_M:.0f} m: {n:3d} vehicles"
          + (f", mean {v:.1f} m/s" if n else ""))


def formation(duration: float, seed: int) -> None:
    import numpy as np
    import pandas as pd
    import overhead as ob
    from formation_traci.scenario import parse_scenario
    from formation_traci.runner import run_scenario
    out = Path(tempfile.mkdtemp(prefix="queue_")) / "run"
    run_scenario(parse_scenario(ob.scenario(5, duration, None, seed), "queue"), out, progress=False)
    tr = pd.read_parquet(out / "trajectories.parquet")
    bg = pd.read_parquet(out / "background.parquet")
    for t in np.arange(EVERY_S, duration, EVERY_S):
        m = tr[np.isclose(tr.t, t) & (tr.vehicle_id != "vc")]
        b = bg[np.isclose(bg.t, t)]
        behind = b[(b.x < m.x.min()) & (b.x > m.x.min() - BEHIND_M)]
        line(t, m.lane_index.astype(int).tolist(), len(behind), behind.v.mean())


def twin(duration: float, seed: int) -> None:
    import libsumo as api
    import overhead as ob
    from formation_traci.scenario import parse_scenario
    from formation_traci.sumo.plan import sumo_args
    sc = parse_scenario(ob.scenario(5, duration, None, seed), "queue")
    out = Path(tempfile.mkdtemp(prefix="queue_"))
    api.start(["sumo"] + sumo_args(sc, ob.long_net(), ob.twin_routes(sc, out, duration, 5), out, duration + 1))
    ids = [m["id"] for m in ob.formation_slots(5)]
    every = int(round(EVERY_S / sc.run.step))
    for k in range(1, int(round(duration / sc.run.step))):
        api.simulationStep()
        if k % every:
            continue
        x_rear = min(api.vehicle.getPosition(v)[0] for v in ids)
        speeds = [api.vehicle.getSpeed(v) for v in api.vehicle.getIDList()
                  if v not in ids and x_rear - BEHIND_M < api.vehicle.getPosition(v)[0] < x_rear]
        line(k * sc.run.step, [api.vehicle.getLaneIndex(v) for v in ids], len(speeds),
             sum(speeds) / len(speeds) if speeds else 0.0)
    api.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("kind", choices=["formation", "twin"])
    ap.add_argument("duration", type=float)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    (formation if a.kind == "formation" else twin)(a.duration, a.seed)


if __name__ == "__main__":
    main()
