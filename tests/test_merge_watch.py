"""Ramp traffic at the route's joins (sumo/merge_watch.py, control/merge.py) on the bundled
on-ramp network: the formation sees the ramp vehicles that reach the merge within the horizon;
``open_gap`` caps the virtual car's requested acceleration while it yields (merge_yield_start
and merge_yield_end events naming the ramp vehicle), ``none`` only observes; run.json carries
what the ramp vehicles did; a mode the tool does not have is bad input."""
import json

import pandas as pd
import pytest

from formation_traci.runner import run_scenario
from formation_traci.scenario import ScenarioError, load_scenario
from run_helpers import cli

BASE = """
name = "merge-watch"
[run]
duration = 45.0
seed = 1
[road]
net = "onramp"
lane = 1
start = 600.0
[leader]
speed = 28.0
[[members]]
id = "right"
slot = {{ along = 0.0, lanes = -1 }}
[[members]]
id = "centre"
slot = {{ along = 0.0, lanes = 0 }}
[[members]]
id = "left"
slot = {{ along = 0.0, lanes = 1 }}
[traffic]
warmup = 150.0
[traffic.sections]
drain_max = 0.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 1200
[[traffic.flows]]
id = "ramp"
route = ["ramp", "mw_accel", "mw_down"]
veh_per_hour = 900
[cooperation]
merge = "{mode}"
"""


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for mode in ("open_gap", "none"):
        d = tmp_path_factory.mktemp(mode)
        p = d / "s.toml"
        p.write_text(BASE.format(mode=mode))
        res = run_scenario(load_scenario(p), d / "run", scenario_path=p, progress=False)
        out[mode] = (res, d / "run")
    return out


def test_open_gap_yields_to_ramp_vehicles_with_paired_events_and_only_lowers_the_request(runs):
    res, out = runs["open_gap"]
    assert res.status in ("completed", "completed_with_incidents"), res.reason
    ev = pd.read_parquet(out / "events.parquet")
    starts = ev[ev.kind == "merge_yield_start"]
    ends = ev[ev.kind == "merge_yield_end"]
    assert len(starts) >= 1
    assert set(starts.vehicle_id) == {"vc"} and set(starts.formation_id) == {"f0"}
    assert all(o.startswith("ramp.") for o in starts.other_id)
    assert set(ends.other_id) <= set(starts.other_id)
    # the same traffic and seed: the runs are the same until the cap first binds (a yield's, or
    # a ramp vehicle's ahead followed), and there the virtual car's acceleration is lower
    vc = {m: pd.read_parquet(o / "trajectories.parquet").query("vehicle_id == 'vc'").set_index("t").a_lon
          for m, (_, o) in runs.items()}
    both = pd.concat(vc, axis=1).dropna()
    differ = both[both["open_gap"] != both["none"]]
    assert len(differ)
    first = differ.iloc[0]
    assert first["open_gap"] < first["none"]


def test_the_ramp_vehicles_are_observed_in_every_mode(runs):
    for mode, (res, out) in runs.items():
        meta = json.loads((out / "run.json").read_text())
        merges = meta["merges"]
        assert merges["mode"] == mode
        f0 = merges["by_formation"]["f0"]
        assert f0["ramp_vehicles"] >= 3
        assert 0 <= f0["merged_before_lane_end"] <= f0["ramp_vehicles"]
        assert f0["ramp_speed_loss_mps"] >= 0.0 and f0["ramp_wait_s"] >= 0.0
    ev = pd.read_parquet(runs["none"][1] / "events.parquet")
    assert not ev.kind.str.startswith("merge_yield").any()


def test_metrics_json_carries_the_merges_per_formation(runs, tmp_path):
    out = runs["open_gap"][1]
    code, text = cli("analyze", out, "--out", tmp_path / "an")
    assert code == 0, text
    doc = json.loads((tmp_path / "an" / "metrics.json").read_text())
    meta = json.loads((out / "run.json").read_text())
    assert doc["merges"] == meta["merges"]["by_formation"]
    assert set(doc["merges"]["f0"]) == {"ramp_vehicles", "merged_before_lane_end", "ramp_speed_loss_mps",
                                        "ramp_wait_s"}


@pytest.mark.parametrize("value", ["zipper", "Shift"])
def test_a_merge_mode_the_tool_does_not_have_is_bad_input(tmp_path, value):
    p = tmp_path / "s.toml"
    p.write_text(BASE.format(mode=value))
    with pytest.raises(ScenarioError, match="cooperation.merge"):
        load_scenario(p)
    code, text = cli("run", p, "--out", tmp_path / "out")
    assert code == 2 and "cooperation.merge" in text and not (tmp_path / "out").exists()


def test_a_sweep_row_sums_the_ramp_vehicles_over_the_formations_and_weights_their_means():
    from formation_traci.sweep.row import merge_values

    meta = {"merges": {"mode": "open_gap", "by_formation": {
        "a": {"ramp_vehicles": 3, "merged_before_lane_end": 2, "ramp_speed_loss_mps": 4.0, "ramp_wait_s": 1.0},
        "b": {"ramp_vehicles": 1, "merged_before_lane_end": 1, "ramp_speed_loss_mps": 8.0, "ramp_wait_s": 0.0},
        "c": {"ramp_vehicles": 0, "merged_before_lane_end": 0, "ramp_speed_loss_mps": None, "ramp_wait_s": None}}}}
    assert merge_values(meta) == {"ramp_vehicles": 4, "ramp_merged_before_lane_end": 3,
                                  "ramp_speed_loss_mps": 5.0, "ramp_wait_s": 0.75}
    assert set(merge_values({}).values()) == {None}


def test_cooperation_in_free_space_is_bad_input(tmp_path):
    p = tmp_path / "free.toml"
    p.write_text('[run]\nduration = 1.0\n[leader]\nspeed = 10.0\n[[members]]\nid = "a"\n'
                 'offset = [0.0, 0.0]\n[cooperation]\nmerge = "open_gap"\n')
    with pytest.raises(ScenarioError, match="cooperation: needs a \\[road\\]"):
        load_scenario(p)
