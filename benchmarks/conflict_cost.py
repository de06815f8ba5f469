"""What the default conflict measurement costs (issue 18 item 5).

Runs ``scenarios/highway/straight_3lane_medium.toml`` for 300 s (200 s warm-up) twice, each in a
fresh process: with the default conflict measurement (``sumo.ssm = "members"``: SUMO's SSM device
on the members, then the analysis' conflicts from the recording) and with none
(``sumo.ssm = "off"``). The cost is

    (loop of the default run + conflict analysis) / loop of the run without

with the loop the wall-clock seconds from SUMO started to the end of the run (``timing_s``), and
the conflict analysis the time of ``analysis.runs.conflict_run`` on the loaded recording (building
the rows, ``recorded_conflicts``, the SSM table); reading the recording is printed apart, since the
analysis reads it anyway. On a shared machine the wall clock drifts with the others' load; the
CPU seconds of each process (with setup) are printed too. ``--oracle`` adds a run with the device on every vehicle (``"all"``,
the former default) and checks the default against it on that run: member conflicts of SUMO's
device with TTC < 3 s found from the recording (min TTC within 0.2 s), and background pairs both
recorded at the time of the minimum TTC.

    python benchmarks/conflict_cost.py                 # default / none, 1 pair
    python benchmarks/conflict_cost.py --oracle        # also the device on every vehicle

Prints ``conflict measurement cost: X.XX``.
"""
from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "highway" / "straight_3lane_medium.toml"


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _conflict_analysis(run: Path) -> dict:
    """Time the conflict part of the analysis on a finished run, and what it finds."""
    from analysis.metrics import traffic as tr
    from analysis.runs.conflict_run import recorded_section, ssm_section
    from analysis.load.run_data import load_run
    from analysis.runs.summary import DEFAULT_SETTINGS
    from analysis.runs.traffic_run import background_rows, member_rows
    t0 = time.perf_counter()
    data = load_run(run)
    t1 = time.perf_counter()
    fp, _ = tr.member_footprint(data.meta.get("scenario"))
    ids = [m.id for m in data.members]
    import pandas as pd
    bg = data.tables.get("background")
    M = member_rows(data, fp, data.dt)
    B = background_rows(bg, data.dt, set(ids)) if bg is not None else M.iloc[:0]
    run_m, _, tab = recorded_section(pd.concat([M, B], ignore_index=True), ids, DEFAULT_SETTINGS)
    traj = data.trajectories
    sr = ssm_section(data.tables.get("ssm"), ids, float(traj["t"].min()), float(traj["t"].max()),
                     DEFAULT_SETTINGS, set(zip(B["vehicle_id"], B["key"])), data.dt,
                     data.tables.get("events"), M[["t", "vehicle_id", "s"]])
    t2 = time.perf_counter()
    return {"read_s": t1 - t0, "conflicts_s": t2 - t1, "n_rows": int(len(M) + len(B)),
            "recorded": run_m, "ssm": sr.run, "conflicts": tab.to_dict("list")}


def child(mode: str, duration: float) -> dict:
    from formation_traci.scenario import load_scenario
    from formation_traci.runner import run_scenario
    sc = load_scenario(SCENARIO, **{"run.duration": duration, "sumo.ssm": mode, "traffic.sections.enabled": False})
    out = Path(tempfile.mkdtemp(prefix="conflict_cost_")) / "run"
    t0, c0 = time.perf_counter(), time.process_time()
    res = run_scenario(sc, out, scenario_path=SCENARIO, progress=False)
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    meta = json.loads((out / "run.json").read_text())
    loop = sum(meta.get("timing_s", {}).values())
    rss_run = peak_rss_mb()
    r = {"mode": mode, "status": res.status, "loop_s": loop, "setup_s": total - loop,
         "cpu_s": cpu, "peak_rss_mb": rss_run}
    if mode != "off":
        c1 = time.process_time()
        r.update(_conflict_analysis(out))
        r["conflicts_cpu_s"] = time.process_time() - c1
        r["peak_rss_with_analysis_mb"] = peak_rss_mb()
    r["run_dir"] = str(out)
    return r


