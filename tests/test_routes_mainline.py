"""Routes by their ends follow the mainline (issue 30 item 3).

sumo_nets/shortcut: the 3-lane motorway swings 150 m to the left between x = 1000 and 2000 m
(mw_arc, 1018 m) while an off-ramp from lane 0, a straight link and an on-ramp (969 m) run
along its right: sumolib's shortest path from mw_up to mw_down leaves the motorway there (the
fault seen on LuST and a second OSM freeway). A route given by its ends stays on edges of the
start edge's road class; where the reference lane can follow no path, the error names the path
chosen and its first edge pair without a lane connection."""
from __future__ import annotations

from pathlib import Path

import pytest

from formation_traci.road.geometry import load_net
from formation_traci.scenario import load_scenario
from formation_traci.scenario.load import ScenarioError
from formation_traci.scenario.schema import RouteEnds
from formation_traci.sumo.road_setup import build_road
from formation_traci.sumo.routes import resolve_route
from sumo_nets import net_path

ROOT = Path(__file__).resolve().parents[1]
LUST = ROOT.parent / "shared" / "realnet" / "LuSTMotorway.net.xml"
MAINLINE = ["mw_up", "mw_arc", "mw_down"]
SHORTCUT = ["mw_up", "offramp", "link", "onramp", "mw_down"]

SCENARIO = """
name = "shortcut"
[run]
duration = 10.0
[road]
net = "shortcut"
route = {route}
lane = {lane}
start = 200.0
[leader]
speed = 25.0
[[members]]
id = "a"
slot = {{ along = 0.0, lanes = 0 }}
"""


@pytest.fixture(scope="module")
def net():
    return load_net(net_path("shortcut"))


def _scenario(tmp_path, route: str, lane: int = 1) -> Path:
    p = tmp_path / "shortcut.toml"
    p.write_text(SCENARIO.format(route=route, lane=lane))
    return p


def test_the_shortest_path_of_the_bundled_network_leaves_the_motorway(net):
    """The fault's precondition: sumolib's shortest path takes the ramps (and is shorter)."""
    path, cost = net.getShortestPath(net.getEdge("mw_up"), net.getEdge("mw_down"), vClass="passenger")
    assert [e.getID() for e in path] == SHORTCUT
    assert cost < sum(net.getEdge(e).getLength() for e in MAINLINE)


@pytest.mark.parametrize("lane", [0, 1, 2])
def test_route_by_ends_is_the_mainline_for_every_reference_lane(tmp_path, lane):
    p = _scenario(tmp_path, '{ from = "mw_up", to = "mw_down" }', lane)
    road = build_road(load_scenario(p), p)
    assert road.route == MAINLINE
    assert road.line.length > 3000  # along the swing (the ramps' path: 2960 m)


def test_via_points_pick_another_path(net):
    """The user's via point takes the ramps (lane 0 is the one connected to them)."""
    spec = RouteEnds(**{"from": "mw_up", "to": "mw_down", "via": ["link"]})
    assert resolve_route(net, spec, "road.route", 0) == (SHORTCUT, [])
    spec = RouteEnds(**{"from": "mw_up", "to": "mw_down", "via": [[1500.0, -27.0]]})  # on the link
    assert resolve_route(net, spec, "road.route", 0) == (SHORTCUT, [])


def test_no_path_the_lane_follows_names_the_chosen_path_and_the_missing_connection(tmp_path):
    p = _scenario(tmp_path, '{ from = "mw_up", to = "mw_down", via = ["link"] }', lane=1)
    with pytest.raises(ScenarioError) as ei:
        build_road(load_scenario(p), p)
    (field, msg), = ei.value.problems
    assert field == "road.route"
    assert "mw_up -> offramp -> link -> onramp -> mw_down" in msg  # the path chosen
    assert "no lane connection from edge 'mw_up' to edge 'offramp'" in msg  # its first break
    assert "lane 1" in msg


@pytest.mark.skipif(not LUST.is_file(), reason="needs ../shared/realnet beside the checkout")
def test_lust_route_by_ends_stays_on_the_motorway():
    """The issue's case: -30668#9 -> -30668#12 went over the ramps -30908#0 .. -31268#2."""
    net = load_net(LUST)
    spec = RouteEnds(**{"from": "-30668#9", "to": "-30668#12"})
    short, _ = net.getShortestPath(net.getEdge("-30668#9"), net.getEdge("-30668#12"), vClass="passenger")
    assert "-30908#0" in [e.getID() for e in short]  # the old route
    route, problems = resolve_route(net, spec, "road.route", 1)
    assert problems == [] and "-30908#0" not in route
    assert route == ["-30668#9", "-30668#9-AddedOffRampEdge", "-30668#10", "-30668#10-AddedOffRampEdge",
                     "-30668#11", "-30668#12-AddedOnRampEdge", "-30668#12"]
    assert {net.getEdge(e).getType() for e in route} == {"highway.motorway"}
