"""Why SUMO's own step is slower in a formation run than in its twin (issue 33).

benchmarks/overhead.py finds SUMO's step (``simulationStep``) 1.10-1.26 times longer in the
formation run than in the twin where SUMO drives the members. This script separates the two
possible causes on the same road and traffic (overhead.py's motorway, 1,500 veh/h/lane, five
members, SSM off), each variant in a fresh process, alternating:

- ``twin``: SUMO drives the five members (overhead.py's twin);
- ``moved``: the five members placed every step by ``moveToXY`` at a constant 30 m/s in their
  lanes (with ``setPreviousSpeed``), their variable subscriptions and the formation's context
  subscription as in a formation run, and nothing else between the steps;
- ``moved+work``: the same, plus ``--work-kb`` kB of numpy and Python objects written between
  the steps (a stand-in for our layer's work: it touches memory SUMO's step then has to read
  back into the cache);
- ``formation``: the real formation run (overhead.py's child), ``simulationStep`` timed alone.

It prints the median ``simulationStep`` time per variant and its ratio to the twin's. With
``--callgrind`` (valgrind installed) it also counts the machine instructions executed inside
``libsumo::Simulation::step`` for ``twin`` and ``moved`` (``--duration`` s each; deterministic,
no machine noise): equal counts with unequal times mean SUMO does the same work, slower.

    python benchmarks/sumo_step_cost.py --duration 120 --repeat 5
    python benchmarks/sumo_step_cost.py --duration 20 --repeat 0 --callgrind
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import overhead as ob  # noqa: E402  (the motorway, its traffic and the formation child)

N_MEMBERS = 5
VARIANTS = ("twin", "moved", "moved+work", "formation")
STEP_SYMBOL = "libsumo::Simulation::step(double)"


def _work(kb: int):
    """Our layer's stand-in: ``kb`` kB of fresh numpy arrays and Python objects written, then
    dropped."""
    import numpy as np
    a = np.ones(max(1, kb * 1024 // 16))  # half the bytes as one array, written twice
    a += 1.0
    [{"i": i} for i in range(max(1, kb * 2))]  # ~250 B per dict: the other half


def child_sumo(variant: str, duration: float, seed: int, work_kb: int) -> dict:
    """``twin``, ``moved`` or ``moved+work``: SUMO's step timed alone."""
    os.environ["BENCH_SSM"] = "off"
    from formation_traci.scenario import parse_scenario
    from formation_traci.sumo.adapter import SumoAdapter
    from formation_traci.sumo.plan import sumo_args
    sc = parse_scenario(ob.scenario(N_MEMBERS, duration, None, seed), "benchmark")
    out = Path(tempfile.mkdtemp(prefix="bench_s_"))
    args = sumo_args(sc, ob.long_net(), ob.twin_routes(sc, out, duration, N_MEMBERS), out, duration + 1)
    adapter = SumoAdapter("libsumo")
    adapter.start(args)
    api, tc = adapter.api, adapter.tc
    ids = [m["id"] for m in ob.formation_slots(N_MEMBERS)]
    while not set(ids) <= set(api.vehicle.getIDList()):  # every member inserted
        api.simulationStep()
    moved = variant != "twin"
    pos = {}
    if moved:
        for vid in ids:
            api.vehicle.setSpeedMode(vid, 0)
            api.vehicle.setLaneChangeMode(vid, 0)
            api.vehicle.subscribe(vid, [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LANE_ID, tc.VAR_LANE_INDEX,
                                        tc.VAR_LANEPOSITION, tc.VAR_LANEPOSITION_LAT])
            pos[vid] = api.vehicle.getPosition(vid)
        api.vehicle.subscribeContext(ids[0], tc.CMD_GET_VEHICLE_VARIABLE, 340.0,
                                     [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_ACCELERATION,
                                      tc.VAR_LANE_ID, tc.VAR_LANE_INDEX])
    steps, dt = int(round(duration / sc.run.step)), sc.run.step
    t_step = 0.0
    for _ in range(steps):
        if moved:
            for vid in ids:
                x, y = pos[vid]
                pos[vid] = (x + ob.SPEED * dt, y)
                api.vehicle.moveToXY(vid, "", -1, x + ob.SPEED * dt, y, 90.0, 1, 5.0)
                api.vehicle.setPreviousSpeed(vid, ob.SPEED)
        if variant == "moved+work":
            _work(work_kb)
        t0 = time.perf_counter()
        api.simulationStep()
        t_step += time.perf_counter() - t0
        if moved:
            api.vehicle.getAllSubscriptionResults()
            api.vehicle.getAllContextSubscriptionResults()
    adapter.close()
    shutil.rmtree(out, ignore_errors=True)
    return {"variant": variant, "step_us": 1e6 * t_step / steps, "steps": steps}


