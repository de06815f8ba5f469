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


# -- 2. ids unique over the whole run ----------------------------------------------------------------
FLOWS = """
name = "ids"
[run]
duration = 2.0
seed = 1
[road]
net = "straight3"
lane = 1
start = 300.0
[leader]
speed = 30.0
[[members]]
id = "{top}"
slot = {{ along = 0.0, lanes = 0 }}
[[formations]]
id = "{fid}"
start = 600.0
leader = {{ speed = 30.0 }}
members = [{{ id = "{fmember}", slot = {{ along = 0.0, lanes = 0 }} }}]
[[formation_flows]]
id = "ff"
lane = 0
start = 900.0
period_s = 10.0
[formation_flows.formation]
leader = {{ speed = 28.0 }}
members = [{{ id = "m", slot = {{ along = 0.0, lanes = 0 }} }}]
[traffic]
warmup = 0.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 600
"""


@pytest.mark.parametrize("ids, words", [
    (dict(fid="ff.0"), ["formations.0.id 'ff.0'", "formation flow 'ff'"]),
    (dict(fmember="vc"), ["formations.0.members.0.id", "reserved for the virtual car"]),
    (dict(fmember="ff.3.m"), ["formations.0.members.0.id 'ff.3.m'", "formation_flows.0.formation.members.0.id"]),
    (dict(top="main.2"), ["members.0.id 'main.2'", "traffic flow 'main'"]),
    (dict(fmember="main.17"), ["formations.0.members.0.id 'main.17'", "traffic.flows.0.id"]),
], ids=["formation-vs-flow", "vc-in-formations", "member-vs-flow-member", "member-vs-background",
        "formation-member-vs-background"])
def test_ids_that_clash_anywhere_in_the_run_are_bad_input_naming_both(tmp_path, ids, words):
    sc = tmp_path / "ids.toml"
    sc.write_text(FLOWS.format(**{"top": "a", "fid": "g", "fmember": "b", **ids}))
    before = tree(tmp_path)
    code, text = cli("run", sc, "--out", tmp_path / "out", "--no-progress")
    assert code == 2 and "Traceback" not in text, text
    assert all(w in text for w in words), text
    assert tree(tmp_path) == before


def test_distinct_ids_of_formations_flows_and_traffic_still_load(tmp_path):
    from formation_traci.scenario import load_scenario

    sc = tmp_path / "ids.toml"
    sc.write_text(FLOWS.format(top="main", fid="ff1", fmember="main.x"))  # no vehicle is named so
    assert [f.id for f in load_scenario(sc).formations] == ["ff1"]
