"""Start-up time: from process start to the end of the first recorded step, cold and warm.

    python benchmarks/startup.py [--repeat 2] [--root CHECKOUT]

Each measurement is a fresh ``python`` process that runs a scenario for one step (free space:
scenarios/thesis/dynamic_case4_straight.toml; SUMO: scenarios/highway/straight_3lane_light.toml
without warm-up), timed from before the process is spawned to its exit. *Cold*: numba's
on-disk cache (NUMBA_CACHE_DIR) empty, so every kernel compiles; *warm*: the same cache
directory again (kernels loaded from disk). Prints one line per case (median of --repeat
warm runs) and whether the compile notice was printed.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = {
    "free space": ("scenarios/thesis/dynamic_case4_straight.toml", {}),
    "sumo": ("scenarios/highway/straight_3lane_light.toml", {"traffic.warmup": 0.0}),
}
CHILD = """
import sys, tempfile
from formation_traci.scenario import load_scenario
from formation_traci.sim.runner import run_scenario
path, extra = sys.argv[1], eval(sys.argv[2])
sc = load_scenario(path, **{"run.duration": 0.05, **extra})
with tempfile.TemporaryDirectory() as d:
    r = run_scenario(sc, d + "/run", scenario_path=path, progress=False, force=True)
    assert r.status == "completed", r.reason
"""


def once(path: str, extra: dict, cache_dir: str, root: Path = ROOT) -> tuple[float, str]:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir, PYTHONPATH=str(root))
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", CHILD, str(root / path), repr(extra)], env=env,
                       capture_output=True, text=True, cwd=root)
    wall = time.perf_counter() - t0
    if p.returncode:
        raise RuntimeError(p.stderr[-2000:])
    return wall, p.stderr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="warm runs per case (median)")
    ap.add_argument("--root", type=Path, default=ROOT,
                    help="checkout to measure (default: this one), e.g. another worktree")
    args = ap.parse_args()
    for name, (path, extra) in CASES.items():
        with tempfile.TemporaryDirectory() as cache:
            cold, err = once(path, extra, cache, args.root)
            notice = "compiling" in err.lower()
            warm = statistics.median(once(path, extra, cache, args.root)[0]
                                     for _ in range(args.repeat))
        print(f"{name:10s} cold {cold:6.2f} s  warm {warm:6.2f} s  compile notice: {notice}")


if __name__ == "__main__":
    main()
