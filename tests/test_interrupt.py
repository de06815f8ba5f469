"""Ctrl-C and SIGTERM stop a real run at the end of a step, flush, and mark run.json."""
import json
import signal

import pandas as pd
import pytest

from run_helpers import free_toml, meta_of, spawn, wait_for

SCENARIO = free_toml(3000.0, name="long", step=0.05)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_marks_run_interrupted_and_keeps_data(tmp_path, sig):
    sc = tmp_path / "long.toml"
    sc.write_text(SCENARIO)
    out = tmp_path / "run"
    proc = spawn("run", sc, "--out", out, "--no-progress")
    wait_for(lambda: meta_of(out).get("t_end", 0.0) > 0)  # simulating: a first part is on disk
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
