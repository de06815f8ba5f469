"""Ramp traffic on a real road: the LuST motorway's on-ramp joining -31622#4 (../shared/realnet, not
copied into the project; the test fails, it does not skip, without it). A 3-car column in the
lane the ramp joins (12 m apart) or three abreast pass the join among 1,200 veh/h/lane with
900 veh/h on the ramp, ``[cooperation] merge`` = "open_gap" or "shift" (docs/maneuvers.md, "Ramp
traffic"). Real SUMO; each run 40 s of formation after 30 s of traffic, from s = 1,400 m at
26 m/s (the join starts at s = 2,061 m, reached after ~25 s); ~5 s a run.

What holds: no emergency brake of the formation, no member collision, no member removed, and
the ramp vehicles are observed (run.json ``merges``), in the runs below. On this network the
acceleration lane runs on as -31622#4's lane 0, and the merge lane and the lane to its left both
run into -31622#4's lane 1 (the lane to the left must give way): a column that shifted left
moved into the lane a ramp vehicle that had moved into the merge lane came into (seed 3:
emergency brakes of b, c and the virtual car at 30.15 s, 7 m/s^2; member collisions from
30.25 s, clearance down to -1.84 m; members removed at 39 s). The join now says so
(road/ramps.py ``left_merges``) and ``shift`` yields there as ``open_gap`` does."""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
import sumolib

from formation_traci.road.ramps import ramp_joins
from formation_traci.runner import run_scenario
from formation_traci.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
LUST = ROOT.parent / "shared" / "realnet" / "LuSTMotorway.net.xml"
JOIN = "-31622#4-AddedOnRampEdge"

HEAD = """
name = "lust-merge-{shape}-{mode}"
[run]
duration = 40.0
step = 0.05
seed = {seed}
[road]
net = "{net}"
route = {{ from = "-31622#2", to = "-31622#6" }}
lane = {lane}
start = 1400.0
[leader]
speed = 26.0
"""
SHAPES = {  # road.lane, (member, along, lanes)
    "column": (0, (("a", 0.0, 0), ("b", -12.0, 0), ("c", -24.0, 0))),
    "abreast": (1, (("a", 0.0, -1), ("b", 0.0, 0), ("c", 0.0, 1))),
}
TAIL = """
[traffic]
warmup = 30.0
[traffic.sections]
drain_max = 0.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 1200
[[traffic.flows]]
id = "ramp"
route = ["-30426", "-31622#4-AddedOnRampEdge", "-31622#4"]
veh_per_hour = 900
[cooperation]
merge = "{mode}"
"""
MEMBERS = ("a", "b", "c")


def scenario(shape: str, mode: str, seed: int) -> str:
    lane, members = SHAPES[shape]
    return (HEAD.format(shape=shape, mode=mode, seed=seed, net=LUST, lane=lane)
            + "".join(f'[[members]]\nid = "{m}"\nslot = {{ along = {along}, lanes = {k} }}\n'
                      for m, along, k in members)
            + TAIL.format(mode=mode))


_RUNS: dict = {}


def _run(tmp_path_factory, shape: str, mode: str, seed: int):
    key = (shape, mode, seed)
    if key not in _RUNS:
        assert LUST.is_file(), f"needs {LUST} (the repository cloned beside shared/)"
        d = tmp_path_factory.mktemp(f"{shape}-{mode}-{seed}")
        p = d / "s.toml"
        p.write_text(scenario(shape, mode, seed))
        res = run_scenario(load_scenario(p), d / "run", scenario_path=p, progress=False)
        _RUNS[key] = (res, json.loads((d / "run" / "run.json").read_text()),
                      pd.read_parquet(d / "run" / "events.parquet"))
    return _RUNS[key]


def _assert_clean(res, meta, mode):
    inc = meta["incidents"]
    assert res.status == "completed", (res.reason, inc)
    assert inc["emergency_brakes"] == inc["member_collisions"] == inc["member_removed"] == 0, inc
    assert inc["sumo_emergency_brakes"] == inc["lane_departures"] == 0, inc
    assert meta["sumo_messages"]["emergency_braking"]["members"] == 0
    assert meta["sumo_messages"]["collision"]["members"] == 0
    merges = meta["merges"]
    assert merges["mode"] == mode
    seen = merges["by_formation"]["f0"]
    assert seen["ramp_vehicles"] >= 5, seen  # the ramp vehicles that joined while the formation was near
    assert seen["merged_before_lane_end"] == seen["ramp_vehicles"], seen
    assert 0.0 <= seen["ramp_speed_loss_mps"] < 2.0, seen


def test_the_join_runs_the_acceleration_lane_on_as_the_right_lane_and_merges_the_two_beside_it():
    """The topology behind the column's failed shift: the acceleration lane (index 0 of the
    four) goes on as -31622#4's lane 0; the merge lane (1) and the lane to its left (2, a minor
    link: it gives way) both go on as lane 1."""
    net = sumolib.net.readNet(str(LUST), withInternal=True)
    out = {}
    for lane in net.getEdge(JOIN).getLanes():
        for c in lane.getOutgoing():
            if c.getToLane().getEdge().getID() == "-31622#4":
                out[lane.getIndex()] = (c.getToLane().getIndex(), c.getState())
    assert out == {0: (0, "M"), 1: (1, "M"), 2: (1, "m"), 3: (2, "M")}
    joins = [j for j in ramp_joins(net, ["-31622#3", JOIN, "-31622#4"]) if j.added_lane]
    assert [(j.merge_index, j.left_merges) for j in joins] == [(1, True)]


@pytest.mark.parametrize("shape, mode, seed, answer", [
    pytest.param("column", "open_gap", 3, "open_gap: acceleration cap ", id="column-open_gap-s3"),
    pytest.param("abreast", "open_gap", 3, "open_gap: acceleration cap ", id="abreast-open_gap-s3"),
    pytest.param("abreast", "shift", 3, "no shift (the lane to the left merges with the merge lane at the join's end); "
                 "open_gap: acceleration cap ", id="abreast-shift-s3"),
    pytest.param("column", "shift", 3, "no shift (the lane to the left merges with the merge lane at the join's end); "
                 "open_gap: acceleration cap ", id="column-shift-s3"),
])
def test_the_formation_yields_to_the_ramp_vehicle_in_conflict_and_passes_the_join_clean(
        tmp_path_factory, shape, mode, seed, answer):
    res, meta, ev = _run(tmp_path_factory, shape, mode, seed)
    _assert_clean(res, meta, mode)
    starts = ev[ev.kind == "merge_yield_start"]
    assert len(starts) == 1 and starts.detail.iloc[0].startswith(answer), starts.detail.tolist()
    ended = ev[(ev.kind == "merge_yield_end") & (ev.other_id == starts.other_id.iloc[0])]
    assert ended.detail.tolist() == ["merged"]
    assert not (ev.kind == "maneuver_start").any()


def test_a_column_with_shift_never_shifts_at_this_join_and_passes_it_clean(tmp_path_factory):
    """Seed 2: the ramp vehicle in conflict with the column is yielded to as with open_gap."""
    res, meta, ev = _run(tmp_path_factory, "column", "shift", 2)
    _assert_clean(res, meta, "shift")
    assert not (ev.kind == "maneuver_start").any()
    starts = ev[ev.kind == "merge_yield_start"]
    assert all(d.startswith("no shift (") for d in starts.detail), starts.detail.tolist()
