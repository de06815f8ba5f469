"""Members cause no SUMO warnings where they pass on-ramps (the bundled on-ramp network and LuST's
on-ramp joining -31622#4), and SUMO's remaining messages are counted by kind and by cause in
run.json ``sumo_messages`` and summed up in one line on the terminal (docs/sumo.md, "SUMO's
speed of a member" and "Lanes that end for a member"). Real SUMO, short runs."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.runner import run_scenario
from formation_traci.scenario import load_scenario
from formation_traci.sumo.messages import KINDS

ROOT = Path(__file__).resolve().parents[1]
LUST = ROOT.parent / "shared" / "realnet" / "LuSTMotorway.net.xml"
MEMBER_KINDS = ("emergency_braking", "lane_end_stop")
"""The warnings SUMO used to give about members placed by moveToXY, none of them a real event."""

ONRAMP = """
name = "onramp-column"
[run]
duration = 48.0
seed = 1
[road]
net = "onramp"
lane = 0
start = 600.0
[leader]
speed = 28.0
[[members]]
id = "a"
slot = { along = 0.0, lanes = 0 }
[[members]]
id = "b"
slot = { along = -20.0, lanes = 0 }
[[members]]
id = "c"
slot = { along = -40.0, lanes = 0 }
[traffic]
warmup = 60.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 1000
[[traffic.flows]]
id = "ramp"
route = ["ramp", "mw_accel", "mw_down"]
veh_per_hour = 900
"""
"""A 3-car column in the merge lane of the bundled on-ramp network: the head reaches the merge
(x = 1,500 m) at ~32 s and the end of the acceleration lane (x = 1,800 m) at ~43 s."""

LUST_RAMP = f"""
name = "lust-on-ramp"
[run]
duration = 40.0
seed = 1
[road]
net = "{LUST}"
route = {{ from = "-31622#2", to = "-31622#6" }}
lane = 1
start = 1500.0
[leader]
speed = 30.0
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
warmup = 30.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 1000
[[traffic.flows]]
id = "ramp"
veh_per_hour = 900
route = {{ from = "-30426", to = "-31622#6" }}
"""
"""Three abreast through the junctions of -31622#2's exit, -31622#3 and the on-ramp joining
-31622#4 (s ~ 1,440-2,160 m, t ~ 0-22 s). The right member's lane 1 of the on-ramp edge runs on
as lane 0, but its own connection (1 -> 1) is closed to the members: SUMO used to stop it at that
lane's end ("no connection to the next edge", decel=126) and then report emergency braking of
68-257 m/s^2 for it, and 4 more for 'left' and 'right' on the junctions' internal lanes (21-40
m/s^2: SUMO's speed of the member taken from the distance along its route, which is off by
centimetres there); the run was completed_with_incidents with 6 SUMO emergency brakes."""


def _run(tmp_path: Path, text: str):
    p = tmp_path / "scenario.toml"
    p.write_text(text)
    sc = load_scenario(p, **{"traffic.sections.drain_max": 0.0})
    res = run_scenario(sc, tmp_path / "run", scenario_path=p, progress=False, force=True)
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    ev = pd.read_parquet(tmp_path / "run" / "events.parquet")
    return res, meta, ev


def _check_no_member_warnings(res, meta, ev, members, err: str, lane_end_steps: int = 0):
    msgs = meta["sumo_messages"]
    assert set(msgs) == {k for _, k in KINDS} | {"other"}  # every kind, zeros included
    for kind, by in msgs.items():
        assert set(by) == {"members", "background"}
        assert by["members"] + by["background"] == meta["sumo"]["messages"]["by_kind"].get(kind, 0), kind
    said = ev[ev.kind == "sumo_message"]
    about = said[said.vehicle_id.isin(members)]
    assert about.empty, about.detail.tolist()
    for kind in MEMBER_KINDS:
        assert msgs[kind]["members"] == 0, (kind, msgs[kind])
    assert meta["incidents"]["sumo_emergency_brakes"] == 0
    assert not ev.kind.isin(["member_removed", "move_refused"]).any()
    assert (ev.kind == "placement_mismatch").sum() <= lane_end_steps
    assert "Warning:" not in err  # SUMO's own lines never reach the terminal
    assert sum("SUMO" in line for line in err.splitlines()) <= 1


def test_column_passes_the_bundled_on_ramp_without_member_warnings(tmp_path, capfd):
    res, meta, ev = _run(tmp_path, ONRAMP)
    assert res.status in ("completed", "completed_with_incidents"), res.reason
    traj = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    assert traj[traj.vehicle_id == "c"].x.max() > 1800.0  # the whole column passed the lane's end
    _check_no_member_warnings(res, meta, ev, {"a", "b", "c"}, capfd.readouterr().err)


@pytest.mark.skipif(not LUST.is_file(), reason="needs ../shared/realnet beside the checkout")
def test_three_abreast_pass_lust_on_ramp_without_member_warnings(tmp_path, capfd):
    res, meta, ev = _run(tmp_path, LUST_RAMP)
    assert res.status in ("completed", "completed_with_incidents"), res.reason
    traj = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    assert traj[traj.vehicle_id == "right"].s.max() > 2300.0  # past the on-ramp's junction
    # In the step the right member's front bumper has just passed the end of the on-ramp
    # edge's lane 1 (whose own connection is closed to it) and is still ~2 m beside the internal
    # lane it enters, SUMO maps its moveToXY onto the end of lane 1, up to a step's travel short
    # of where we put it (docs/sumo.md, "Lanes that end for a member"): a placement_mismatch of
    # that one step, the next step on the internal lane, is all that may be recorded
    mism = ev[ev.kind == "placement_mismatch"]
    right = traj[traj.vehicle_id == "right"].set_index("t")
    for t, vid in zip(mism.t, mism.vehicle_id):
        assert vid == "right"
        near = right[(right.index > t - 0.06) & (right.index < t + 0.11)]
        assert near.sumo_gap.max() < 30.0 * 0.05, "at most a step's travel"
        assert near.lane_index.dropna().nunique() == 2, "at the step it leaves its lane"
    _check_no_member_warnings(res, meta, ev, {"right", "centre", "left"}, capfd.readouterr().err,
                              lane_end_steps=1)


def _drive_past_the_acceleration_lane_end(tmp_path: Path, place) -> str:
    """A member car on the bundled on-ramp network, driven by moveToXY at 25 m/s along the lane
    beside the acceleration lane (mw_accel lane 1) 1.0 m right of its centre (its body reaches
    0.15 m into the acceleration lane, which ends at x = 1,800 m), on into mw_down; ``place``:
    the adapter's move of one step. Returns SUMO's messages."""
    from formation_traci.sumo.adapter import MemberType, SumoAdapter
    log = tmp_path / "messages.log"
    ad = SumoAdapter("libsumo")
    ad.start(["-n", str(ROOT / "sumo_nets" / "onramp.net.xml"), "--no-step-log", "true", "--end", "100",
              "--lateral-resolution", "0.8", "--step-length", "0.05", "--no-warnings", "true",
              "--error-log", str(log)])
    try:
        ad.add_route("r", ["mw_accel", "mw_down"])
        mt = MemberType(id="t_car", length=4.6, width=1.8, d_front=2.3, color=(0, 0, 255), vclass="custom1")
        ad.add_member_type(mt)
        x0, y0 = ad.api.simulation.convert2D("mw_accel", 150.0, 1)
        y = y0 - 1.0
        ad.insert_member("m", "r", mt, x0 - 2.3, y, 0.0, 25.0)
        ad.step()
        overlapped = False
        for k in range(1, 160):  # 8 s: 200 m, past x = 1,800 m
            ad.read_members(["m"])
            overlapped |= "m" in ad._overlap
            place(ad, x0 - 2.3 + 1.25 * k, y)
            ad.step()
            ad.set_true_speeds(["m"], np.array([25.0]), np.array([0.0]))
        assert overlapped  # the member did reach into the acceleration lane
        assert ad.api.vehicle.getRoadID("m") == "mw_down"
    finally:
        ad.close()
    return log.read_text()


def test_a_member_reaching_into_an_ending_acceleration_lane_is_not_put_on_it(tmp_path):
    """A member whose body reaches into the neighbour lane is put on that lane before its move
    (SUMO then has it on both lanes, sumo/adapter/__init__.py place); on the acceleration lane in the step
    it passes that lane's end SUMO moved it along a lane with no connection into mw_down and
    warned 'no connection to the next edge'. It is not put on a lane that ends there."""
    said = _drive_past_the_acceleration_lane_end(
        tmp_path, lambda ad, x, y: ad.place(["m"], np.array([x + 2.3]), np.array([y]), np.array([90.0]),
                                            np.array([25.0]), np.array([[x, y]])))
    assert "'m'" not in said, said
