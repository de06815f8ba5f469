"""Start-up time: from process start to the first step, cold and warm.

    python benchmarks/startup.py [--repeat 5] [--root CHECKOUT]

Each measurement is a fresh ``python`` process that runs a scenario for one step (free space:
scenarios/thesis/dynamic_case4_straight.toml; SUMO: scenarios/highway/straight_3lane_light.toml
without warm-up), timed from before the process is spawned to its exit. *Cold*: numba's
on-disk cache (NUMBA_CACHE_DIR) and the road cache (sumo/road_cache.py, below it) empty, so
every kernel compiles and the reference line is fitted; *warm*: the same cache directory again
(kernels and line loaded from disk). Python writes and reads its bytecode (``__pycache__``,
as an installed package has it; PYTHONDONTWRITEBYTECODE is dropped for the child: without
bytecode every module of the package is compiled from source, ~0.1-0.2 s of every start).
Prints one line per case (median of --repeat warm runs) and whether the compile notice was
printed; then, for the warm runs, the time to the first step (issue 18's measure: process
start to the end of the first simulated step, t = 0 -> one step, recorded), the time to the
end of the run (its tables written, SUMO closed; what is left is the interpreter's exit) and
the CPU time of the process
(user + system: less sensitive to other load on a shared machine than wall-clock time).

The next line is the floor any tool built on these libraries pays, measured in turn with the
warm runs (the VM's speed varies up to 2x from minute to minute): a process that imports
numpy, numba and libsumo, starts SUMO on the SUMO case's network and makes one step, no
formation and nothing recorded. What a warm run takes beyond it is this package's share.
The last line (a fixed interface, issue 33) is ``warm start: X.XX s``: the slower case's
median time to the first step. The first warm run after the cold one also writes the side
files of formation_traci/core/kernel_load.py (~50 ms more); the median of >= 3 leaves it out.
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]
CASES = {
    "free space": ("scenarios/thesis/dynamic_case4_straight.toml", {}),
    "sumo": ("scenarios/highway/straight_3lane_light.toml", {"traffic.warmup": 0.0, "traffic.sections.enabled": False}),
}
CHILD = """
import sys, tempfile, time
from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario
from formation_traci.sim.recorder import Recorder
_end_step = Recorder.end_step
def _timed_end_step(self, k, t, report=None):  # the first simulated step (k = 1) is recorded: its wall time
    _end_step(self, k, t, report)
    if k == 1:
        print("FIRST_STEP", time.time())
Recorder.end_step = _timed_end_step
path, extra = sys.argv[1], eval(sys.argv[2])
sc = load_scenario(path, **{"run.duration": 0.05, **extra})
with tempfile.TemporaryDirectory() as d:
    r = run_scenario(sc, d + "/run", scenario_path=path, progress=False, force=True)
    assert r.status == "completed", r.reason
print("END_OF_RUN", time.time())
"""


FLOOR = """
import sys, time
import numpy, numba, libsumo
libsumo.start(["sumo", "-n", sys.argv[1], "--no-step-log", "true", "--step-length", "0.05"])
libsumo.simulationStep()
print("FIRST_STEP", time.time())
libsumo.close()
"""
FLOOR_NET = "sumo_nets/straight3.net.xml"  # the SUMO case's network (straight_3lane_light)


def _stamp(stdout: str, tag: str) -> float:
    """The time.time() a child printed after ``tag`` (its last such line)."""
    return [float(x.split()[1]) for x in stdout.splitlines() if x.startswith(tag)][-1]


def floor_once(root: Path = ROOT) -> float:
    """Wall time [s] from process start to the end of SUMO's first step, for :data:`FLOOR`."""
    t_start = time.time()
    p = subprocess.run([sys.executable, "-c", FLOOR, str(root / FLOOR_NET)], capture_output=True,
                       text=True, cwd=root)
    if p.returncode:
        raise RuntimeError(p.stderr[-2000:])
    return _stamp(p.stdout, "FIRST_STEP") - t_start


class Start(NamedTuple):
    """One start of a case, from process start [s]: to its exit, to the end of the run, to the
    first step; the CPU time of the process [s]; its stderr."""
    exit: float
    end_of_run: float
    first_step: float
    cpu: float
    stderr: str


def once(path: str, extra: dict, cache_dir: str, root: Path = ROOT) -> Start:
    """Run the case ``path`` (with overrides ``extra``) for one step in a fresh process."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir, PYTHONPATH=str(root))
    env.pop("FORMATION_TRACI_CACHE", None)  # the road cache below NUMBA_CACHE_DIR
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # bytecode as in an installed package
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t_start = time.time()
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", CHILD, str(root / path), repr(extra)], env=env,
                       capture_output=True, text=True, cwd=root)
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode:
        raise RuntimeError(p.stderr[-2000:])
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    return Start(wall, _stamp(p.stdout, "END_OF_RUN") - t_start, _stamp(p.stdout, "FIRST_STEP") - t_start,
                 cpu, p.stderr)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="warm runs per case (median)")
    ap.add_argument("--root", type=Path, default=ROOT,
                    help="checkout to measure (default: this one), e.g. another worktree")
    args = ap.parse_args()
    floors = []
    warm_first = {}
    for name, (path, extra) in CASES.items():
        with tempfile.TemporaryDirectory() as cache:
            cold = once(path, extra, cache, args.root)
            warm = []
            for _ in range(args.repeat):
                floors.append(floor_once(args.root))
                warm.append(once(path, extra, cache, args.root))
        med = Start(*(statistics.median(getattr(w, f) for w in warm) for f in Start._fields[:4]), "")
        warm_first[name] = med.first_step
        print(f"{name:10s} cold {cold.exit:6.2f} s  warm {med.exit:6.2f} s  "
              f"compile notice: {'compiling' in cold.stderr.lower()}  "
              f"(warm: {med.first_step:.2f} s to the first step, {med.end_of_run:.2f} s to the end of the run, "
              f"CPU {med.cpu:.2f} s; cold: {cold.first_step:.2f} s to the first step)")
    print(f"floor      numpy + numba + libsumo imported, SUMO started on {FLOOR_NET}, one step: "
          f"{statistics.median(floors):.2f} s to the first step (median of {len(floors)}, "
          f"{min(floors):.2f}-{max(floors):.2f})")
    slow = max(warm_first, key=warm_first.get)
    print(f"warm start: {warm_first[slow]:.2f} s (median of {args.repeat} warm runs, process start to "
          f"the first step, the slower case: {slow})")


if __name__ == "__main__":
    main()
