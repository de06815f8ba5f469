"""Many formations among heavy traffic (issues 27 and 33): what our layer costs per formation
vehicle and step at 1, 5 and 20 formations of 3 members, and the 20-formation run against its
twin where SUMO drives the same 60 vehicles.

The road and traffic of benchmarks/overhead.py (a straight 120 km 3-lane motorway in 1 km
edges, the wheel's netconvert), at ``--vph`` veh/h/lane after ``--warmup`` s of SUMO alone, so
that >= 1,500 background vehicles are on the road when the formations enter: formation k is a
column of three cars 12 m apart in lane k % 3 at 600 + 300 k m, at 30 m/s; SSM off, no
measurement sections (the loop only). Each run in a fresh process (one libsumo per process);
the 20-formation run and its twin run at the same time, one per core, their loops started
together after the warm-up (as overhead.py's pairs), so that both see the machine's drift.

    python benchmarks/formations.py                    # 1, 5, 20 formations and the twin of 20
    python benchmarks/formations.py --duration 60 --warmup 600 --vph 1500   # quicker
    python benchmarks/formations.py --formations 20 --pairs 3   # the ratio only, median of 3 pairs

Per run it prints the SUMO vehicles at the end of the warm-up, the loop's wall time, SUMO's
share (run.json timing_s sumo_step) and our layer's (every other phase) per step and per
formation vehicle and step, with the run's status and incidents; the last line is
``formations ratio: X.XX`` (the 20-formation run's loop over its twin's, the median over
``--pairs``).
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import overhead as ob  # noqa: E402  (the motorway and its edges)

SPEED, SPACING, FIRST = 30.0, 300.0, 600.0  # [m/s], between formations [m], first start [m]
ALONG = (0.0, -12.0, -24.0)  # the column's slots [m]


def scenario(k: int, duration: float, warmup: float, vph: float, seed: int) -> dict:
    """k formations of three (the first top-level, the others [[formations]])."""
    def members(j):
        return [{"id": f"f{j}m{i}", "slot": {"along": a, "lanes": 0}} for i, a in enumerate(ALONG)]

    more = [{"id": f"f{j}", "start": FIRST + SPACING * j, "lane": j % 3, "leader": {"speed": SPEED},
             "members": members(j)} for j in range(1, k)]
    return {
        "name": f"formations-{k}", "run": {"duration": duration, "step": 0.05, "seed": seed},
        "road": {"net": str(ob.long_net()), "route": ob.route_edges(), "lane": 0, "start": FIRST},
        "leader": {"speed": SPEED}, "members": members(0), "formations": more,
        "traffic": {"warmup": warmup, "flows": [{"id": "main", "veh_per_hour_per_lane": vph}],
                    "sections": {"enabled": False}},
        "sumo": {"ssm": "off"},
    }


def child_formations(k, duration, warmup, vph, seed) -> dict:
    from formation_traci.scenario import parse_scenario
    from formation_traci.runner import run_scenario
    sc = parse_scenario(scenario(k, duration, warmup, vph, seed), "benchmark")
    out = Path(tempfile.mkdtemp(prefix="bench_f_"))
    counted, waited = [], []

    def count(step, t, adapter):  # SUMO's vehicles when the formations enter; --pairs: start together
        if step == 0:
            counted.append(len(adapter.api.vehicle.getIDList()))
            waited.append(ob.meet("formation.ready", "twin.ready"))

    res = run_scenario(sc, out / "run", progress=False, step_hook=count)
    timing = json.loads((out / "run" / "run.json").read_text()).get("timing_s", {})
    timing["sumo_step"] = timing.get("sumo_step", 0.0) - sum(waited)  # the wait is no work
    ob.keep_busy("formation.done", "twin.done")
    shutil.rmtree(out, ignore_errors=True)
    return {"status": res.status, "steps": res.steps_done, "vehicles": counted[0] if counted else None,
            "loop_s": sum(timing.values()), "sumo_s": timing.get("sumo_step", 0.0),
            "layer_s": sum(v for n, v in timing.items() if n != "sumo_step"),
            "incidents": res.incident_summary}


def child_twin(k, duration, warmup, vph, seed) -> dict:
    """The same traffic; the 3k vehicles as SUMO vehicles of the members' size in their lanes at
    the end of the warm-up, driven by SUMO (maxSpeed 30 m/s, no dawdling)."""
    from formation_traci.models.params import PASSENGER_CAR as car
    from formation_traci.scenario import parse_scenario
    from formation_traci.sumo.adapter import SumoAdapter
    from formation_traci.sumo.plan import sumo_args
    from formation_traci.sumo.traffic import write_routes
    sc = parse_scenario(scenario(k, duration, warmup, vph, seed), "benchmark")
    out = Path(tempfile.mkdtemp(prefix="bench_t_"))
    routes = write_routes(out / "traffic.rou.xml", [(sc.traffic.flows[0], ob.route_edges(), vph * 3)],
                          warmup + duration + 1)
    text = routes.read_text().replace("</routes>", "")
    text += (f'  <vType id="member" length="{car.length}" width="{car.width}" maxSpeed="{SPEED}" '
             f'speedFactor="1" sigma="0" minGap="2"/>\n'
             f'  <route id="member_route" edges="{" ".join(ob.route_edges())}"/>\n')
    for j in range(k):
        for i, a in enumerate(ALONG):
            pos = FIRST + SPACING * j + a + car.cog_to_front_bumper
            text += (f'  <vehicle id="f{j}m{i}" type="member" route="member_route" depart="{warmup:.2f}" '
                     f'departLane="{j % 3}" departPos="{pos:.2f}" departSpeed="{SPEED}"/>\n')
    routes.write_text(text + "</routes>\n")
    adapter = SumoAdapter("libsumo")
    adapter.start(sumo_args(sc, ob.long_net(), routes, out, warmup + 2 * duration + 1))
    for _ in range(int(round(warmup / sc.run.step))):
        adapter.simulation_step()
    vehicles = len(adapter.api.vehicle.getIDList())
    ob.meet("twin.ready", "formation.ready")
    t0 = time.perf_counter()
    for _ in range(int(round(duration / sc.run.step))):
        adapter.simulation_step()
    loop = time.perf_counter() - t0
    t_stop = warmup + duration  # --pairs: SUMO steps on (to its end, then Python) until the partner is done
    ob.keep_busy("twin.done", "formation.done",
                 lambda: adapter.simulation_step() if adapter.time < t_stop else ob._spin())
    adapter.close()
    shutil.rmtree(out, ignore_errors=True)
    return {"status": "completed", "vehicles": vehicles, "loop_s": loop}


def spawn_pair(k: int, *args) -> tuple[dict, dict]:
    """The k-formation run and its twin at the same time, one per core, their loops started
    together after the warm-up (ob.meet): both see the same drift of the machine's speed, which
    between two runs minutes apart reached 30 % here."""
    rest = [str(k), *map(str, args)]
    form, twin = ob.run_together(__file__, {"formations": ["formations", *rest], "twin": ["twin", *rest]})
    return form, twin


def spawn(kind: str, *args) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", kind, *map(str, args)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{kind} child failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--warmup", type=float, default=1000.0)
    ap.add_argument("--vph", type=float, default=1800.0)
    ap.add_argument("--formations", type=int, nargs="*", default=[1, 5, 20])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--pairs", type=int, default=1,
                    help="runs of the largest case with its twin at the same time (median ratio)")
    ap.add_argument("--child", nargs=6, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        kind, k, duration, warmup, vph, seed = a.child
        fn = child_formations if kind == "formations" else child_twin
        print(json.dumps(fn(int(k), float(duration), float(warmup), float(vph), int(seed))))
        return
    ob.long_net()
    print(f"{a.vph:.0f} veh/h/lane, {a.warmup:.0f} s warm-up, {a.duration:.0f} s, step 0.05 s, SSM off")
    k_max = max(a.formations)
    for k in sorted(set(a.formations) - {k_max}):  # our layer's cost per member: each run alone
        _show(k, spawn("formations", k, a.duration, a.warmup, a.vph, a.seed))
    ratios = []
    for i in range(a.pairs):  # the largest with its twin, at the same time
        r, twin = spawn_pair(k_max, a.duration, a.warmup, a.vph, a.seed + i)
        _show(k_max, r, f"pair {i + 1} (seed {a.seed + i}), ")
        ratios.append(r["loop_s"] / twin["loop_s"])
        print(f"  twin of {k_max} (SUMO drives the {3 * k_max} vehicles, {twin['vehicles']} SUMO vehicles): "
              f"loop {twin['loop_s']:7.2f} s; SUMO's step alone: formation run / twin "
              f"{r['sumo_s'] / twin['loop_s']:.3f}; formation run / twin {ratios[-1]:.3f}")
    if len(ratios) > 1:
        print(f"  formation run / twin: median of {len(ratios)} pairs, {min(ratios):.2f}-{max(ratios):.2f}")
    print(f"formations ratio: {statistics.median(ratios):.2f}")


def _show(k: int, r: dict, head: str = "") -> None:
    n, steps = 3 * k, max(r["steps"], 1)
    print(f"  {head}{k:3d} formations ({n:3d} members, {r['vehicles']} SUMO vehicles): loop {r['loop_s']:7.2f} s, "
          f"SUMO {r['sumo_s']:7.2f} s, our layer {1e6 * r['layer_s'] / steps:7.0f} us/step = "
          f"{1e6 * r['layer_s'] / steps / n:5.1f} us per member and step  [{r['status']}"
          + (f": {r['incidents']}" if r.get("incidents") else "") + "]")


if __name__ == "__main__":
    main()
