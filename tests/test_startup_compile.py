"""Issue 30 item 4: one kernel compilation covers every scenario kind. After the main job
(the README's demo scenario, run with a cold numba cache) a maneuver scenario, a [comm]
scenario and a free-space scenario load every kernel from the cache: none prints the
"compiling" notice (formation_traci/core/kernels.py) again. Before sim/warm.py the maneuver run
compiled the slot planner's kernels and the comm run the channel's.

The four runs are real processes of their own (their own numba cache and road cache, nothing
shared with this process) that take ~70 s, nearly all of it the main job's cold compilation on
one core. So that the rest of the suite need not wait for them, tests/conftest.py starts them
in the background when this test is collected (:func:`start`); the test waits for them and
checks what they printed. Run alone, the test starts them itself."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTICE = "compiling the numba kernels"
COMM = "\n[comm]\nbeacon_hz = 10.0\ndelay_s = 0.1\nloss = \"bursty\"\nloss_p = 0.2\nloss_burst = 5.0\n"
RUNS = (("main", "scenarios/highway/straight_3lane_light.toml", ""),
        ("maneuver", "scenarios/maneuvers/lane_change.toml", ""),
        ("comm", "scenarios/highway/straight_3lane_light.toml", COMM),
        ("free", "scenarios/thesis/dynamic_case1.toml", ""))
"""The main job first, then one scenario of every other kind: (name, scenario, appended text)."""
TIMEOUT_S = 900.0
"""Each run's limit, as before (a cold compilation on a busy machine is slow) [s]."""


def _short(src: str, dst: Path, extra: str = "") -> Path:
    text = (ROOT / src).read_text()
    text = text.replace("warmup = 200.0", "warmup = 5.0").replace("warmup = 120.0", "warmup = 5.0")
    dst.write_text(text + extra)
    return dst


class Runs:
    """The four runs, one after the other in a thread, in a directory of their own (the
    numba cache, the road cache, the scenarios and the outputs); a run that fails ends the
    sequence. ``results``: name -> (exit code, stderr)."""

    def __init__(self):
        self.dir = Path(tempfile.mkdtemp(prefix="formation-traci-startup-"))
        self.env = {**os.environ, "NUMBA_CACHE_DIR": str(self.dir / "numba"),
                    "FORMATION_TRACI_CACHE": str(self.dir / "road")}
        self.env.pop("NUMBA_DISABLE_JIT", None)
        self.results: dict[str, tuple[int, str]] = {}
        self._proc = None
        self._stopped = False
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run_all, name="startup-compile", daemon=True)
        self._thread.start()

    def _run_all(self) -> None:
        for name, src, extra in RUNS:
            scenario = _short(src, self.dir / f"{name}.toml", extra)
            cmd = [sys.executable, "-m", "formation_traci.cli", "run", str(scenario),
                   "--out", str(self.dir / name), "--duration", "0.5", "--no-progress"]
            with self._lock:
                if self._stopped:
                    return
                self._proc = subprocess.Popen(cmd, env=self.env, cwd=self.dir, stdout=subprocess.PIPE,
                                              stderr=subprocess.PIPE, text=True)
            try:
                _, err = self._proc.communicate(timeout=TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                _, err = self._proc.communicate()
                err += f"\n(killed after {TIMEOUT_S:.0f} s)"
            self.results[name] = (self._proc.returncode, err)
            if self._proc.returncode != 0:
                return

    def wait(self) -> dict[str, tuple[int, str]]:
        self._thread.join(len(RUNS) * TIMEOUT_S + 60.0)
        assert not self._thread.is_alive(), "the runs did not end"
        return self.results

    def stop(self) -> None:
        """End a run still going and remove the directory (the end of the session)."""
        with self._lock:
            self._stopped = True
            if self._proc is not None and self._proc.poll() is None:
                self._proc.kill()
        self._thread.join(60.0)
        shutil.rmtree(self.dir, ignore_errors=True)


_RUNS: list[Runs] = []


def start() -> Runs:
    """The runs of this session, started now if they are not running yet."""
    if not _RUNS:
        _RUNS.append(Runs())
    return _RUNS[0]


def stop() -> None:
    while _RUNS:
        _RUNS.pop().stop()


SESSION_START, SESSION_END = start, stop
"""Called by tests/conftest.py when this test is collected to run, and at the session's end."""


def test_after_the_main_job_no_scenario_kind_compiles_again():
    results = start().wait()
    code, main = results["main"]
    assert code == 0, main
    assert NOTICE in main  # the cold cache compiles: the test really starts from nothing
    for name, _, _ in RUNS[1:]:
        code, err = results[name]
        assert code == 0, err
        assert NOTICE not in err, f"the {name} scenario compiled kernels again:\n{err}"
