"""On-ramps read from the network (formation_traci/road/ramps.py): the bundled on-ramp network's
acceleration lane, the LuST motorway's on-ramp joining -31622#4, the 100 km motorway's nine
on-ramps; off-ramps, lane drops and plain roads have none."""
from pathlib import Path

import pytest
import sumolib

import sumo_nets
from formation_traci.road.ramps import ramp_joins
from formation_traci.sumo.routes import mainline_path

ROOT = Path(__file__).resolve().parents[1]
LUST = ROOT.parent / "shared" / "realnet" / "LuSTMotorway.net.xml"


def _net(path):
    return sumolib.net.readNet(str(path), withInternal=True)


def test_the_bundled_onramp_has_one_acceleration_lane_beside_the_right_lane():
    net = _net(sumo_nets.net_path("onramp"))
    (join,) = ramp_joins(net, ["mw_up", "mw_accel", "mw_down"])
    assert (join.edge_index, join.added_lane, join.merge_lane) == (1, "mw_accel_0", "mw_accel_1")
    # the 300 m acceleration lane (x 1500-1800 m) less the junctions' internal lanes at its ends
    assert join.length_m == pytest.approx(net.getLane("mw_accel_0").getLength())
    assert 280.0 < join.length_m <= 300.0
    feeders = dict(join.feeders)
    ramp = net.getLane("ramp_0").getLength()  # 400 m drawn from x = 1100 m, 25.5 m to the side
    assert feeders["ramp_0"] == pytest.approx(ramp + feeders[next(k for k in feeders if k.startswith(":"))])
    assert 400.0 < feeders["ramp_0"] < 410.0
    assert not join.left_merges  # mw_accel_2 runs on into mw_down as a lane of its own


def test_lust_on_ramp_joins_beside_the_mainlines_right_lane():
    net = _net(LUST)
    route = [e.getID() for e in mainline_path(net.getEdge("-31622#2"), net.getEdge("-31622#6"))]
    (join,) = ramp_joins(net, route)  # the off-ramps (-31558, -31828, -31760) are no joins
    assert route[join.edge_index] == "-31622#4-AddedOnRampEdge"
    assert join.added_lane == "-31622#4-AddedOnRampEdge_0"
    # the road frame runs it on as -31622#4's lane 0; SUMO connects it to lane 1 (tests/test_merge_lust.py)
    assert join.merge_lane == "-31622#4-AddedOnRampEdge_1"
    assert join.length_m == pytest.approx(95.07, abs=0.01)
    assert "-30426_0" in dict(join.feeders)
    assert join.left_merges  # lanes 1 and 2 both run into -31622#4_1: a shift left gains nothing


@pytest.mark.parametrize("name, route", [("straight3", None), ("offramp", None), ("lanedrop", None)])
def test_roads_without_on_ramps_have_no_join(name, route):
    net = _net(sumo_nets.net_path(name))
    edges = [e for e in net.getEdges() if e.getFunction() != "internal"]
    start = next(e for e in edges if not e.getIncoming())
    paths = [mainline_path(start, e) for e in edges if not e.getOutgoing()]
    longest = max((p for p in paths if p), key=len)
    assert ramp_joins(net, [e.getID() for e in longest]) == []


def test_the_100_km_motorway_has_its_nine_on_ramps_10_km_apart():
    net = _net(sumo_nets.net_path("motorway100"))
    route = sumo_nets.main_route("motorway100")
    joins = ramp_joins(net, route)
    assert len(joins) == 9
    starts = [sum(net.getEdge(e).getLength() for e in route[:j.edge_index]) for j in joins]
    assert [round(b - a, -2) for a, b in zip(starts, starts[1:])] == [10000.0] * 8
