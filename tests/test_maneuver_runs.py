"""Bundled maneuver scenarios on real, shortened SUMO runs (libsumo, no mocks)."""
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.scenario import load_scenario
from formation_traci.sim.runner import run_scenario

ROOT = Path(__file__).resolve().parents[1]
MANEUVERS = ROOT / "scenarios" / "maneuvers"
MEDIUM_COMFORT = 3.6  # m/s^2, the seed's medium-comfort lateral band


def _run(tmp_path, name, **overrides):
    path = MANEUVERS / f"{name}.toml"
    sc = load_scenario(path, **overrides)
    res = run_scenario(sc, tmp_path / name, scenario_path=path, progress=False, force=True)
    out = tmp_path / name
    assert res.status == "completed", res.reason
    ev = pd.read_parquet(out / "events.parquet")
    traj = pd.read_parquet(out / "trajectories.parquet")
    bg = pd.read_parquet(out / "background.parquet")
    return json.loads((out / "run.json").read_text()), ev, traj, bg


def _intervals(ev, kind):
    """(start, end) of every completed maneuver of ``kind`` from the events."""
    m = ev[ev.kind.isin(["maneuver_start", "maneuver_end"]) & ev.detail.str.startswith(kind)]
    starts = m[m.kind == "maneuver_start"].t.to_numpy()
    ends = m[m.kind == "maneuver_end"].t.to_numpy()
    assert len(starts) == len(ends) and len(starts) > 0, m
    assert np.all(ends >= starts)
    return list(zip(starts, ends))


def _common_checks(meta, ev, traj, kind, n_maneuvers):
    ids = {m["id"] for m in meta["members"]}
    coll = ev[ev.kind == "collision"]
    assert not (coll.vehicle_id.isin(ids) | coll.other_id.isin(ids)).any(), coll
    spans = _intervals(ev, kind)
    assert len(spans) == n_maneuvers
    members = traj[traj.vehicle_id.isin(ids)]
    for t0, t1 in spans:
        during = members[(members.t >= t0) & (members.t <= t1)]
        assert len(during) and during.a_lat.abs().max() < MEDIUM_COMFORT
    return spans, members


def test_lanedrop_reshape_abreast_column_abreast(tmp_path):
    """Three abreast close into a column before the lane drop (no member in the ending lane
    when it ends), then open to two abreast and one behind after it (two reshapes); slot
    indices follow the assignment."""
    meta, ev, traj, _ = _run(tmp_path, "lanedrop_reshape", **{
        "road.start": 1750.0, "traffic.warmup": 60.0, "run.duration": 60.0})
    (a0, a1), (b0, b1), (c0, c1) = _common_checks(meta, ev, traj, "reshape", 3)[0]
    m = traj[traj.vehicle_id.isin(["left", "centre", "right"])]
    column = m[(m.t > a1 + 2.0) & (m.t < b0)]
    np.testing.assert_allclose(column.d, 0.0, atol=0.3)  # all in the reference lane
    assert sorted(column.groupby("vehicle_id").slot.first()) == [0, 1, 2]
    assert column[column.vehicle_id == "centre"].slot.iloc[0] == 0  # kept its place in front
    drop = m[(m.s > 2400) & (m.s < 2490)]  # the ending lane (d = -3.5 m) ends at 2496 m
    assert len(drop) and (drop.lane_index == 1).all() and (drop.d.abs() < 0.3).all()
    after = m[m.t > c1 + 2.0]
    d_end = after.groupby("vehicle_id").d.last().sort_values()
    np.testing.assert_allclose(d_end.to_numpy(), [0.0, 0.0, 3.5], atol=0.3)


def test_lane_change_postponed_while_target_lane_occupied_then_done(tmp_path):
    meta, ev, traj, bg = _run(tmp_path, "lane_change_blocked")
    ((t0, t1),), members = _common_checks(meta, ev, traj, "lane_change", 1)
    post = ev[ev.kind == "maneuver_postponed"]
    assert len(post) == 1 and post.t.iloc[0] == pytest.approx(2.0) and t0 > post.t.iloc[0] + 5.0
    blocker = post.detail.iloc[0].split("no room: ")[1].split()[0]
    # the named vehicle really is in the target (left) lane near the formation then
    b = bg[(bg.vehicle_id == blocker) & (bg.t == post.t.iloc[0])]
    front = members[(members.vehicle_id == "front") & (members.t == post.t.iloc[0])].s.iloc[0]
    assert len(b) and abs(b.d.iloc[0] - 3.5) < 1.0 and abs(b.s.iloc[0] - front) < 80.0
    before = members[members.t < t0]
    np.testing.assert_allclose(before.d, 0.0, atol=0.05)
    after = members[members.t > t1 + 2.0]
    np.testing.assert_allclose(after.d, 3.5, atol=0.2)
    assert (after.lane_index == 2).all()


