"""Maneuvers use SUMO's own lane centres (issue 16 with issue 15's lane mapping): lane
shifts, reshape goals given in lanes, entry positions and the in-lane tests of the planner
come from RoadSetup.lane_d on the edge where the slot is, not from lanes * lane_width.

The network is built here with netconvert: two straight 1.5 km edges of three 3.2 m wide
lanes whose centres are 3.3 m apart on the first edge (as on the LuST motorway, SUMO's old
0.1 m gap) and 3.6 m apart on the second, so a nominal lane width (3.2 m) misplaces a lane
change by 0.4 m there and the first edge's spacing by 0.3 m."""
import subprocess

import numpy as np
import pandas as pd
import pytest

from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario

WIDTH = 3.2  # m, every lane
SPACING = {"e1": 3.3, "e2": 3.6}  # m, between lane centres
Y0 = -1.65  # m, centre of lane 0 (the reference lane)
EDGE_M = 1500.0


def lane_y(edge: str, k: int) -> float:
    """SUMO's centre of lane k of ``edge`` [m] (the lane shapes below)."""
    return Y0 + k * SPACING[edge]


@pytest.fixture(scope="module")
def gap_net(tmp_path_factory):
    import sumolib
    d = tmp_path_factory.mktemp("gapnet")
    (d / "g.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="1500" y="0"/>'
                                 '<node id="c" x="3000" y="0"/></nodes>')
    edges = []
    for i, (e, a, b) in enumerate((("e1", "a", "b"), ("e2", "b", "c"))):
        x0, x1 = i * EDGE_M, (i + 1) * EDGE_M
        lanes = "".join(f'<lane index="{k}" shape="{x0},{lane_y(e, k)} {x1},{lane_y(e, k)}"/>'
                        for k in range(3))
        edges.append(f'<edge id="{e}" from="{a}" to="{b}" numLanes="3" speed="36.11" '
                     f'width="{WIDTH}">{lanes}</edge>')
    (d / "g.edg.xml").write_text("<edges>" + "".join(edges) + "</edges>")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "g.nod.xml", "-e", "g.edg.xml",
                    "-o", "g.net.xml", "--offset.disable-normalization", "true",
                    "--no-turnarounds", "true"], cwd=d, check=True, capture_output=True)
    return d / "g.net.xml"


SCENARIO = """
name = "gap lanes"
[run]
duration = 28.0
seed = 1
[road]
net = "{net}"
route = ["e1", "e2"]
lane = 0
start = 1300.0
[leader]
speed = 25.0
[[members]]
id = "front"
slot = {{ along = 0.0, lanes = 0 }}
[[members]]
id = "rear"
slot = {{ along = -20.0, lanes = 0 }}
[[maneuvers]]
kind = "lane_change"
lanes = 1
at = {{ s = 1600.0 }}
[[maneuvers]]
kind = "reshape"
at = {{ time = 18.0 }}
slots = [{{ along = 0.0, lanes = 2 }}, {{ along = -20.0, lanes = 0 }}]
"""


@pytest.fixture(scope="module")
def gap_run(gap_net, tmp_path_factory):
    d = tmp_path_factory.mktemp("gaprun")
    path = d / "gap.toml"
    path.write_text(SCENARIO.format(net=gap_net))
    res = run_scenario(load_scenario(path), d / "out", scenario_path=path, progress=False)
    assert res.status == "completed", res.reason
    return (pd.read_parquet(d / "out" / "events.parquet"),
            pd.read_parquet(d / "out" / "trajectories.parquet"))


def _span(ev, kind):
    m = ev[ev.kind.isin(["maneuver_start", "maneuver_end"]) & ev.detail.str.startswith(kind)]
    (t0,), (t1,) = m[m.kind == "maneuver_start"].t, m[m.kind == "maneuver_end"].t
    return t0, t1


def test_lane_change_of_one_lane_ends_on_sumos_lane_centre(gap_run):
    """A whole-formation lane change of one lane on the second edge (centres 3.6 m apart,
    lanes 3.2 m wide) ends with both members on SUMO's centre of lane 1 there (within
    0.05 m); lanes * lane_width would leave them 0.4 m off it."""
    ev, traj = gap_run
    t0, t1 = _span(ev, "lane_change")
    members = traj[traj.vehicle_id.isin(["front", "rear"])]
    at_start = members[np.isclose(members.t, t0)]
    assert (at_start.x > EDGE_M).all()  # both slots on e2 when it starts
    settled = members[(members.t > t1 + 1.0) & (members.t < 18.0)]
    assert len(settled) and (settled.x > EDGE_M).all()
    np.testing.assert_allclose(settled.y, lane_y("e2", 1), atol=0.05)
    assert (settled.lane_index == 1).all()


