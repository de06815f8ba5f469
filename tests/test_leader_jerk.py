"""``leader.jerk_max``: the longitudinal planner's jerk bound outside emergencies, a scenario
choice (0.8 m/s^3 by default, at most ISO 15622's 2.5 m/s^3).

The merge study's column at 900 veh/h on the ramp, seed 2 (bundled on-ramp network, 1,200
veh/h/lane, ``open_gap``): in the merge area's stop-and-go the leader ahead brakes and the
column's braking, rising at 0.8 m/s^3, falls behind what the closing gap asks: every member and
the virtual car go into an emergency brake at 45.85 s (requests of 3.06-3.10 m/s^2, 4 emergency
brakes; docs/maneuvers.md). At 2.0 m/s^3 the column follows the braking leader in time: no
emergency brake, its deceleration within 2 m/s^2 and its 1 s mean jerk within 2.5 m/s^3."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.runner import run_scenario
from formation_traci.scenario import ScenarioError, load_scenario

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "highway" / "onramp_column.toml"


def _text(jerk: float | None) -> str:
    src = SCENARIO.read_text()
    text = (src.replace("duration = 90.0", "duration = 50.0").replace("seed = 1", "seed = 2")
               .replace("veh_per_hour = 700", "veh_per_hour = 900")
            + '\n[cooperation]\nmerge = "open_gap"\n')
    assert "duration = 50.0" in text and "seed = 2" in text and "veh_per_hour = 900" in text
    if jerk is not None:
        text = text.replace("[leader]\n", f"[leader]\njerk_max = {jerk}\n")
        assert f"jerk_max = {jerk}" in text
    return text


def test_a_column_that_follows_a_braking_leader_at_2_m_s3_has_no_emergency_brake(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(_text(2.0))
    res = run_scenario(load_scenario(p), tmp_path / "run", scenario_path=p, progress=False)
    ev = pd.read_parquet(tmp_path / "run" / "events.parquet")
    assert (ev.kind == "emergency_brake").sum() == 0, ev[ev.kind == "emergency_brake"].to_string()
    assert res.status == "completed"
    tr = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    for vid in ("first", "second", "third"):
        g = tr[tr.vehicle_id == vid].sort_values("t")
        a = g.a_lon.to_numpy()
        assert a.min() > -2.0, vid
        assert np.abs(a[20:] - a[:-20]).max() <= 2.5, vid  # 1 s mean jerk at 20 Hz


@pytest.mark.parametrize("value", [0.0, 3.0])
def test_a_jerk_bound_outside_0_to_2_5_is_bad_input(tmp_path, value):
    p = tmp_path / "s.toml"
    p.write_text(_text(value))
    with pytest.raises(ScenarioError, match="leader.jerk_max"):
        load_scenario(p)