def child_formation(duration: float, seed: int) -> dict:
    """The formation run of overhead.py with ``simulationStep`` itself timed."""
    os.environ["BENCH_SSM"] = "off"
    from formation_traci.sumo import adapter as sumo_adapter
    spent = {"s": 0.0, "n": 0}
    step = sumo_adapter.SumoAdapter.step

    def timed_step(self):
        if not hasattr(self, "_bench_step"):
            self._bench_step = inner = self.api.simulationStep

            def timed():
                t0 = time.perf_counter()
                inner()
                spent["s"] += time.perf_counter() - t0
                spent["n"] += 1
            self.api.simulationStep = timed
        return step(self)

    sumo_adapter.SumoAdapter.step = timed_step
    ob.child_formation(N_MEMBERS, duration, None, seed)
    return {"variant": "formation", "step_us": 1e6 * spent["s"] / max(1, spent["n"]), "steps": spent["n"]}


def spawn(variant: str, duration: float, seed: int, work_kb: int) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", variant, str(duration), str(seed), str(work_kb)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{variant} child failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def callgrind(variant: str, duration: float, seed: int) -> int | None:
    """Instructions executed inside SUMO's step over the run (valgrind's callgrind), or None."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp, "cg.out")
        subprocess.run([valgrind, "--tool=callgrind", f"--callgrind-out-file={out}", "--collect-atstart=no",
                        f"--toggle-collect={STEP_SYMBOL}", sys.executable, __file__, "--child", variant,
                        str(duration), str(seed), "0"], capture_output=True, text=True, check=True)
        for line in out.read_text().splitlines():
            if line.startswith("summary:") or line.startswith("totals:"):
                return int(line.split()[1])
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=120.0, help="simulated seconds per run")
    ap.add_argument("--repeat", type=int, default=5, help="alternating rounds of every variant")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--work-kb", type=int, default=2048, help="moved+work: kB written between the steps")
    ap.add_argument("--callgrind", action="store_true", help="also count SUMO's instructions (twin, moved)")
    ap.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        variant, duration, seed, kb = a.child[0], float(a.child[1]), int(a.child[2]), int(a.child[3])
        res = child_formation(duration, seed) if variant == "formation" else child_sumo(variant, duration, seed, kb)
        print(json.dumps(res))
        return
    ob.long_net()
    print(f"{N_MEMBERS} members, {a.duration:.0f} s, seed {a.seed}, SSM off; moved+work writes {a.work_kb} kB per step")
    times = {v: [] for v in VARIANTS}
    for r in range(a.repeat):
        order = VARIANTS if r % 2 == 0 else VARIANTS[::-1]
        for v in order:
            times[v].append(spawn(v, a.duration, a.seed, a.work_kb)["step_us"])
            print(f"  round {r + 1} {v:11s} simulationStep {times[v][-1]:7.0f} us", flush=True)
    if a.repeat:
        base = statistics.median(times["twin"])
        for v in VARIANTS:
            med = statistics.median(times[v])
            print(f"{v:11s}: simulationStep median {med:6.0f} us  ({min(times[v]):.0f}-{max(times[v]):.0f}), "
                  f"{med / base:.3f} x the twin's")
    if a.callgrind:
        counts = {v: callgrind(v, a.duration, a.seed) for v in ("twin", "moved")}
        if None in counts.values():
            print("callgrind: valgrind not found")
        else:
            print(f"callgrind: instructions inside SUMO's step, {a.duration:.0f} s: twin {counts['twin']:,}, "
                  f"moved {counts['moved']:,} ({counts['moved'] / counts['twin']:.3f} x)")


if __name__ == "__main__":
    main()
