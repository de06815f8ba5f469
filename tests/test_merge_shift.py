"""``[cooperation] merge = "shift"`` on the bundled on-ramp network (real SUMO): a ramp vehicle in
conflict with the members in the merge lane makes the whole formation change one lane to the left
with the maneuver planner's gap check and comfort-limited transition (maneuver_start /
maneuver_end named merge_shift); a formation that cannot move there yields as ``open_gap`` does
(merge_yield_start naming the refusal, the virtual car's acceleration capped) and asks again every
step, the yield ending when the shift starts; shift is bad input where ``open_gap`` is and without
road slots."""
import pandas as pd
import pytest

from formation_traci.runner import run_scenario
from formation_traci.scenario import ScenarioError, load_scenario
from run_helpers import cli

HEAD = """
name = "merge-shift"
[run]
duration = 45.0
seed = 1
[road]
net = "onramp"
lane = {lane}
start = 600.0
[leader]
speed = 28.0
"""
TAIL = """
[traffic]
warmup = 150.0
[traffic.sections]
drain_max = 0.0
[[traffic.flows]]
id = "ramp"
route = ["ramp", "mw_accel", "mw_down"]
veh_per_hour = 900
[cooperation]
merge = "shift"
"""
# a column in the merge lane (the rightmost through lane beside the acceleration lane)
COLUMN = HEAD.format(lane=0) + "".join(
    f'[[members]]\nid = "{m}"\nslot = {{ along = {along}, lanes = 0 }}\n'
    for m, along in (("a", 0.0), ("b", -12.0), ("c", -24.0))) + TAIL
# one member per lane: no lane to the left of the formation's shape
WIDE = HEAD.format(lane=1) + "".join(
    f'[[members]]\nid = "{m}"\nslot = {{ along = 0.0, lanes = {k} }}\n'
    for m, k in (("right", -1), ("centre", 0), ("left", 1))) + TAIL
# the same column with a second formation's column beside it in the lane to the left
BLOCKED = COLUMN.replace("[traffic]", """[[formations]]
id = "beside"
lane = 1
leader = { speed = 28.0 }
members = [{ id = "p1", slot = { along = 0.0, lanes = 0 } },
           { id = "p2", slot = { along = -12.0, lanes = 0 } },
           { id = "p3", slot = { along = -24.0, lanes = 0 } }]

[traffic]""")
# the column beside it faster, from behind: it passes the column while the column yields
PASSING = BLOCKED.replace('lane = 1\nleader = { speed = 28.0 }', 'lane = 1\nstart = 440.0\nleader = { speed = 34.0 }')
LANE_W = 3.5  # the onramp network's lane width [m]


def _run(tmp_path_factory, name, text):
    d = tmp_path_factory.mktemp(name)
    p = d / "s.toml"
    p.write_text(text)
    res = run_scenario(load_scenario(p), d / "run", scenario_path=p, progress=False)
    out = d / "run"
    return (res, pd.read_parquet(out / "events.parquet"), pd.read_parquet(out / "trajectories.parquet"),
            pd.read_parquet(out / "background.parquet"))


@pytest.fixture(scope="module")
def column(tmp_path_factory):
    return _run(tmp_path_factory, "column", COLUMN)


@pytest.fixture(scope="module")
def wide(tmp_path_factory):
    return _run(tmp_path_factory, "wide", WIDE)


@pytest.fixture(scope="module")
def blocked(tmp_path_factory):
    return _run(tmp_path_factory, "blocked", BLOCKED)


@pytest.fixture(scope="module")
def passing(tmp_path_factory):
    return _run(tmp_path_factory, "passing", PASSING)


def test_a_column_in_the_merge_lane_shifts_left_before_the_ramp_vehicle_merges_within_comfort(column):
    res, ev, tr, bg = column
    assert res.status == "completed", res.reason
    starts, ends = ev[ev.kind == "maneuver_start"], ev[ev.kind == "maneuver_end"]
    assert len(starts) == 1 and len(ends) == 1, ev[["t", "kind", "detail"]]
    assert starts.detail.iloc[0].startswith("merge_shift: away from ramp.")
    assert ends.detail.iloc[0] == "merge_shift" and set(starts.vehicle_id) == {"vc"}
    t0, t1 = float(starts.t.iloc[0]), float(ends.t.iloc[0])
    # the shift is the answer: no yield, no emergency braking
    assert not ev.kind.isin(["merge_yield_start", "emergency_brake"]).any()
    members = tr[tr.vehicle_id.isin(["a", "b", "c"])]
    assert members.a_lon.abs().max() <= 2.0
    # from the merge lane (offset 0 on the reference lane) to the lane to its left (one lane width)
    before = members[members.t < t0]
    assert before.d.abs().max() < 0.3
    after = members[members.t >= t1]
    assert len(after) and (after.d - LANE_W).abs().max() < 0.3
    # the ramp vehicle it shifted for moves into the merge lane only after the members left it
    vid = starts.detail.iloc[0].split("away from ")[1].split(" ")[0]
    ramp = bg[bg.vehicle_id == vid]
    merged = ramp[ramp.d.abs() < LANE_W / 2]
    assert len(merged), f"{vid} did not merge within the run"
    assert t1 < float(merged.t.min())
    assert float(ramp.t.min()) < t0  # seen before the shift started


