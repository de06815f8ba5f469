"""The longitudinal planner's jerk bounds in a dense merge: ``leader.jerk_max`` (0.8 m/s^3 by
default) for every change, ``leader.jerk_brake`` (2.0 m/s^3 by default) while braking grows towards
a request of more than 2 m/s^2, both at most ISO 15622's 2.5 m/s^3.

The merge studies' cases at 900 veh/h on the ramp (bundled on-ramp network, 1,200 veh/h/lane,
``open_gap``), each with the single bound of 0.8 m/s^3 (``jerk_brake = 0.8``, the former planner):

* the 3-car column in the merge lane, seed 2: in the merge area's stop-and-go the vehicle ahead
  brakes and the column's braking, rising at 0.8 m/s^3, falls behind what the closing gap asks:
  every member and the virtual car go into an emergency brake at 45.85 s (requests of 3.06-3.10
  m/s^2, 4 emergency brakes);
* three abreast, seed 1: ``ramp.42`` merges 23 m ahead of the right member at 44.8 s and brakes
  at 2.4-4.5 m/s^2; the right and centre members' braking, rising at 0.8 m/s^3, reaches 2 m/s^2
  only at 47.8 s and their requests pass 3 m/s^2 (9 emergency brakes). With firm braking at 2.0
  m/s^3 that is gone, and a 12 m truck creeping at 0.8 m/s 30 m before the acceleration lane's end
  pushes in 14 m ahead of the right member at 50.8 s (2 emergency brakes, 3.30 and 3.38 m/s^2):
  its own time to the lane's end was beyond the merge horizon, so the yield law never saw it
  (control/merge.py: now the formation's time to reach it counts).

At the defaults neither case has an emergency brake, the members' deceleration stays within
comfortable braking and their 1 s mean jerk within 2.5 m/s^3."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.runner import run_scenario
from formation_traci.scenario import ScenarioError, load_scenario

HIGHWAY = Path(__file__).resolve().parents[1] / "scenarios" / "highway"
CASES = {"column": ("onramp_column.toml", 2, 50.0, ("first", "second", "third")),
         "abreast": ("onramp_merge.toml", 1, 60.0, ("right", "centre", "left"))}


def _text(case: str, leader: str = "") -> str:
    name, seed, duration, _ = CASES[case]
    src = (HIGHWAY / name).read_text()
    old = src[src.index("duration = "):].split("\n", 1)[0]
    text = (src.replace(old, f"duration = {duration}").replace("seed = 1", f"seed = {seed}")
               .replace("veh_per_hour = 700", "veh_per_hour = 900")
            + '\n[cooperation]\nmerge = "open_gap"\n')
    assert f"duration = {duration}" in text and f"seed = {seed}" in text and "veh_per_hour = 900" in text
    if leader:
        text = text.replace("[leader]\n", f"[leader]\n{leader}\n")
        assert leader in text
    return text


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_formation_in_a_dense_merge_has_no_emergency_brake_at_the_default_jerk_bounds(tmp_path, case):
    p = tmp_path / "s.toml"
    p.write_text(_text(case))
    res = run_scenario(load_scenario(p), tmp_path / "run", scenario_path=p, progress=False)
    ev = pd.read_parquet(tmp_path / "run" / "events.parquet")
    assert (ev.kind == "emergency_brake").sum() == 0, ev[ev.kind == "emergency_brake"].to_string()
    assert res.status == "completed"
    tr = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    for vid in CASES[case][3]:
        g = tr[tr.vehicle_id == vid].sort_values("t")
        a = g.a_lon.to_numpy()
        assert a.min() > -3.0, vid  # within comfortable braking (leader.decel_max)
        assert np.abs(a[20:] - a[:-20]).max() <= 2.5, vid  # 1 s mean jerk at 20 Hz


@pytest.mark.parametrize("field, value", [("jerk_max", 0.0), ("jerk_max", 3.0), ("jerk_brake", 0.0),
                                          ("jerk_brake", 2.6)])
def test_a_jerk_bound_outside_0_to_2_5_is_bad_input(tmp_path, field, value):
    p = tmp_path / "s.toml"
    p.write_text(_text("column", f"{field} = {value}"))
    with pytest.raises(ScenarioError, match=f"leader.{field}"):
        load_scenario(p)
