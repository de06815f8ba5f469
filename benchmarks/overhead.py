"""What the formation layer costs on top of SUMO (issue: performance).

Runs, alternating to cancel machine noise, the reference case and its twin, each in a fresh
process (libsumo allows one simulation per process; peak memory is per process):

- formation: a 120 km straight 3-lane motorway (edges of 1 km, ``--edge-m``), 1500 veh/h/lane of background traffic, a
  5-member wedge with the dynamic model, SUMO step 0.05 s, 600 s simulated, recording on;
- twin: the same network, demand and seed through libsumo, the five members as ordinary SUMO
  vehicles of the same type, departure, lanes and speed, driven by SUMO;
- bare: the same traffic without the members.

Then the scaling with 1, 5, 20 and 50 members, and a 600 s versus 3600 s run for memory
(there the flows stop after 240 s so SUMO's own vehicle count is the same in both).

    python benchmarks/overhead.py                 # full (40 minutes or more on 2 cores)
    python benchmarks/overhead.py --quick         # 60 s runs, 1 pair, small scaling table
    python benchmarks/overhead.py --no-ssm        # SUMO's SSM device off in every run
    python benchmarks/overhead.py --ssm-all       # SUMO's SSM device on every vehicle
    python benchmarks/overhead.py --edge-m 120000 # the motorway as one 120 km edge
    python benchmarks/overhead.py --together      # formation and twin at once, one per core

Pair i runs with seed ``--seed`` + i (formation, twin and bare of a pair share it). A formation
run and its twin never see the same realisation of the random traffic (the queue behind the
formation builds at different times), so one seed would carry one fixed bias in SUMO's own
step; over several seeds it averages out.

Timings are wall-clock seconds of the simulation loop (after SUMO has started, until the run
ends); setup (network reading, reference line, SUMO start) is printed separately.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
CACHE = HERE / ".cache"
ROAD_M = 120_000.0
SPEED = 30.0  # set speed of the formation [m/s]
START = 600.0  # formation's start along the road [m]


def edge_m() -> float:
    """Length of one edge of the benchmark motorway [m] (``--edge-m``; children inherit it)."""
    return float(os.environ.get("BENCH_EDGE_M", "1000"))


def long_net() -> Path:
    """Build (once) a straight 3-lane motorway of ROAD_M metres, split into edges of
    :func:`edge_m` metres, with the wheel's netconvert.

    The split matters: with the sublane model SUMO checks collisions pairwise among all
    vehicles of a lane, and a ``moveToXY`` re-inserts the member, which costs its lane one
    more such check in the step. On a single 120 km edge that makes SUMO's own step ~7 %
    slower with five moved members than with five SUMO-driven ones; on 1 km edges (real
    motorway networks are split at every junction and ramp) the extra is not measurable.
    RESULTS.md gives both."""
    n_edges = max(1, int(round(ROAD_M / edge_m())))
    name = f"long3_{n_edges}"
    net = CACHE / f"{name}.net.xml"
    if net.exists():
        return net
    CACHE.mkdir(exist_ok=True)
    xs = [ROAD_M * i / n_edges for i in range(n_edges + 1)]
    (CACHE / f"{name}.nod.xml").write_text("<nodes>" + "".join(
        f'<node id="n{i}" x="{x:.1f}" y="0"/>' for i, x in enumerate(xs)) + "</nodes>\n")
    (CACHE / f"{name}.edg.xml").write_text("<edges>" + "".join(
        f'<edge id="{e}" from="n{i}" to="n{i + 1}" numLanes="3" speed="36.11" width="3.5" '
        'disallow="pedestrian bicycle"/>' for i, e in enumerate(route_edges())) + "</edges>\n")
    import sumolib
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", f"{name}.nod.xml", "-e", f"{name}.edg.xml",
                    "-o", f"{name}.net.xml", "--offset.disable-normalization", "true", "--no-turnarounds", "true",
                    "--precision", "4", "--default.lanewidth", "3.5"], cwd=CACHE, check=True,
                   stdout=subprocess.DEVNULL)
    return net


def route_edges() -> list[str]:
    """The motorway's edges in driving order."""
    return [f"e{i}" for i in range(max(1, int(round(ROAD_M / edge_m()))))]


def formation_slots(n: int) -> list[dict]:
    """n members in a multi-lane wedge/column block: apex in the centre lane, then rows of
    three lanes 20 m apart."""
    slots = [{"along": 0.0, "lanes": 0}]
    row = 1
    while len(slots) < n:
        for lanes in (-1, 1, 0):
            if len(slots) < n:
                slots.append({"along": -20.0 * row, "lanes": lanes})
        row += 1
    return [{"id": f"m{i:02d}", "slot": s} for i, s in enumerate(slots)]


