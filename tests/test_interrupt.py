"""Ctrl-C and SIGTERM stop a real run at the end of a step, flush, and mark run.json."""
import json
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest

SCENARIO = """
name = "long"
[run]
duration = 3000.0
step = 0.05
[vehicle]
model = "kinematic"
[leader]
speed = 20.0
[[members]]
id = "a"
offset = [0.0, 3.5]
position = [-2.0, 2.0]
"""


def _t_end(out):
    try:
        return json.loads((out / "run.json").read_text())["t_end"]
    except (OSError, ValueError, KeyError):
        return 0.0


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_marks_run_interrupted_and_keeps_data(tmp_path, sig):
    sc = tmp_path / "long.toml"
    sc.write_text(SCENARIO)
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "formation_traci.cli", "run", str(sc), "--out", str(out),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while time.time() < deadline and _t_end(out) <= 0:  # simulating: a first part is on disk
        time.sleep(0.05)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    meta = json.loads((out / "run.json").read_text())
    assert meta["status"] == "interrupted"
    assert signal.Signals(sig).name in meta["reason"]
    assert 0 < meta["t_end"] < 3000
    df = pd.read_parquet(out / "trajectories.parquet")
    assert df.t.max() == pytest.approx(meta["t_end"])
    assert len(df) == 2 * (meta["steps_done"] + 1)
    assert "interrupted" in stdout
