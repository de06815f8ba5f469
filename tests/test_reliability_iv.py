"""Reliability IV: sweeps that resume, ids that never merge, a warm-up cache that deletes nothing,
no write through a link, bad input refused before anything runs. Each test reproduces one finding
of an adversarial probe (it failed on the code before the fix) with real SUMO and real processes;
docs/reliability.md maps them."""
import json
import signal
from pathlib import Path

import pandas as pd
import pytest

from run_helpers import cli, spawn, wait_for
from test_reliability_ii import free, road
from test_reliability_iii import tree

ROOT = Path(__file__).resolve().parents[1]


def _road_sweep(tmp_path, seeds="[1]", duration=1.0) -> Path:
    base = road(tmp_path, duration=duration, warmup=2.0)
    path = tmp_path / "sweep.toml"
    path.write_text(f'base = "{base}"\nseeds = {seeds}\n')
    return path


# -- 1. sweeps resume ------------------------------------------------------------------------------

def test_a_road_sweep_with_twins_runs_again_and_skips_what_is_done(tmp_path):
    sweep = _road_sweep(tmp_path)
    out = tmp_path / "sw"
    args = ("sweep", sweep, "--out", out, "--no-progress", "--workers", "1", "--baseline")
    code, text = cli(*args)
    assert code == 0, text
    assert (out / "means.csv").is_file() and (out / "effects.csv").is_file() and (out / "twins").is_dir()
    log = next((out / "logs").glob("*.log"))
    code, text = cli(*args)
    assert code == 0 and "1 done before" in text, text
    assert log.read_text().count("--- ") == 1  # the finished case (and its twin) not run again


def test_a_road_sweep_stopped_by_sigterm_resumes_to_the_same_summary(tmp_path):
    sweep = _road_sweep(tmp_path, "[1, 2, 3]", duration=3.0)
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    code, text = cli("sweep", sweep, "--out", whole, "--no-progress", "--workers", "1")
    assert code == 0, text
    proc = spawn("sweep", sweep, "--out", cut, "--no-progress", "--workers", "1")
    try:
        assert wait_for(lambda: len(list((cut / "cases").glob("*/case.json"))) >= 1, timeout=300)
        assert wait_for(lambda: len(list((cut / "logs").glob("*.log"))) >= 2, timeout=60)
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and "run the same command again" in err, err
    assert set(pd.read_parquet(cut / "summary.parquet")["status"]) != {"completed"}
    code, text = cli("sweep", sweep, "--out", cut, "--no-progress", "--workers", "1")
    assert code == 0 and "done before" in text, text
    assert (cut / "summary.parquet").read_bytes() == (whole / "summary.parquet").read_bytes()
    assert list(pd.read_parquet(cut / "timings.parquet").columns) == ["case_id", "wall_s", "host", "pid"]
