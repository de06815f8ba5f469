"""The scale case against its same-demand twin: scenarios/highway/motorway100.toml (100 km,
4 lanes, ~4,050 vehicles populated at t = 0, formation flows at 15 % penetration) and the same
run with every member a SUMO-driven vehicle (``run --baseline same``).

Both run at the same time, one per core, each in a fresh process (one libsumo per process),
their loops started together after the warm-up (overhead.py's ``run_together``, ``meet`` and
``keep_busy``): both see the same drift of the machine's speed.

    python benchmarks/scale.py            # the scenario as bundled (60 s warm-up, 600 s)
    python benchmarks/scale.py --quick    # 10 s warm-up, 30 s: a few minutes on 2 cores
    python benchmarks/scale.py --duration 120 --warmup 30

Per run: the real-time factor of the loop (simulated seconds over the loop's wall seconds,
run.json timing_s), SUMO's step and our layer's time (every other timing_s phase) per step,
the members on the road (mean over the recorded steps, trajectories.parquet), peak memory
(the process's max RSS) and the bytes the run wrote (its run directory) per simulated hour of
the run (tables and run.json; SUMO's input files, written once, apart). The last two lines:
``per member: X us`` (our layer per member and step in the formation run) and ``scale ratio:
X.XX``: the formation run's loop over SUMO's own step time in the twin, i.e. over what SUMO
alone takes to drive the same vehicles. The twin's loop also holds our reading and recording of
its vehicles (every timing_s phase but sumo_step), which a SUMO-alone run would not have; the
ratio of the two loops is printed above it.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import overhead as ob  # noqa: E402  (run_together, meet, keep_busy, peak_rss_mb)

CASE = HERE.parent / "scenarios" / "highway" / "motorway100.toml"
QUICK = {"warmup": 10.0, "duration": 30.0}


def child(kind: str, duration: float, warmup: float) -> dict:
    """One run of the case (kind ``formation``) or its twin (``twin``), its loop started with
    the partner's."""
    import pandas as pd

    from formation_traci.runner import run_scenario
    from formation_traci.scenario import load_scenario

    me, other = (f"{kind}.ready", ("twin" if kind == "formation" else "formation") + ".ready")
    sc = load_scenario(CASE, **{"run.duration": duration, "traffic.warmup": warmup})
    out = Path(tempfile.mkdtemp(prefix=f"bench_scale_{kind}_")) / "run"
    waited, vehicles = [], []

    def hook(k, t, adapter):  # after the warm-up's last SUMO step: both loops start together
        if k == 0:
            vehicles.append(adapter.api.vehicle.getIDCount())
            waited.append(ob.meet(me, other))

    res = run_scenario(sc, out, scenario_path=CASE, progress=False, force=True,
                       baseline="same" if kind == "twin" else False, step_hook=hook)
    ob.keep_busy(me.replace("ready", "done"), other.replace("ready", "done"))
    meta = json.loads((out / "run.json").read_text())
    timing = meta.get("timing_s", {})
    timing["sumo_step"] = timing.get("sumo_step", 0.0) - sum(waited)  # the wait is no work
    traj = pd.read_parquet(out / "trajectories.parquet", columns=["t", "vehicle_id"])
    ids = traj.vehicle_id.astype(str)
    members = traj[~ids.str.startswith("vc")] if kind == "formation" else traj.iloc[:0]
    per_t = members.groupby("t").size()
    files = [p for p in out.rglob("*") if p.is_file()]
    setup = sum(p.stat().st_size for p in files if p.relative_to(out).parts[0] == "sumo")  # SUMO's inputs
    written = sum(p.stat().st_size for p in files) - setup
    shutil.rmtree(out.parent, ignore_errors=True)
    return {"status": res.status, "steps": res.steps_done, "t_end": meta.get("t_end", 0.0),
            "timing_s": timing, "loop_s": sum(timing.values()),
            "members_mean": len(members) / max(traj.t.nunique(), 1),
            "members_last": int(per_t.iloc[-1]) if len(per_t) else 0,
            "vehicles": vehicles[0] if vehicles else None, "bytes": written, "setup_bytes": setup,
            "peak_rss_mb": ob.peak_rss_mb(), "incidents": res.incident_summary}


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def show(kind: str, r: dict) -> None:
    steps, t = max(r["steps"], 1), max(r["t_end"], 1e-9)
    sumo = r["timing_s"].get("sumo_step", 0.0)
    layer = r["loop_s"] - sumo
    print(f"{kind:9s}: real-time factor {t / r['loop_s']:.3f} (loop {r['loop_s']:.1f} s for {t:.0f} s), "
          f"SUMO step {1e3 * sumo / steps:.1f} ms, our layer {1e3 * layer / steps:.1f} ms per step; "
          f"{r['vehicles']} SUMO vehicles after the warm-up; peak {r['peak_rss_mb']:.0f} MB; "
          f"wrote {r['bytes'] / 1e6:.1f} MB of tables and run.json = {r['bytes'] / 1e9 * 3600.0 / t:.2f} GB per "
          f"simulated hour (+ {r['setup_bytes'] / 1e6:.1f} MB of SUMO inputs once)  "
          f"[{r['status']}" + (f": {r['incidents']}" if r.get("incidents") else "") + "]")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true",
                    help=f"{QUICK['warmup']:.0f} s warm-up and {QUICK['duration']:.0f} s of formations")
    ap.add_argument("--duration", type=float, help="run.duration [s] (default: the scenario's)")
    ap.add_argument("--warmup", type=float, help="traffic.warmup [s] (default: the scenario's)")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        kind, duration, warmup = a.child
        print(json.dumps(child(kind, float(duration), float(warmup))))
        return
    from formation_traci.scenario import load_scenario

    sc = load_scenario(CASE)
    duration = a.duration or (QUICK["duration"] if a.quick else sc.run.duration)
    warmup = a.warmup if a.warmup is not None else (QUICK["warmup"] if a.quick else sc.traffic.warmup)
    print(f"machine: {os.cpu_count()} cores, {cpu_model()}, Python {sys.version.split()[0]}")
    print(f"case: {CASE.relative_to(HERE.parent)}, {warmup:.0f} s warm-up, {duration:.0f} s, step "
          f"{sc.run.step} s, {len(sc.formation_flows)} formation flows; formation run and twin together")
    rest = [str(duration), str(warmup)]
    form, twin = ob.run_together(__file__, {"formation": ["formation", *rest], "twin": ["twin", *rest]})
    show("formation", form)
    show("twin", twin)
    steps = max(form["steps"], 1)
    for kind, r in (("formation run", form), ("twin", twin)):
        print(f"{kind} per step (ms, run.json timing_s): " + ", ".join(
            f"{k} {1e3 * v / max(r['steps'], 1):.1f}" for k, v in r["timing_s"].items()))
    layer = form["loop_s"] - form["timing_s"].get("sumo_step", 0.0)
    twin_sumo = max(twin["timing_s"].get("sumo_step", 0.0), 1e-9)  # SUMO driving the same vehicles
    print(f"members on the road: {form['members_mean']:.0f} (mean over the steps), {form['members_last']} at the "
          f"end; SUMO's step: formation "
          f"run / twin {form['timing_s'].get('sumo_step', 0.0) / max(twin['timing_s'].get('sumo_step', 0.0), 1e-9):.3f}")
    print(f"formation run / twin run (loops): {form['loop_s'] / twin['loop_s']:.2f} (the twin's loop holds our "
          f"recording of it: {1e3 * (twin['loop_s'] - twin_sumo) / max(twin['steps'], 1):.1f} ms per step)")
    print(f"per member: {1e6 * layer / steps / max(form['members_mean'], 1e-9):.0f} us")
    print(f"scale ratio: {form['loop_s'] / twin_sumo:.2f}")


if __name__ == "__main__":
    main()
