"""A ramp car that merges ahead of the formation and then brakes (the bundled on-ramp
network, three abreast, 1,200 veh/h/lane, 600 veh/h on the ramp, seed 1: the merge study's
case, its first 42 s): ``ramp.28`` moves into the right member's lane at 38.45 s, 33 m ahead at nearly the
member's speed (24.8 against 25.0 m/s), and brakes at 4.5 m/s^2 for half a second.

Before, with ``open_gap``, the right member went into an emergency brake at 38.20 s (its speed
cap asked -4.3 m/s^2 for a car at nearly its own speed) and the virtual car at 39.10 s
(3.02 m/s^2): the yield opened only the ramp driver's 1 s time gap, from which the merged car's
brake was more than the formation's comfortable braking. Now the speed cap of a vehicle whose
speed comfortable braking matches is not below that vehicle's speed (control/governor.py
_cap_floor), and the yield opens the formation's own time gap for a vehicle merging ahead
(control/merge.py ``follow_gap_s``): no emergency brake."""
import json

import pandas as pd
import pytest

from formation_traci.runner import run_scenario
from formation_traci.scenario import load_scenario

ROOT_SCENARIO = "scenarios/highway/onramp_merge.toml"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from pathlib import Path

    src = (Path(__file__).resolve().parents[1] / ROOT_SCENARIO).read_text()
    text = (src.replace("duration = 90.0", "duration = 42.0")  # the cut-in and its brakes by 40 s
               .replace("veh_per_hour = 700", "veh_per_hour = 600")
            + '\n[cooperation]\nmerge = "open_gap"\n')
    assert "duration = 42.0" in text and "veh_per_hour = 600" in text
    d = tmp_path_factory.mktemp("cutin")
    p = d / "s.toml"
    p.write_text(text)
    res = run_scenario(load_scenario(p), d / "run", scenario_path=p, progress=False)
    meta = json.loads((d / "run" / "run.json").read_text())
    return res, meta, pd.read_parquet(d / "run" / "events.parquet")


def test_a_ramp_car_that_merges_ahead_and_brakes_is_followed_without_an_emergency_brake(run):
    res, meta, ev = run
    cut = ev[(ev.kind == "cut_in") & (ev.vehicle_id == "ramp.28")]
    assert len(cut) and cut.other_id.iloc[0] == "right", "the case's cut-in happens"
    assert (ev.kind == "emergency_brake").sum() == 0, ev[ev.kind == "emergency_brake"].to_string()
    assert meta["status"] == "completed"
