"""The speed knobs on the scale case (scenarios/highway/motorway100.toml): what each costs or
saves, and what it changes in the results.

    python benchmarks/speed_knobs.py                       # 20 s after 10 s of warm-up per variant
    python benchmarks/speed_knobs.py --duration 60 --warmup 30

Each variant is one run of the case in a fresh process (one libsumo per process), one after the
other, the same seed, after a short run that compiles the kernels. Per variant: the loop's real-time factor (simulated seconds over the loop's
wall seconds, run.json timing_s), SUMO's step and our layer's time per step [ms], the members on
the road (mean over the recorded steps), and what the results show: the members' mean speed
[m/s], the RMS of their lateral and longitudinal formation error [m], the emergency brakes
(run.json incidents), the background rows recorded per step and the bytes written per
simulated hour. The printed table is the one of docs/performance.md "Speed knobs".

The control runs at 100 Hz in every variant (run.control_step 0.01 s): a longer SUMO step means
more control periods per step, not a slower controller.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
CASE = HERE.parent / "scenarios" / "highway" / "motorway100.toml"

VARIANTS = [
    ("bundled: 0.05 s step, 0.8 m sublanes, SSM off, background within 300 m", {}),
    ("SUMO step 0.1 s", {"run.step": 0.1}),
    ("SUMO step 0.2 s", {"run.step": 0.2}),
    ("sublanes 1.6 m", {"sumo.lateral_resolution": 1.6}),
    ("SSM on (members)", {"sumo.ssm": "members"}),
    ("background within 50 m", {"traffic.record_radius": 50.0}),
    ("background within 1000 m", {"traffic.record_radius": 1000.0}),
]

CHILD = """
import json, sys
from pathlib import Path
from formation_traci.runner import run_scenario
from formation_traci.scenario import load_scenario
case, out, over = sys.argv[1], Path(sys.argv[2]), json.loads(sys.argv[3])
res = run_scenario(load_scenario(Path(case), **over), out, progress=False)
print(json.dumps({"status": res.status, "steps": res.steps_done}))
"""


def measure(out: Path, duration: float) -> dict:
    """The figures of one finished run directory ``out`` (module docstring)."""
    import numpy as np
    import pandas as pd

    meta = json.loads((out / "run.json").read_text())
    timing = meta.get("timing_s", {})
    steps = max(int(round(duration / meta["scenario"]["run"]["step"])), 1)
    loop = sum(timing.values())
    ours = loop - timing.get("sumo_step", 0.0)
    tr = pd.read_parquet(out / "trajectories.parquet")
    m = tr[tr.e_lat.notna()]  # the members' rows (a virtual car's formation error is NaN)
    bg = pd.read_parquet(out / "background.parquet", columns=["t"])
    tables = sum(p.stat().st_size for p in out.rglob("*") if p.is_file() and "sumo" not in p.parts)
    emergencies = meta.get("incidents", {}).get("emergency_brakes", 0)
    return {"rtf": duration / loop if loop else float("nan"),
            "sumo_ms": 1e3 * timing.get("sumo_step", 0.0) / steps, "ours_ms": 1e3 * ours / steps,
            "members": m.groupby("t").size().mean() if len(m) else 0.0,
            "v": float(m.v.mean()) if len(m) else float("nan"),
            "e_lat": float(np.sqrt(np.mean(m.e_lat ** 2))) if len(m) else float("nan"),
            "e_lon": float(np.sqrt(np.mean(m.e_lon ** 2))) if len(m) else float("nan"),
            "emergency": emergencies, "bg_rows": len(bg) / steps,
            "gb_per_h": tables / duration * 3600 / 1e9, "status": meta.get("status")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=20.0, help="simulated seconds per run [s]")
    ap.add_argument("--warmup", type=float, default=10.0, help="SUMO's warm-up per run [s]")
    args = ap.parse_args(argv)
    root = Path(tempfile.mkdtemp(prefix="bench_knobs_"))
    rows = []
    try:  # a first short run compiles the kernels (not counted)
        subprocess.run([sys.executable, "-c", CHILD, str(CASE), str(root / "warm"),
                        json.dumps({"run.duration": 1.0, "traffic.warmup": 1.0})],
                       capture_output=True, text=True, env=os.environ.copy())
        for name, over in VARIANTS:
            over = {**over, "run.duration": args.duration, "traffic.warmup": args.warmup}
            out = root / f"v{len(rows)}"
            proc = subprocess.run([sys.executable, "-c", CHILD, str(CASE), str(out), json.dumps(over)],
                                  capture_output=True, text=True, env=os.environ.copy())
            if proc.returncode != 0 or not (out / "run.json").exists():
                print(f"{name}: failed\n{proc.stderr[-2000:]}", file=sys.stderr)
                return 1
            rows.append((name, measure(out, args.duration)))
            print(f"done: {name}", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    print(f"motorway100, {args.duration:g} s after {args.warmup:g} s of warm-up, seed 1, one run per variant")
    print("| variant | real-time factor | SUMO step [ms] | our layer [ms/step] | members | members' mean v [m/s] "
          "| RMS e_lat [m] | RMS e_lon [m] | emergency brakes | background rows/step | GB per simulated hour | status |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, r in rows:
        print(f"| {name} | {r['rtf']:.3f} | {r['sumo_ms']:.1f} | {r['ours_ms']:.1f} | {r['members']:.0f} | {r['v']:.2f} "
              f"| {r['e_lat']:.3f} | {r['e_lon']:.3f} | {r['emergency']} | {r['bg_rows']:.0f} | {r['gb_per_h']:.2f} "
              f"| {r['status']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
