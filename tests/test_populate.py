"""A traffic flow with ``populate``: its vehicles stand along its whole route when it begins, at
the density its demand has in free flow at the speed limit (vph / (3600 v) per metre of road),
so a long road does not need a warm-up as long as its travel time. Real SUMO on the straight
3-lane motorway (6 km)."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from formation_traci.runner import run_scenario
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.sumo.traffic import POPULATE_JITTER, populate_places

V_LIMIT = 36.11  # the bundled motorways' speed limit [m/s]
VPH_LANE = 1200.0
LANES = 3


def test_places_are_one_spacing_apart_in_driving_order_and_seeded():
    """One vehicle every 3600 v / vph metres (all lanes), each moved by at most 0.3 of that
    spacing, in driving order, none in an edge's last 50 m or the route's last 100 m; the same
    seed gives the same places, another seed others."""
    lengths = [300.0, 5700.0]
    vph = LANES * VPH_LANE
    spacing = 3600.0 * V_LIMIT / vph  # 36.1 m
    p = populate_places(vph, V_LIMIT, lengths, seed=1)
    starts = np.array([0.0, 300.0])
    s = np.array([starts[k] + pos for k, pos in p])
    assert np.all(np.diff(s) >= (1.0 - 2.0 * POPULATE_JITTER) * spacing - 0.01)
    i = np.rint(s / spacing - 0.5)  # the slot each vehicle was drawn around
    assert np.abs(s / spacing - 0.5 - i).max() <= POPULATE_JITTER + 1e-3
    for k, pos in p:
        assert 0.0 <= pos <= lengths[k] - 50.0
    n_slots = int((sum(lengths) - 100.0) / spacing)
    assert n_slots - 3 <= len(p) <= n_slots  # at most the edge's last 50 m left out (~1.4 slots)
    assert populate_places(vph, V_LIMIT, lengths, seed=1) == p
    assert populate_places(vph, V_LIMIT, lengths, seed=2) != p


SCENARIO = """
name = "populated"
[run]
duration = 1.0
seed = 1
[road]
net = "straight3"
lane = 1
start = 300.0
[leader]
speed = 30.0
[[members]]
id = "a"
slot = {{ along = 0.0, lanes = 0 }}
[sumo]
fcd = true
[traffic]
warmup = 2.0
sections = {{ enabled = false }}
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = {vph}
populate = {populate}
"""


def _run(tmp_path, populate: bool):
    p = tmp_path / f"pop_{populate}.toml"
    p.write_text(SCENARIO.format(vph=VPH_LANE, populate=str(populate).lower()))
    out = tmp_path / f"run_{populate}"
    res = run_scenario(load_scenario(p), out, force=True, progress=False)
    return res, json.loads((out / "run.json").read_text()), pd.read_parquet(out / "sumo" / "fcd.parquet")


def test_a_populated_flow_fills_the_road_at_its_free_flow_density(tmp_path):
    """With populate the road holds, from SUMO's first step, the flow's vehicles over its whole
    6 km at vph / (3600 v) per metre (within 15 % over every 1 km stretch between 0.5 and 5.5 km,
    the member's own clearance aside); SUMO inserts every one (run.json counts them as the
    flow's, requested and inserted). Without it the same flow has entered only its first
    100 m or so after the 2 s warm-up."""
    res, meta, fcd = _run(tmp_path, True)
    assert res.status == "completed", res.reason
    vph = LANES * VPH_LANE
    n_placed = len(populate_places(vph, V_LIMIT, [300.0, 5700.0], seed=1))
    flow = meta["traffic"]["flows"]["main"]
    assert flow["requested"] >= n_placed and flow["inserted"] == flow["requested"], flow
    t_first = fcd.t.min()
    first = fcd[(fcd.t == t_first) & fcd.vehicle_id.str.startswith("main.p")]
    assert len(first) == n_placed  # all of them in SUMO from its first step
    x = first.x.to_numpy()
    per_km = np.histogram(x, bins=np.arange(500.0, 5501.0, 1000.0))[0]
    expected = vph / (3600.0 * V_LIMIT) * 1000.0  # 27.7 vehicles per km, all lanes
    assert np.all(np.abs(per_km - expected) <= 0.15 * expected), (per_km, expected)
    lanes = first.lane.str.rsplit("_", n=1).str[1].astype(int)
    assert set(lanes) == {0, 1, 2}  # spread over the lanes

    _, meta0, fcd0 = _run(tmp_path, False)
    end = fcd0[fcd0.t == fcd0.t.max()]
    assert end.x.max() < 500.0 and meta0["traffic"]["flows"]["main"]["requested"] < 20


def test_populate_needs_the_main_route(tmp_path):
    """A populated flow on another route than the main one is refused before the run (exit 2
    semantics: ScenarioError naming the field), nothing created."""
    p = tmp_path / "bad.toml"
    p.write_text(SCENARIO.format(vph=VPH_LANE, populate="true").replace(
        'populate = true', 'populate = true\nroute = ["ramp", "mw_accel", "mw_down"]').replace(
        'net = "straight3"', 'net = "onramp"'))
    with pytest.raises(ScenarioError, match=r"traffic\.flows\.0\.populate"):
        run_scenario(load_scenario(p), tmp_path / "never", force=True, progress=False)
    assert not (tmp_path / "never").exists()
