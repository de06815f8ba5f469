"""A close column brakes as one when a car cuts in ahead of it (found with issue 20's
column_energy scenario: on main the second car ran into the first, 32 collision events)."""
from pathlib import Path

import numpy as np
import pandas as pd

from formation_traci.scenario import load_scenario
from formation_traci.control.governor import column_caps
from formation_traci.runner import run_scenario

INF = np.inf


def test_column_caps_pass_the_tightest_cap_down_each_column():
    # a column in lane 0 (a ahead of b ahead of c), a car d beside b in the next lane
    slot_s = np.array([0.0, -6.9, -13.8, -6.9])
    slot_d = np.array([0.0, 0.0, 0.0, 3.2])
    half_w = np.full(4, 0.9)
    v_cap = np.array([20.0, INF, 24.0, INF])
    a_cap = np.array([-3.0, INF, INF, INF])
    v, a = column_caps(slot_s, slot_d, half_w, np.ones(4, bool), v_cap, a_cap)
    np.testing.assert_array_equal(v, [20.0, 20.0, 20.0, INF])
    np.testing.assert_array_equal(a, [-3.0, -3.0, -3.0, INF])
    # a member no longer on the road passes nothing on
    v, a = column_caps(slot_s, slot_d, half_w, np.array([False, True, True, True]), v_cap, a_cap)
    np.testing.assert_array_equal(v, [20.0, INF, 24.0, INF])
    np.testing.assert_array_equal(a, [-3.0, INF, INF, INF])


SCENARIO = """
name = "column-cut-in"
[run]
duration = 52.0
seed = 1
[road]
net = "straight3"
lane = 1
start = 300.0
[leader]
speed = 25.0
[[members]]
id = "a"
slot = { along = 0.0, lanes = 0 }
[[members]]
id = "b"
slot = { along = -6.9, lanes = 0 }
[[members]]
id = "c"
slot = { along = -13.8, lanes = 0 }
[traffic]
warmup = 100.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 600
"""


NO_DRAIN = {"traffic.sections.drain_max": 0.0}
"""No drain of the measurement stretch after the formation's last step (sumo/sections.py:
members out, SUMO alone runs on): it records into none of the tables read here."""


def test_cut_in_ahead_of_a_close_column_causes_no_collision(tmp_path):
    """Three cars 2.3 m apart at 25 m/s; at t = 48.1 s a car cuts in 24 m ahead of the first.
    The first member's caps reach the others, so the column falls back as one: no collision,
    bumper gaps within 5 cm of 2.3 m (on main: b hit a at t = 49.75 s)."""
    path = tmp_path / "cut_in.toml"
    path.write_text(SCENARIO)
    res = run_scenario(load_scenario(path, **NO_DRAIN), tmp_path / "run", scenario_path=path, progress=False)
    assert res.status == "completed", res.reason
    ev = pd.read_parquet(tmp_path / "run" / "events.parquet")
    assert (ev.kind == "cut_in").any()  # the situation really happens
    assert not (ev.kind == "collision").any(), ev[ev.kind == "collision"].head()
    t = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    p = {m: t[t.vehicle_id == m][["x", "y"]].to_numpy() for m in "abc"}
    for front, back in (("a", "b"), ("b", "c")):
        gap = np.hypot(*(p[front] - p[back]).T) - 4.6
        assert np.all(np.abs(gap - 2.3) < 0.05), (front, back, gap.min())
