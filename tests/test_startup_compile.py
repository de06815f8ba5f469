"""Issue 30 item 4: one kernel compilation covers every scenario kind. After the main job
(the README's demo scenario, run with a cold numba cache) a maneuver scenario, a [comm]
scenario and a free-space scenario load every kernel from the cache: none prints the
"compiling" notice (formation_traci/kernels.py) again. Before sim/warm.py the maneuver run
compiled the slot planner's kernels and the comm run the channel's."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTICE = "compiling the numba kernels"


def _short(src: str, dst: Path, extra: str = "") -> Path:
    text = (ROOT / src).read_text()
    text = text.replace("warmup = 200.0", "warmup = 5.0").replace("warmup = 120.0", "warmup = 5.0")
    dst.write_text(text + extra)
    return dst


def test_after_the_main_job_no_scenario_kind_compiles_again(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
           "FORMATION_TRACI_CACHE": str(tmp_path / "road")}
    env.pop("NUMBA_DISABLE_JIT", None)

    def run(scenario: Path, name: str) -> str:
        cp = subprocess.run([sys.executable, "-m", "formation_traci.cli", "run", str(scenario),
                             "--out", str(tmp_path / name), "--duration", "0.5", "--no-progress"],
                            env=env, cwd=tmp_path, capture_output=True, text=True, timeout=900)
        assert cp.returncode == 0, cp.stderr
        return cp.stderr

    main = run(_short("scenarios/highway/straight_3lane_light.toml", tmp_path / "main.toml"), "main")
    assert NOTICE in main  # the cold cache compiles: the test really starts from nothing
    comm = "\n[comm]\nbeacon_hz = 10.0\ndelay_s = 0.1\nloss = \"bursty\"\nloss_p = 0.2\nloss_burst = 5.0\n"
    for name, src, extra in (("maneuver", "scenarios/maneuvers/lane_change.toml", ""),
                             ("comm", "scenarios/highway/straight_3lane_light.toml", comm),
                             ("free", "scenarios/thesis/dynamic_case1.toml", "")):
        err = run(_short(src, tmp_path / f"{name}.toml", extra), name)
        assert NOTICE not in err, f"the {name} scenario compiled kernels again:\n{err}"