def test_reshape_goals_in_lanes_are_sumos_lane_centres(gap_run):
    """A reshape whose goal slots are given in lanes puts the members on SUMO's centres of
    lanes 2 and 0 of the edge they are on (within 0.05 m)."""
    ev, traj = gap_run
    _, t1 = _span(ev, "reshape")
    end = traj[traj.t > t1 + 1.5]
    assert len(end)
    front, rear = (end[end.vehicle_id == v] for v in ("front", "rear"))
    np.testing.assert_allclose(front.y, lane_y("e2", 2), atol=0.05)
    np.testing.assert_allclose(rear.y, lane_y("e2", 0), atol=0.05)
    assert (front.lane_index == 2).all() and (rear.lane_index == 0).all()


@pytest.fixture(scope="module")
def gap_road(gap_net, tmp_path_factory):
    from formation_traci.sumo.road_setup import build_road
    path = tmp_path_factory.mktemp("gaproad") / "gap.toml"
    path.write_text(SCENARIO.format(net=gap_net))
    sc = load_scenario(path)
    return sc, build_road(sc, path)


def test_lane_centres_are_sumos_on_the_edge_at_an_arc_length(gap_road):
    """One mapping (road/lanes.py LaneCentres) for the initial slots and the maneuvers: lane k
    of the edge at s, relative to the reference lane; a shift keeps the place in the lane."""
    from formation_traci.sumo.road_setup import slot_offsets
    sc, road = gap_road
    lanes = road.lanes
    np.testing.assert_allclose(lanes.across([-1, 0, 1, 2], 1000.0), [-3.2, 0.0, 3.3, 6.6], atol=1e-9)
    np.testing.assert_allclose(lanes.across([0, 1, 2, 3], 2000.0), [0.0, 3.6, 7.2, 10.4], atol=1e-9)
    np.testing.assert_allclose(lanes.shift(2000.0, [0.0, 0.2, 3.6], 1), [3.6, 3.8, 7.2], atol=1e-9)
    np.testing.assert_allclose(lanes.shift(1000.0, 6.6, -2), 0.0, atol=1e-9)
    # the initial slots use the same function: lanes = 0 -> on the reference line
    np.testing.assert_allclose(slot_offsets(sc, road)[:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(lanes.off_centre(2000.0, [3.6, 3.9, 5.2]), [0.0, 0.3, 1.6], atol=1e-4)  # the fitted line: microns


def test_join_takes_a_car_centred_in_sumos_lane_and_enters_on_its_centre(gap_road):
    """On the second edge (centres 3.6 m apart) a car on lane 1's centre is centred in its
    lane (with the nominal 3.2 m width it looked 0.4 m off: 'changing lanes'); a car between
    the lanes is not taken; a member entering one lane left enters on SUMO's lane centre."""
    from formation_traci.control.maneuvers.gap import Others
    from formation_traci.control.maneuvers.join import pick_vehicle
    from formation_traci.control.maneuvers.planner import ManeuverPlanner, Situation
    from formation_traci.scenario.load import parse_scenario
    from formation_traci.scenario.maneuvers import ManeuverLimits
    _, road = gap_road
    o = Others(("between", "centred"), np.array([2010.0, 2015.0]), np.array([1.9, 3.6]),
               np.full(2, 4.5), np.full(2, 1.8), np.full(2, 25.0))
    assert pick_vehicle(o, 2000.0, 3.6, 30.0, road.lanes, 4.6, 1.8, None) == 1
    assert pick_vehicle(o, 2000.0, 0.0, 30.0, road.lanes, 4.6, 1.8, None) == -1
    doc = {"run": {"duration": 10.0}, "road": {"net": "straight3"}, "leader": {"speed": 25.0},
           "members": [{"id": "a", "slot": {"along": 0.0, "lanes": 0}},
                       {"id": "j", "slot": {"along": -10.0, "lanes": 1}}],
           "maneuvers": [{"kind": "join", "member": "j", "at": {"time": 0.0},
                          "enter": {"along": -60.0, "lanes": 1}}]}
    sc = parse_scenario(doc)
    p = ManeuverPlanner(sc.maneuvers, np.array([[0.0, 0.0], [-10.0, 3.6]]), road.lanes,
                        ManeuverLimits(), 4.6, 1.8, ["a", "j"])
    none = Others((), *(np.empty(0),) * 5)
    ev = p.step(Situation(0.0, 2000.0, np.array([2000.0, np.nan]), np.array([0.0, np.nan]),
                          np.full(2, 25.0), np.array([True, False]), none, 25.0))
    enter = [e for e in ev if e.kind == "enter"]
    assert len(enter) == 1 and enter[0].where[:2] == pytest.approx((1940.0, 3.6))


def test_queue_behind_counts_by_sumos_lanes(gap_road):
    """Queued vehicles are those in a lane a member is in, by SUMO's lane centres."""
    from formation_traci.control.maneuvers.gap import Others
    from formation_traci.control.maneuvers.triggers import queue_behind
    _, road = gap_road
    o = Others(("q1", "q2", "right", "ahead"), np.array([1960.0, 1930.0, 1960.0, 2050.0]),
               np.array([3.6, 4.9, 0.3, 3.6]), np.full(4, 4.5), np.full(4, 1.8), np.full(4, 25.0))
    assert queue_behind(np.array([2000.0, 1980.0]), np.array([3.6, 3.6]), np.full(2, 4.6),
                        road.lanes, o, 100.0) == 2
