"""Time the traffic analysis of a long synthetic run (600 s, 3 members, 50 vehicles in range).

    python benchmarks/analysis_speed.py [--duration 600] [--vehicles 50]

Prints the analysis time and the number of (member, vehicle, step) pairs it went through.
This timing used to be an assertion in the test suite; timings stay out of tests.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "analysis")]

from analysis.load.run_data import load_run  # noqa: E402
from analysis.runs.summary import compute_run  # noqa: E402
from test_analysis_traffic_run import FAST, long_run_with_traffic  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="run length [s]")
    ap.add_argument("--vehicles", type=int, default=50, help="background vehicles in range")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        run = long_run_with_traffic(Path(tmp) / "long", args.duration, args.vehicles)
        data = load_run(run)
        t0 = time.perf_counter()
        a = compute_run(data, FAST)
        elapsed = time.perf_counter() - t0
    print(f"traffic analysis: {elapsed:.2f} s for {a.traffic.run['n_pairs']} pairs "
          f"({args.duration:.0f} s run, {args.vehicles} vehicles)")


if __name__ == "__main__":
    main()
