"""The exit leave on a real road: on LuST (-31622#2 to -31622#6, 26 m/s, 600 veh/h/lane) three
abreast reshape to a column at 3 s, the column changes lane right at 25 s and member 'a' leaves
by the -31558 exit at s = 1,150 m. The members that stay keep their slots, 'a' is handed over to
SUMO's driver on the exit lane's side and reaches the exit; no member is removed and no
emergency brake of the formation or about a member happens."""
import json
from pathlib import Path

import pandas as pd

from formation_traci.runner import run_scenario
from formation_traci.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
LUST = ROOT.parent / "shared" / "realnet" / "LuSTMotorway.net.xml"

SCENARIO = f"""
name = "lust-exit-leave"
[run]
duration = 42.0
step = 0.05
seed = 2
[road]
net = "{LUST}"
route = {{ from = "-31622#2", to = "-31622#6" }}
lane = 1
start = 200.0
[leader]
speed = 26.0
[[members]]
id = "a"
slot = {{ along = 0.0, lanes = -1 }}
[[members]]
id = "b"
slot = {{ along = 0.0, lanes = 0 }}
[[members]]
id = "c"
slot = {{ along = 0.0, lanes = 1 }}
[[maneuvers]]
kind = "reshape"
at = {{ time = 3.0 }}
slots = [{{ along = 0.0, lanes = 0 }}, {{ along = -20.0, lanes = 0 }}, {{ along = -40.0, lanes = 0 }}]
[[maneuvers]]
kind = "lane_change"
lanes = -1
at = {{ time = 25.0 }}
[[maneuvers]]
kind = "leave"
member = "a"
exit = "-31558"
at = {{ s = 1150.0 }}
[traffic]
warmup = 30.0
[traffic.sections]
drain_max = 0.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 600
"""


def test_the_lust_exit_leave_keeps_every_member_it_should_with_no_emergency_brake(tmp_path):
    p = tmp_path / "exit.toml"
    p.write_text(SCENARIO)
    res = run_scenario(load_scenario(p), tmp_path / "run", scenario_path=p, progress=False)
    assert res.status == "completed", res.reason
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    inc = meta["incidents"]
    assert inc["member_removed"] == inc["emergency_brakes"] == inc["sumo_emergency_brakes"] == 0, inc
    assert inc["member_collisions"] == inc["lane_departures"] == 0, inc
    assert meta["sumo_messages"]["emergency_braking"]["members"] == 0
    ev = pd.read_parquet(tmp_path / "run" / "events.parquet")
    assert not (ev.kind == "member_removed").any()
    done = ev[ev.kind == "maneuver_end"].detail.tolist()
    assert done[:2] == ["reshape", "lane_change"], ev[ev.kind.str.startswith("maneuver")]
    hand = ev[(ev.kind == "handover") & (ev.vehicle_id == "a")]
    assert len(hand) == 1 and "-31558" in hand.detail.iloc[0]
    traj = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    stay = traj[traj.vehicle_id.isin(["b", "c"])]
    assert set(stay.groupby("vehicle_id").t.max().round(1)) == {42.0}  # b and c to the end
