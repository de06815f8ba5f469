"""Formations inserted by a flow (issue 27, item 2): a penetration rate of a traffic flow
inserts formations at the asked share of the vehicles entering during the run (within 10 %),
run.json counts requested and inserted formations, each formation is '<flow>.<k>' with its
own rows, and a formation that reaches the end of its route is retired."""
import json

import pandas as pd
import pytest

from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.runner import run_scenario
from formation_traci.sumo.formation_flows import expand_flows, flow_period

SC = """
name = "flow"
[run]
duration = 120.0
seed = 1
[road]
net = "straight3"
lane = 1
start = 300.0
[leader]
speed = 30.0
[[members]]
id = "a"
slot = { along = 0.0, lanes = 0 }
[[formation_flows]]
id = "pen"
lane = 0
start = 3500.0
penetration = 0.1
of_flow = "main"
[formation_flows.formation]
leader = { speed = 28.0 }
members = [{ id = "m1", slot = { along = 0.0, lanes = 0 } }, { id = "m2", slot = { along = -12.0, lanes = 0 } }]
[traffic]
warmup = 30.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 1000
"""


def test_the_period_follows_from_the_share_of_the_flow(tmp_path):
    """p = 0.1 of 3 x 1000 veh/h in formations of 2: 300 formation veh/h, one formation every
    2 x 3600 / 300 = 24 s; the traffic flow keeps 90 % of its demand; 120 s: 5 formations due
    (t = 0, 24, 48, 72, 96 s)."""
    p = tmp_path / "s.toml"
    p.write_text(SC)
    sc = load_scenario(p)
    assert flow_period(sc, sc.formation_flows[0], {"main": 3}) == pytest.approx(24.0)
    run_sc, flow_of, keep, _ = expand_flows(sc, {"main": 3})
    assert [f.depart for f in run_sc.formations] == pytest.approx([0.0, 24.0, 48.0, 72.0, 96.0])
    assert [m.id for m in run_sc.formations[1].members] == ["pen.1.m1", "pen.1.m2"]
    assert set(flow_of.values()) == {"pen"} and keep["main"] == pytest.approx(0.9)


def test_a_traffic_flow_may_be_called_of_flow(tmp_path):
    """The share a traffic flow keeps and the formation flows' sources are apart: a traffic
    flow with the id 'of_flow' keeps 90 % of its demand (it once collided with a reserved key
    and kept all of it)."""
    p = tmp_path / "s.toml"
    p.write_text(SC.replace('"main"', '"of_flow"'))
    run_sc, flow_of, keep, share_of = expand_flows(load_scenario(p), {"of_flow": 3})
    assert keep == {"of_flow": pytest.approx(0.9)} and share_of == {"pen": "of_flow"}


NO_DRAIN = {"traffic.sections.drain_max": 0.0}
"""The runs below end at the formation's last step: SUMO's drain of the measurement stretch
after it (sumo/sections.py, ~half of each run's time) changes none of the files or run.json
entries these tests read (the trajectories, events, comfort and background tables, the flows'
counts, the formations); only run.json 'sections' and SUMO's raw outputs go on with it."""


@pytest.fixture(scope="module")
def grouped(tmp_path_factory):
    """SC (120 s) run once with the group step: the penetration test reads it, the group
    test compares the per-formation path with it. (path, scenario, result, run directory)"""
    d = tmp_path_factory.mktemp("flow")
    p = d / "s.toml"
    p.write_text(SC)
    sc = load_scenario(p, **NO_DRAIN)
    res = run_scenario(sc, d / "run", scenario_path=p, force=True, progress=False)
    return p, sc, res, d / "run"