def test_lane_change_triggered_by_the_queue_behind(tmp_path):
    """The formation moves right when more than 3 vehicles queue within 150 m behind it."""
    meta, ev, traj, bg = _run(tmp_path, "lane_change", **{"run.duration": 30.0, "traffic.warmup": 60.0})
    ((t0, t1),), members = _common_checks(meta, ev, traj, "lane_change", 1)
    rear = members[(members.vehicle_id == "rear")].set_index("t").s
    due = ev[ev.kind.isin(["maneuver_start", "maneuver_postponed"])].t.min()
    g = bg[np.isclose(bg.t, due)]
    front_bumper = g.s + g.length / 2
    r = rear.loc[rear.index[np.isclose(rear.index, due)][0]] - 4.6 / 2
    queued = (front_bumper <= r) & (front_bumper >= r - 150.0) & (g.d.abs() < 1.75)
    assert queued.sum() > 3
    after = members[members.t > t1 + 2.0]
    np.testing.assert_allclose(after.d, -3.5, atol=0.2)


def test_leave_hands_the_member_over_to_sumo_without_a_jump(tmp_path):
    """The leaving member is driven on by SUMO from its lane, position and speed: no speed
    jump above 0.5 m/s, no lane jump, and it keeps driving (background rows) to the end."""
    meta, ev, traj, bg = _run(tmp_path, "leave")
    ids = {m["id"] for m in meta["members"]}
    coll = ev[ev.kind == "collision"]
    assert not (coll.vehicle_id.isin(ids) | coll.other_id.isin(ids)).any(), coll
    (t0, t1), = _intervals(ev, "leave")
    ho = ev[ev.kind == "handover"]
    assert list(ho.vehicle_id) == ["right"] and ho.t.iloc[0] == pytest.approx(t0)
    ours = traj[traj.vehicle_id == "right"]
    assert ours.t.max() < t0 + 1e-9  # no longer controlled (recorded) after the hand-over
    last = ours.iloc[-1]
    theirs = bg[bg.vehicle_id == "right"].sort_values("t")
    first = theirs.iloc[0]
    assert first.t == pytest.approx(last.t + 0.1)  # the next recorded step
    assert abs(first.v - last.v) <= 0.5
    assert first.lane_index == last.lane_index and abs(first.d - last.d) < 0.05
    assert abs(first.s - (last.s + 0.1 * last.v)) < 0.5  # where it was going
    assert np.abs(np.diff(theirs.v)).max() <= 0.5
    assert theirs.t.max() == pytest.approx(meta["t_end"]) and theirs.s.iloc[-1] - first.s > 300.0
    rest = traj[traj.vehicle_id.isin(["front", "rear"])]
    assert rest.t.max() == pytest.approx(meta["t_end"])  # the others drive on in formation


def test_mixed_truck_keeps_its_slot_with_its_own_chassis_and_gains(tmp_path):
    """A small truck (Table 3.5, speed gains of Table 3.6) among passenger cars: its own
    parameters and gains in the fleet, its own body in SUMO (placed to 1 cm: its CoG-to-bumper
    distance, not a car's) and in run.json, and it holds its slot through a slow-down."""
    from formation_traci.control.schedule import SPEED_GAINS_CAR, SPEED_GAINS_TRUCK
    from formation_traci.models.params import PASSENGER_CAR, SMALL_TRUCK
    from formation_traci.sim.setup import build_fleet

    sc = load_scenario(MANEUVERS / "mixed_truck.toml")
    cfg = build_fleet(sc)
    assert cfg.speed_gains == (SPEED_GAINS_CAR, SPEED_GAINS_CAR, SPEED_GAINS_TRUCK)
    np.testing.assert_allclose(cfg.params.m, [PASSENGER_CAR.m, PASSENGER_CAR.m, SMALL_TRUCK.m])
    # 32 s: with issue 19's jerk-limited caps (control/longitudinal.py) the truck closes up
    # about 5 s later than with the raw governor caps (back within 0.1 m at t = 30 s)
    meta, ev, traj, _ = _run(tmp_path, "mixed_truck", **{"run.duration": 32.0})
    bodies = {m["id"]: m["body"]["length"] for m in meta["members"]}
    assert bodies == {"car_centre": PASSENGER_CAR.length, "car_left": PASSENGER_CAR.length,
                      "truck": SMALL_TRUCK.length}
    ids = set(bodies)
    coll = ev[ev.kind == "collision"]
    assert not (coll.vehicle_id.isin(ids) | coll.other_id.isin(ids)).any(), coll
    truck = traj[(traj.vehicle_id == "truck") & (traj.t > 0)]
    assert truck.sumo_gap.max() < 0.01
    vc = traj[traj.vehicle_id == "vc"]
    assert vc.v.iloc[0] - vc.v.iloc[-1] > 3.0  # the formation really slowed down
    assert truck.e_lat.abs().max() < 0.3 and truck.a_lat.abs().max() < MEDIUM_COMFORT
    # the heavier truck with its softer Table 3.6 speed gains lags more in the slow-down than
    # the cars (what the physics and the seed's gains give: about 6 m, docs/maneuvers.md),
    # then closes up again
    car = traj[(traj.vehicle_id == "car_centre") & (traj.t > 0)]
    peak = truck.e_lon.abs().max()
    assert car.e_lon.abs().max() < peak < 8.0
    assert abs(truck.e_lon.iloc[-1]) < 0.5 * peak