def scenario(n: int, duration: float, flow_end: float | None, seed: int) -> dict:
    flow = {"id": "main", "veh_per_hour_per_lane": 1500}
    if flow_end is not None:
        flow["end"] = flow_end
    return {
        "name": f"bench-{n}",
        "run": {"duration": duration, "step": 0.05, "seed": seed},
        "vehicle": {"model": "dynamic"},
        "road": {"net": str(long_net()), "route": route_edges(), "lane": 1, "start": START},
        "leader": {"speed": SPEED},
        "members": formation_slots(n),
        "traffic": {"warmup": 0.0, "flows": [flow], "sections": {"enabled": False}},  # the loop, no drain
        "sumo": {"ssm": os.environ.get("BENCH_SSM", "members")},
    }


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


# --------------------------------------------------------------------------- children
def meet(me: str, other: str) -> float:
    """--together: say ``me`` is ready and wait until ``other`` is (files in BENCH_BARRIER);
    returns the seconds waited. No-op (0) when not run together."""
    d = os.environ.get("BENCH_BARRIER")
    if not d:
        return 0.0
    t0 = time.perf_counter()
    Path(d, me).touch()
    while not Path(d, other).exists():
        if time.perf_counter() - t0 > 600.0:  # the partner failed before it was ready
            raise RuntimeError(f"{other} not ready after 600 s")
        time.sleep(0.001)
    return time.perf_counter() - t0


def child_formation(n, duration, flow_end, seed):
    from formation_traci.scenario import parse_scenario
    from formation_traci.runner import run_scenario
    sc = parse_scenario(scenario(n, duration, flow_end, seed), "benchmark")
    out = Path(tempfile.mkdtemp(prefix="bench_"))
    waited = []

    def barrier(k, t, adapter):  # after SUMO's first step: both loops start together
        if k == 0:
            waited.append(meet("formation.ready", "twin.ready"))

    t0 = time.perf_counter()
    res = run_scenario(sc, out / "run", progress=False, step_hook=barrier)
    total = time.perf_counter() - t0
    meta = json.loads((out / "run" / "run.json").read_text())
    timing = meta.get("timing_s", {})
    timing["sumo_step"] = timing.get("sumo_step", 0.0) - sum(waited)  # the wait is no work
    loop = sum(timing.values())
    total -= sum(waited)
    keep_busy("formation.done", "twin.done")
    shutil.rmtree(out, ignore_errors=True)
    return {"status": res.status, "total_s": total, "loop_s": loop, "setup_s": total - loop,
            "timing_s": timing, "steps": res.steps_done, "peak_rss_mb": peak_rss_mb()}


def twin_routes(sc, out: Path, duration: float, n: int) -> Path:
    """SUMO routes of the benchmark traffic of ``sc`` plus, for n > 0, the n members as SUMO
    vehicles of the members' size (maxSpeed SPEED, no dawdling) in their slots' lanes."""
    from formation_traci.models.params import PASSENGER_CAR
    from formation_traci.sumo.traffic import write_routes
    routes = write_routes(out / "traffic.rou.xml", [(sc.traffic.flows[0], route_edges(), 1500 * 3)],
                          duration + 1)
    if n:
        text = routes.read_text().replace("</routes>", "")
        car = PASSENGER_CAR
        text += (f'  <vType id="member" length="{car.length}" width="{car.width}" maxSpeed="{SPEED}" '
                 f'speedFactor="1" sigma="0" minGap="2"/>\n  <route id="member_route" edges="{" ".join(route_edges())}"/>\n')
        for m in formation_slots(n):
            pos = START + m["slot"]["along"] + car.cog_to_front_bumper
            text += (f'  <vehicle id="{m["id"]}" type="member" route="member_route" depart="0" '
                     f'departLane="{1 + m["slot"]["lanes"]}" departPos="{pos:.2f}" departSpeed="{SPEED}"/>\n')
        routes.write_text(text + "</routes>\n")
    return routes