def test_a_penetration_flow_inserts_its_share_and_retires_at_the_route_end(grouped):
    _, _, res, run = grouped
    assert res.status == "completed", res.reason
    assert res.incidents["member_collisions"] == 0
    meta = json.loads((run / "run.json").read_text())
    counts = meta["formation_flows"]["pen"]
    assert counts["requested"] == 5 and counts["inserted"] == 5 and counts["members_inserted"] == 10
    assert counts["share"] == pytest.approx(0.1, rel=0.1)  # within 10 % of the asked share
    assert meta["scenario"]["formation_flows"][0]["id"] == "pen"  # run.json keeps the scenario as given
    tr = pd.read_parquet(run / "trajectories.parquet")
    ev = pd.read_parquet(run / "events.parquet")
    first = tr[tr.formation_id == "pen.0"]
    assert set(first.vehicle_id) == {"pen.0.m1", "pen.0.m2", "vc:pen.0"}
    # every formation's members are in SUMO after their first step, where we put them
    members = tr[tr.formation_id.str.startswith("pen.") & ~tr.vehicle_id.str.startswith("vc")]
    placed = members[members.t > members.groupby("vehicle_id").t.transform("min")]
    assert placed.sumo_gap.notna().all() and placed.sumo_gap.max() < 0.01
    assert set(placed.lane_index.dropna()) == {0.0}
    # from s = 3500 m at 28 m/s the first formations reach the end of the 6 km route and retire
    retired = ev[ev.kind == "member_retired"]
    assert {"pen.0.m1", "pen.0.m2"} <= set(retired.vehicle_id)
    assert "vc:pen.0" in set(ev[ev.kind == "end_of_road"].vehicle_id)
    assert tr[tr.vehicle_id == "a"].t.max() == pytest.approx(120.0)  # the run goes on


def test_a_flow_needs_exactly_one_rule_and_a_known_flow(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(SC.replace('penetration = 0.1', 'penetration = 0.1\nperiod_s = 10.0'))
    with pytest.raises(ScenarioError, match="exactly one of"):
        load_scenario(p)
    p.write_text(SC.replace('of_flow = "main"', 'of_flow = "side"'))
    with pytest.raises(ScenarioError, match="formation_flows.0.of_flow"):
        load_scenario(p)


def test_the_group_step_equals_the_per_formation_path(grouped, tmp_path, monkeypatch):
    """Plain road formations are stepped as one group (sim/formation_group.py); the loop's
    per-formation path (the group switched off) gives the same files bit for bit, through
    departures, formations waiting for room and retirements at the route end (the group's
    run is the module's 120 s run, the per-formation path runs the same scenario here)."""
    p, sc, res, group = grouped
    import formation_traci.sim.loop as loop
    monkeypatch.setattr(loop, "group_of", lambda forms, world: None)
    alone = run_scenario(sc, tmp_path / "each", scenario_path=p, progress=False)
    assert res.status == alone.status == "completed", (res.reason, alone.reason)
    for name in ("trajectories", "events", "comfort", "background"):
        a = pd.read_parquet(group / f"{name}.parquet")
        b = pd.read_parquet(tmp_path / "each" / f"{name}.parquet")
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    meta = [json.loads((d / "run.json").read_text()) for d in (group, tmp_path / "each")]
    assert meta[0]["formations"] == meta[1]["formations"]
    assert any(f["left_s"] is not None for f in meta[0]["formations"].values())  # some retired


def test_a_waiting_formations_room_check_answers_as_a_full_check(tmp_path, monkeypatch):
    """A formation that found no room keeps the vehicle that blocked it, and while that vehicle
    still overlaps its zones the check reads nothing else (sumo/flow_inserts.py RoomCheck):
    at every check of a run where formations wait in dense traffic, the answer equals a fresh
    check's over every vehicle on the edges around the formation."""
    from formation_traci.sumo.flow_inserts import RoomCheck
    from formation_traci.sumo.world import SumoWorld

    seen = {"calls": 0, "kept": 0, "no": 0, "differ": []}

    def has_room(self, t, rows, state):
        if self._room is None:
            self._room = RoomCheck(self)
        kept = rows.start in self._room._blocked_by
        got = self._room(t, rows, state)
        full = RoomCheck(self)(t, rows, state)
        seen["calls"] += 1
        seen["kept"] += kept and not got
        seen["no"] += not got
        if got != full:
            seen["differ"].append((t, rows.start, got, full))
        return got

    monkeypatch.setattr(SumoWorld, "has_room", has_room)
    p = tmp_path / "s.toml"
    p.write_text(SC.replace("veh_per_hour_per_lane = 1000", "veh_per_hour_per_lane = 1900")
                 .replace("penetration = 0.1", "penetration = 0.2").replace("start = 3500.0", "start = 700.0"))
    sc = load_scenario(p, **{**NO_DRAIN, "run.duration": 40.0})
    res = run_scenario(sc, tmp_path / "run", scenario_path=p, force=True, progress=False)
    assert res.status in ("completed", "completed_with_incidents"), res.reason
    assert seen["differ"] == []
    assert seen["no"] >= 50 and seen["kept"] >= 0.5 * seen["no"], seen  # formations waited