def test_a_formation_with_no_lane_left_of_it_yields_as_open_gap(wide):
    res, ev, tr, _ = wide
    assert res.status == "completed", res.reason
    assert not (ev.kind == "maneuver_start").any()
    starts = ev[ev.kind == "merge_yield_start"]
    assert len(starts) >= 1
    assert all(d.startswith("shift refused (target slots off the road ahead); open_gap: acceleration cap ")
               for d in starts.detail)
    # no other traffic on the motorway: the virtual car slows only for the yield, within its comfort
    vc = tr[tr.vehicle_id == "vc"].set_index("t").a_lon
    t0 = float(starts.t.min())
    assert (vc[vc.index < t0] == 0.0).all()
    assert vc.min() < -0.5 and vc.min() >= -1.5 - 1e-6


def test_a_column_whose_left_lane_is_taken_yields_as_open_gap(blocked):
    res, ev, tr, _ = blocked
    assert res.status == "completed", res.reason
    assert not (ev.kind == "maneuver_start").any()
    starts = ev[ev.kind == "merge_yield_start"]
    assert len(starts) >= 1 and set(starts.vehicle_id) == {"vc:f0"}
    # the gap check found the other formation's members in the way
    assert all(d.startswith("shift refused (no room: p") for d in starts.detail)
    vc = tr[tr.vehicle_id == "vc:f0"].set_index("t").a_lon
    assert (vc[vc.index < float(starts.t.min())] == 0.0).all()
    assert vc.min() < -0.5 and vc.min() >= -1.5 - 1e-6
    # neither column changed its lane
    col = tr[tr.vehicle_id.isin(["a", "b", "c"])]
    beside = tr[tr.vehicle_id.isin(["p1", "p2", "p3"])]
    assert col.d.abs().max() < 0.3 and (beside.d - LANE_W).abs().max() < 0.3


def test_a_refused_shift_is_asked_again_and_starts_once_the_left_lane_has_room(passing):
    res, ev, tr, _ = passing
    assert res.status == "completed", res.reason
    f0 = ev[ev.vehicle_id == "vc:f0"]
    yields, starts = f0[f0.kind == "merge_yield_start"], f0[f0.kind == "maneuver_start"]
    assert len(yields) == 1 and len(starts) == 1
    assert yields.detail.iloc[0].startswith("shift refused (no room: p")
    assert starts.detail.iloc[0].startswith("merge_shift: away from " + yields.other_id.iloc[0])
    t_yield, t_shift = float(yields.t.iloc[0]), float(starts.t.iloc[0])
    assert t_shift > t_yield + 1.0  # yielded meanwhile
    # the yield ends at the next step: the shift is the answer now
    ended = f0[(f0.kind == "merge_yield_end") & (f0.other_id == yields.other_id.iloc[0])]
    assert list(ended.detail) == ["the formation shifts away"]
    assert 0.0 < float(ended.t.iloc[0]) - t_shift <= 0.1
    t_end = float(f0[f0.kind == "maneuver_end"].t.iloc[0])
    members = tr[tr.vehicle_id.isin(["a", "b", "c"])]
    assert (members[members.t >= t_end].d - LANE_W).abs().max() < 0.3
    assert members.a_lon.abs().max() <= 2.0
    assert not ev[ev.kind == "emergency_brake"].vehicle_id.isin(["a", "b", "c", "vc:f0"]).any()


def test_shift_is_bad_input_where_a_road_or_road_slots_are_missing(tmp_path):
    p = tmp_path / "free.toml"
    p.write_text('[run]\nduration = 1.0\n[leader]\nspeed = 10.0\n[[members]]\nid = "a"\n'
                 'offset = [0.0, 0.0]\n[cooperation]\nmerge = "shift"\n')
    with pytest.raises(ScenarioError, match="cooperation: needs a \\[road\\]"):
        load_scenario(p)
    code, text = cli("run", p, "--out", tmp_path / "out")
    assert code == 2 and "cooperation" in text and not (tmp_path / "out").exists()
    q = tmp_path / "rigid.toml"
    q.write_text(COLUMN.replace('slot = { along = -24.0, lanes = 0 }', 'offset = [-24.0, 0.0]'))
    with pytest.raises(ScenarioError, match="cooperation.merge = \"shift\" needs road-frame slots"):
        load_scenario(q)
    ok = tmp_path / "ok.toml"
    ok.write_text(COLUMN)
    assert load_scenario(ok).cooperation.merge == "shift"
