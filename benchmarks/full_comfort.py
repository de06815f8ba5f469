"""Issue 19's comfort bounds at full duration: every bundled highway scenario, run as bundled
(warm-up and duration unchanged), each member's jerk p95 and 1-s averaged jerk peak outside
emergencies (analysis metrics `jerk_lon_p95_mps3`, `jerk_lon_1s_peak_mps3`).

    python benchmarks/full_comfort.py [OUT_DIR]     # about 10 minutes on 2 cores
"""
from __future__ import annotations

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def one(path: Path, out: Path) -> tuple[str, list[tuple[str, float, float]]]:
    run_dir = out / path.stem
    subprocess.run([sys.executable, "-m", "formation_traci.cli", "run", str(path), "--out",
                    str(run_dir), "--force", "--no-progress"], check=True, capture_output=True)
    from analysis import analyze_run
    res = analyze_run(run_dir, figures=False)
    m = res.members
    return path.stem, [(str(i), float(r["jerk_lon_p95_mps3"]), float(r["jerk_lon_1s_peak_mps3"]))
                       for i, r in m.iterrows()]


def main() -> int:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/full_comfort")
    paths = sorted((ROOT / "scenarios" / "highway").glob("*.toml"))
    worst = 0.0, 0.0
    with ThreadPoolExecutor(2) as pool:
        for name, rows in pool.map(lambda p: one(p, out), paths):
            for mid, p95, j1 in rows:
                print(f"{name:24s} {mid:10s} jerk p95 {p95:5.2f}  1-s peak {j1:5.2f} m/s^3")
                worst = max(worst[0], p95), max(worst[1], j1)
    ok = worst[0] <= 1.0 and worst[1] <= 2.5
    print(f"worst: jerk p95 {worst[0]:.2f} (bound 1.0), 1-s peak {worst[1]:.2f} (bound 2.5): "
          f"{'within' if ok else 'OUTSIDE'} issue 19's bounds")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