def child_sumo(n, duration, flow_end, seed):
    """The twin (n > 0: members as SUMO vehicles) or the bare traffic (n = 0)."""
    from formation_traci.scenario import parse_scenario
    from formation_traci.sumo.adapter import SumoAdapter
    from formation_traci.sumo.plan import sumo_args
    sc = parse_scenario(scenario(max(n, 1), duration, flow_end, seed), "benchmark")
    out = Path(tempfile.mkdtemp(prefix="bench_"))
    t0 = time.perf_counter()
    routes = twin_routes(sc, out, duration, n)
    args = sumo_args(sc, long_net(), routes, out, duration + 1)
    if os.environ.get("BENCH_BARRIER"):  # --together: SUMO may step on after the timed loop
        args[args.index("--end") + 1] = repr(3 * duration + 10)
    adapter = SumoAdapter("libsumo")
    adapter.start(args)
    waited = meet("twin.ready", "formation.ready")
    t1 = time.perf_counter()
    steps = int(round(duration / sc.run.step))
    for _ in range(steps):
        adapter.simulation_step()
    t2 = time.perf_counter()
    t_stop = float(args[args.index("--end") + 1]) - 1.0  # SUMO steps on until its end, then Python

    def more():
        if adapter.time < t_stop:
            adapter.simulation_step()
        else:
            _spin()

    keep_busy("twin.done", "formation.done", more)
    t3 = time.perf_counter()
    adapter.close()
    t4 = time.perf_counter()
    shutil.rmtree(out, ignore_errors=True)
    setup = t1 - t0 - waited  # the wait and the work after the timed loop are not the run's
    return {"status": "completed", "total_s": setup + (t2 - t1) + (t4 - t3), "loop_s": t2 - t1,
            "setup_s": setup, "steps": steps, "peak_rss_mb": peak_rss_mb()}


def keep_busy(me: str, other: str, work=None) -> None:
    """--together: say ``me`` is done, then keep working (``work()``: SUMO steps on; else a
    Python loop) until ``other`` is done, so that the partner runs under the same load to
    its end. No-op when not run together."""
    d = os.environ.get("BENCH_BARRIER")
    if not d:
        return
    Path(d, me).touch()
    t_give_up = time.perf_counter() + 3600.0
    while not Path(d, other).exists() and time.perf_counter() < t_give_up:
        (work or _spin)()


def _spin() -> None:
    """A few hundred microseconds of Python work (keeps a core busy)."""
    sum(range(20000))


def spawn_together(n: int, duration: float, seed: int) -> tuple[dict, dict]:
    """The formation and its twin at the same time, one per core, their loops started
    together (the machine's speed drifts by tens of percent within minutes; run together,
    both see the same drift)."""
    rest = [str(n), str(duration), "None", str(seed)]
    form, twin = run_together(__file__, {"formation": ["formation", *rest], "twin": ["sumo", *rest]})
    return form, twin


def run_together(script, children: dict[str, list[str]]) -> list[dict]:
    """``script --child ARGS`` for each named child at the same time, sharing one BENCH_BARRIER
    directory (:func:`meet`, :func:`keep_busy`); their last stdout lines as JSON, in order."""
    with tempfile.TemporaryDirectory(prefix="bench_barrier_") as d:
        env = dict(os.environ, BENCH_BARRIER=d)
        procs = {name: subprocess.Popen([sys.executable, str(script), "--child", *argv], stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True, env=env)
                 for name, argv in children.items()}
        out = []
        for name, p in procs.items():
            so, se = p.communicate()
            if p.returncode != 0:
                raise RuntimeError(f"{name} child failed:\n{se[-3000:]}")
            out.append(json.loads(so.strip().splitlines()[-1]))
    return out