def spawn(mode: str, duration: float) -> dict:
    p = subprocess.run([sys.executable, __file__, "--child", mode, str(duration)], capture_output=True,
                       text=True, cwd=ROOT)
    if p.returncode != 0:
        raise RuntimeError(f"{mode} child failed:\n{p.stderr[-3000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def _oracle_check(oracle: dict, default: dict) -> None:
    import numpy as np
    import pandas as pd
    from analysis.metrics import conflicts as cf
    from analysis.metrics import traffic as tr
    run = Path(oracle["run_dir"])
    s = pd.read_parquet(run / "ssm.parquet")
    s = tr.merge_ssm_duplicates(s.assign(ego=s["ego"].astype(str), foe=s["foe"].astype(str)))
    s = s.loc[s["end"] >= 0]
    ours = pd.DataFrame(oracle["conflicts"])
    mem = s.loc[s["member_involved"].astype(bool)]
    chk = cf.compare_with_ssm(ours, mem)
    print(f"oracle, member conflicts with TTC < 3 s: {len(chk)}, found from the recording "
          f"{int(chk['found'].sum())}, min TTC within 0.2 s {int(chk['within'].sum())}")
    bg = pd.read_parquet(run / "background.parquet")
    keys = set(zip(bg["vehicle_id"].astype(str), np.round(bg["t"].to_numpy() / 0.05).astype(int)))
    k = np.round(s["min_ttc_time"].fillna(s["begin"]).to_numpy() / 0.05).astype(int)
    both = np.array([(e, kk) in keys and (f, kk) in keys for e, f, kk in zip(s["ego"], s["foe"], k)],
                    bool)
    near = s.loc[both & ~s["member_involved"].astype(bool).to_numpy()]
    chk = cf.compare_with_ssm(ours, near)
    extreme = near["min_ttc"] <= 0.05
    print(f"oracle, background pairs both recorded with TTC < 3 s: {len(chk)} ({int(extreme.sum())} "
          f"with TTC 0), found {int(chk['found'].sum())}, within 0.2 s {int(chk['within'].sum())}")
    print(f"oracle SSM extremes by class: " + ", ".join(
        f"{k[len('ssm_n_extreme_'):]} {v}" for k, v in oracle["ssm"].items() if k.startswith("ssm_n_extreme_")))
    d = pd.read_parquet(Path(default["run_dir"]) / "ssm.parquet")
    print(f"default run (device on the members): {len(d)} SSM records, "
          f"{int(d['member_involved'].astype(bool).sum())} with a member")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--oracle", action="store_true", help="also run the SSM device on every vehicle")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(a.child[0], float(a.child[1]))))
        return
    runs = {}
    for m in ["members", "off"] + (["all"] if a.oracle else []):
        r = runs[m] = spawn(m, a.duration)
        extra = (f", read {r['read_s']:.2f} s, conflict analysis {r['conflicts_s']:.2f} s "
                 f"({r['n_rows']} rows), peak with analysis {r['peak_rss_with_analysis_mb']:.0f} MB"
                 if "conflicts_s" in r else "")
        print(f"sumo.ssm = {m:8s}: loop {r['loop_s']:.2f} s, setup {r['setup_s']:.2f} s, CPU {r['cpu_s']:.2f} s, "
              f"peak {r['peak_rss_mb']:.0f} MB{extra}", flush=True)
        if m == "off":
            d, off = runs["members"], runs["off"]
            print(f"with setup: {(d['loop_s'] + d['setup_s'] + d['conflicts_s']) / (off['loop_s'] + off['setup_s']):.2f}")
            print(f"CPU seconds of the whole process (run with setup, + analysis; robust to a busy machine): "
                  f"{(d['cpu_s'] + d['conflicts_cpu_s']) / off['cpu_s']:.2f}")
            print(f"conflict measurement cost: {(d['loop_s'] + d['conflicts_s']) / off['loop_s']:.2f}", flush=True)
    print("recorded conflicts (default run): " + ", ".join(
        f"{k} {v}" for k, v in d["recorded"].items() if k.startswith("conflict_n")))
    if "all" in runs:
        print(f"device on every vehicle / none: {runs['all']['loop_s'] / off['loop_s']:.2f}")
        _oracle_check(runs["all"], d)
    for r in runs.values():
        shutil.rmtree(Path(r["run_dir"]).parent, ignore_errors=True)


if __name__ == "__main__":
    main()