def spawn(kind: str, n: int, duration: float, flow_end: float | None, seed: int) -> dict:
    cmd = [sys.executable, __file__, "--child", kind, str(n), str(duration), str(flow_end), str(seed)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{kind} child failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


# --------------------------------------------------------------------------- report
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--long-duration", type=float, default=3600.0)
    ap.add_argument("--members", type=int, nargs="*", default=[1, 5, 20, 50])
    ap.add_argument("--skip-scaling", action="store_true")
    ap.add_argument("--skip-long", action="store_true")
    ap.add_argument("--quick", action="store_true", help="60 s runs, 1 pair, members 1 5, no long run")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-ssm", action="store_true",
                    help="SUMO's SSM device off in every run")
    ap.add_argument("--ssm-all", action="store_true",
                    help="SUMO's SSM device on every vehicle (before issue 18 the default; it dominates "
                         "SUMO's time and memory); default: on the members only (sumo.ssm = members)")
    ap.add_argument("--edge-m", type=float, default=1000.0,
                    help="length of one edge of the 120 km motorway [m] (120000: a single edge)")
    ap.add_argument("--together", action="store_true",
                    help="run each pair's formation and twin at the same time, one per core, their "
                         "loops started together (cancels the machine's drift; needs 2 idle cores)")
    ap.add_argument("--child", nargs=5, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        kind, n, duration, flow_end, seed = a.child
        fe = None if flow_end == "None" else float(flow_end)
        fn = child_formation if kind == "formation" else child_sumo
        print(json.dumps(fn(int(n), float(duration), fe, int(seed))))
        return
    if a.quick:
        a.pairs, a.duration, a.members, a.skip_long = 1, 60.0, [1, 5], True
    os.environ["BENCH_SSM"] = "off" if a.no_ssm else ("all" if a.ssm_all else "members")  # children inherit it
    os.environ["BENCH_EDGE_M"] = str(a.edge_m)

    long_net()
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}; "
          f"reference: 5-member wedge, dynamic model, 1500 veh/h/lane, step 0.05 s, {a.duration:.0f} s, "
          f"SSM device {os.environ['BENCH_SSM']}, edges of {a.edge_m:.0f} m")
    form, twin, bare = [], [], []
    for i in range(a.pairs):
        seed = a.seed + i  # a pair shares its seed; pairs differ (see RESULTS.md: traffic realisations)
        if a.together:
            f, t = spawn_together(5, a.duration, seed)
            form.append(f)
            twin.append(t)
            for kind, r in (("formation", f), ("twin", t)):
                print(f"  pair {i + 1} (seed {seed}) {kind:9s} loop {r['loop_s']:7.2f} s  setup {r['setup_s']:5.2f} s  "
                      f"peak {r['peak_rss_mb']:6.0f} MB  (together)")
        order = [] if a.together else (
            [("formation", form), ("twin", twin)] if i % 2 == 0 else [("twin", twin), ("formation", form)])
        for kind, bucket in order:
            r = spawn("formation" if kind == "formation" else "sumo", 5 if kind != "bare" else 0,
                      a.duration, None, seed)
            bucket.append(r)
            print(f"  pair {i + 1} (seed {seed}) {kind:9s} loop {r['loop_s']:7.2f} s  setup {r['setup_s']:5.2f} s  "
                  f"peak {r['peak_rss_mb']:6.0f} MB")
        r = spawn("sumo", 0, a.duration, None, seed)
        bare.append(r)
        print(f"  pair {i + 1} (seed {seed}) bare      loop {r['loop_s']:7.2f} s  setup {r['setup_s']:5.2f} s  "
              f"peak {r['peak_rss_mb']:6.0f} MB")
    ratios = [f["loop_s"] / t["loop_s"] for f, t in zip(form, twin)]
    ratios_bare = [f["loop_s"] / b["loop_s"] for f, b in zip(form, bare)]
    med = statistics.median(ratios)
    spread = (min(ratios), max(ratios))
    steps = form[0]["steps"]
    sim_time = a.duration
    print()
    print(f"formation / twin  : median {med:.3f}  (min {spread[0]:.3f}, max {spread[1]:.3f}, {len(ratios)} pairs)")
    print(f"formation / bare  : median {statistics.median(ratios_bare):.3f}")
    sumo_only = [f["timing_s"]["sumo_step"] / t["loop_s"] for f, t in zip(form, twin)]
    print(f"SUMO's step alone : formation run / twin median {statistics.median(sumo_only):.3f} "
          f"(min {min(sumo_only):.3f}, max {max(sumo_only):.3f}); the rest of the ratio is our layer")
    ratios_total = [f["total_s"] / t["total_s"] for f, t in zip(form, twin)]
    print(f"with setup        : formation / twin median {statistics.median(ratios_total):.3f} "
          f"(setup: formation {statistics.median(f['setup_s'] for f in form):.1f} s, "
          f"twin {statistics.median(t['setup_s'] for t in twin):.1f} s)")
    print(f"real-time factor  : formation {sim_time / statistics.median(f['loop_s'] for f in form):.1f}x, "
          f"twin {sim_time / statistics.median(t['loop_s'] for t in twin):.1f}x, "
          f"bare {sim_time / statistics.median(b['loop_s'] for b in bare):.1f}x")
    print(f"peak memory       : formation {max(f['peak_rss_mb'] for f in form):.0f} MB, "
          f"twin {max(t['peak_rss_mb'] for t in twin):.0f} MB")
    tm = {k: statistics.median(f["timing_s"][k] for f in form) for k in form[0]["timing_s"]}
    print("split per step (median run, microseconds): " + ", ".join(
        f"{k} {1e6 * v / steps:.0f}" for k, v in tm.items()))

    if not a.skip_scaling:
        print()
        print("members | loop s | ours per step [us] | ours per member per step [us] | peak MB")
        for n in a.members:
            r = spawn("formation", n, a.duration, None, a.seed)
            ours = sum(v for k, v in r["timing_s"].items() if k != "sumo_step")
            print(f"{n:7d} | {r['loop_s']:6.1f} | {1e6 * ours / r['steps']:18.0f} | "
                  f"{1e6 * ours / r['steps'] / n:29.1f} | {r['peak_rss_mb']:7.0f}")
    if not a.skip_long:
        print()
        print("run length | loop s | peak MB   (5 members, flows stop at 240 s)")
        for d in (a.duration, a.long_duration):
            r = spawn("formation", 5, d, 240.0, a.seed)
            print(f"{d:9.0f}s | {r['loop_s']:6.1f} | {r['peak_rss_mb']:7.0f}")
    print()
    print(f"overhead ratio: {med:.2f} (median of {len(ratios)} pairs)")


if __name__ == "__main__":
    main()
