"""A real OSM-derived motorway (LuST, Luxembourg; ../shared/realnet/, not copied into the
project): geometric lanes through on-ramps, lane centres from SUMO's shapes, a smooth reference
line, routes by their ends, routes checked before SUMO starts (issue 15, items 2-4)."""
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.road.geometry import route_lanes
from formation_traci.road.lanes import geometric_route_lanes, geometric_route_shape
from formation_traci.road.smoothing import deviation, fit_within
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.runner import run_scenario
from formation_traci.sumo.road_setup import build_road

ROOT = Path(__file__).resolve().parents[1]
LUST = ROOT.parent / "shared" / "realnet" / "LuSTMotorway.net.xml"
ROUTE = ["-30668#1", "-30668#2-AddedOnRampEdge", "-30668#2", "-30668#2-AddedOffRampEdge", "-30668#3",
         "-30668#4-AddedOnRampEdge", "-30668#4", "-30668#4-AddedOffRampEdge", "-30668#5",
         "-30668#6-AddedOnRampEdge", "-30668#6"]
"""5.5 km of the ring: three on-ramps (…-AddedOnRampEdge, 4 lanes) and two exits."""

SCENARIO = f"""
name = "lust"
[run]
duration = 120.0
seed = 1
[road]
net = "{LUST}"
route = {{ from = "-30668#1", to = "-30668#6" }}
lane = 1
start = 200.0
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
veh_per_hour_per_lane = 600
[[traffic.flows]]
id = "ramp"
veh_per_hour = 300
route = {{ from = "-31316", to = "-30668#6" }}
"""

NO_DRAIN = {"traffic.sections.drain_max": 0.0}
"""No drain of the measurement stretch after the formation's last step (sumo/sections.py:
members out, SUMO alone runs on): it records into none of the tables read here, and run.json
keeps SUMO's messages up to the drain's start."""

pytestmark = pytest.mark.skipif(not LUST.is_file(), reason="needs ../shared/realnet beside the checkout")


@pytest.fixture(scope="module")
def net():
    import sumolib
    return sumolib.net.readNet(str(LUST), withInternal=True)


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    p = tmp_path_factory.mktemp("lust") / "lust.toml"
    p.write_text(SCENARIO)
    return p


def test_reference_lane_follows_the_geometry_not_the_connection(net):
    """At the on-ramp the merge edge connects its lane 1 to lane 1 of the next edge, but lane 1
    lies across from lane 0 there: the rightmost lane stays the rightmost lane."""
    conn = [x for x in route_lanes(net, ROUTE, 0) if not x.startswith(":")]
    geo = [x for x in geometric_route_lanes(net, ROUTE, 0) if not x.startswith(":")]
    assert conn[2] == "-30668#2_1"  # SUMO's connection swerves a lane
    assert geo[1:3] == ["-30668#2-AddedOnRampEdge_1", "-30668#2_0"]
    assert [g.rsplit("_", 1)[1] for g in geo[::2]] == ["0"] * 6  # every 3-lane edge: lane 0


def test_members_kept_off_sideways_junction_lanes_always_have_a_lane_where_they_are(net):
    """The internal lanes closed to the members are those whose connection swerves a lane
    (on-ramps 1 -> 1, exits 0 -> 0 where lane 0 runs on as the exit's lane 1), and every
    one of them lies beside an open internal lane into the lane the member geometrically
    enters, so moveToXY always has a lane for it."""
    from formation_traci.road.lanes import geometric_successor, sideways_internal_lanes
    closed = sideways_internal_lanes(net, ROUTE)
    assert closed == [":-30668#2-AddedOffRampNode_0_0", ":-30668#2-AddedOnRampNode_0_1",
                      ":-30668#4-AddedOffRampNode_0_0", ":-30668#4-AddedOnRampNode_0_1",
                      ":-30668#6-AddedOnRampNode_0_1"]
    for a, b in zip(ROUTE, ROUTE[1:]):
        for lane in net.getEdge(a).getLanes():
            for c in lane.getOutgoing():
                if c.getViaLaneID() in closed:
                    geo = geometric_successor(lane, net.getEdge(b))
                    open_into = [d for x in net.getEdge(a).getLanes() for d in x.getOutgoing()
                                 if d.getToLane() == geo and d.getViaLaneID() not in closed]
                    assert open_into, (lane.getID(), geo.getID())


def test_smoothed_reference_is_within_tolerance_and_gently_curved(net):
    """OSM corners (up to 7.4 deg every ~58 m): the 80 m fit the tolerance allowed before issue
    32 item 5 kept the sharpest one as a 311 m radius; the 160 m fit held within 0.6 m of SUMO's
    lane centre has a smallest radius above 500 m (measured 529 m; within 0.6 m no line does
    better than ~600 m there: 1.51 m/s^2 at 30 m/s, a linear programme over that corner). A
    tighter tolerance is met too, with the corner kept sharper (0.3 m: 263 m)."""
    xy = geometric_route_shape(net, ROUTE, 1)
    line, length, dev = fit_within(xy, 0.6)
    assert length == 160.0 and dev <= 0.6 and deviation(line, xy) == pytest.approx(dev)
    s = np.linspace(300, line.length - 300, 20000)
    assert 1 / np.abs(line.curvature(s)).max() > 500
    tight, _, tight_dev = fit_within(xy, 0.3)
    assert tight_dev <= 0.3
    assert 1 / np.abs(tight.curvature(s)).max() < 300  # the corner kept sharp


def _lane_distance(xy: np.ndarray, lane: np.ndarray) -> np.ndarray:
    """Distance of points xy (n, 2) from a lane's centre polyline (m, 2) [m]."""
    a, b = lane[:-1], lane[1:]
    ab = b - a
    L2 = (ab ** 2).sum(axis=1)
    keep = L2 > 1e-9
    a, ab, L2 = a[keep], ab[keep], L2[keep]
    t = np.clip(((xy[:, None, :] - a[None]) * ab[None]).sum(axis=2) / L2[None], 0.0, 1.0)
    return np.hypot(*np.moveaxis(xy[:, None, :] - (a[None] + t[..., None] * ab[None]), -1, 0)).min(axis=1)


def test_members_feel_the_road_not_its_polyline_corners(tmp_path, net):
    """Issue 32 item 5: 60 s at 30 m/s from s = 3500 m (1.8 km of a gentle left curve,
    R ~ 2.3 km, drawn with 1.6-2.6 deg corners every ~90 m, and the junction jogs at 3.69 km).
    The line used to follow the polyline (80 m fit: a_lat up to 1.07 m/s^2, lateral jerk
    1.34 m/s^3, measured); now every member's peak |a_lat| <= 1.0 m/s^2 (measured 0.71) and
    lateral jerk (0.1 s mean of d a_lat / dt at 100 Hz) <= 1.0 m/s^3 (0.30), after the first
    3 s (the members start with a_lat = 0 on the curve). Tracking stays tight: |e_lat| <= 0.5 m
    (0.12), and every member stays within road.fit_tolerance (0.6 m) of its SUMO lane's centre
    (0.33: the line's own distance plus the tracking error)."""
    p = tmp_path / "lust.toml"
    p.write_text(SCENARIO)
    sc = load_scenario(p, **{"road.start": 3500.0, "run.duration": 60.0}, **NO_DRAIN)
    res = run_scenario(sc, tmp_path / "out", scenario_path=p, progress=False)
    assert res.status == "completed", res.reason
    comfort = pd.read_parquet(tmp_path / "out" / "comfort.parquet")
    tr = pd.read_parquet(tmp_path / "out" / "trajectories.parquet")
    lanes = {"right": 0, "centre": 1, "left": 2}  # lanes -1, 0, +1 of reference lane 1
    for vid, lane in lanes.items():
        g = comfort[comfort.vehicle_id == vid].sort_values("t")
        t, a = g.t.to_numpy(), g.a_lat.to_numpy()
        jerk = np.convolve(np.gradient(a, t), np.ones(10) / 10, mode="same")
        late = t >= 3.0
        assert np.abs(a[late]).max() <= 1.0, vid
        assert np.abs(jerk[late]).max() <= 1.0, vid
        rows = tr[(tr.vehicle_id == vid) & (tr.t >= 3.0)]
        assert np.abs(rows.e_lat).max() <= 0.5, vid
        shape = geometric_route_shape(net, ROUTE, lane)
        assert _lane_distance(rows[["x", "y"]].to_numpy(), shape).max() <= 0.6, vid
    assert tr[tr.vehicle_id == "vc"].s.max() > 5200.0  # the whole stretch was driven


def test_route_by_its_ends_and_lane_centres_from_sumo_shapes(scenario):
    road = build_road(load_scenario(scenario), scenario)
    assert road.route == ROUTE  # the mainline between the two end edges (sumo/routes.py)
    d = road.lane_d["-30668#1"]
    np.testing.assert_allclose(np.diff(d), 3.3, atol=0.02)  # 3.2 m lanes, centres 3.3 m apart


@pytest.mark.parametrize("route,field,words", [
    ('["-31316", "-30668#2"]', "traffic.flows.1.route", "missing link -31316 -> -30668#2"),
    ('["-31316", "nowhere"]', "traffic.flows.1.route", "not in the network"),
    ('{ from = "-31316", to = "nowhere" }', "traffic.flows.1.route", "'nowhere' is not in the network"),
])
def test_bad_flow_route_is_refused_before_sumo_starts(tmp_path, route, field, words):
    p = tmp_path / "bad.toml"
    p.write_text(SCENARIO.replace('route = { from = "-31316", to = "-30668#6" }', f"route = {route}"))
    with pytest.raises(ScenarioError) as ei:
        run_scenario(load_scenario(p), tmp_path / "out", scenario_path=p, progress=False)
    assert any(f == field and words in m for f, m in ei.value.problems), ei.value.problems
    assert not (tmp_path / "out").exists()


def test_rightmost_reference_lane_is_accepted_and_stays_in_its_lane(tmp_path, scenario):
    """With lane 0 as reference (slots in lanes 0, 1, 2) the formation used to swerve a lane in
    each on-ramp junction or be refused as 'off the road'; now it is accepted and the reference
    line stays within the fit tolerance of lane 0's centre on every 3-lane edge."""
    from formation_traci.sumo.plan import prepare
    p = tmp_path / "right.toml"
    p.write_text(SCENARIO.replace("lane = 1\n", "lane = 0\n").replace("lanes = -1 }", "lanes = 2 }"))
    plan = prepare(load_scenario(p), p)
    line = plan.road.line
    for edge in ROUTE[::2]:
        assert abs(plan.road.lane_d[edge][0]) < 0.6, edge
    assert sorted(plan.slots[:, 1].round(1)) == [0.0, 3.3, 6.6]


def test_sumo_messages_are_events_on_the_formation_clock(tmp_path):
    from formation_traci.sumo.messages import record_messages, summary_line
    log = tmp_path / "messages.log"
    log.write_text("Warning: Vehicle 'a' performs emergency braking on lane 'x_0' with decel=9.1, "
                   "wished=4.5, severity=1.0, time=44.15.\n"
                   "Warning: Value of 'emergencyDecel' (3.00) should be higher than 'decel'.\n"
                   "Warning: Vehicle 'right' performs emergency stop at the end of lane 'e_1' because "
                   "there is no connection to the next edge (decel=204.28, offset=2.66), time=53.75.\n")
    got = []
    counts = record_messages(log, 30.0, lambda *a: got.append(a), 0.05, members={"right"})
    assert got[0][:4] == (pytest.approx(14.2), "sumo_message", "a", "emergency_braking")
    assert "t=14.20 s (formation clock)" in got[0][4] and "time=" not in got[0][4]
    assert got[1][0] == -30.0 and got[1][3] == "other"  # at loading: SUMO's start, before t = 0
    assert got[2][:4] == (pytest.approx(23.8), "sumo_message", "right", "lane_end_stop")
    by_cause = counts.pop("by_cause")
    assert counts == {"warnings": 3, "errors": 0, "during_warmup": 1,
                      "by_kind": {"emergency_braking": 1, "other": 1, "lane_end_stop": 1}}
    assert by_cause["emergency_braking"] == {"members": 0, "background": 1}  # 'a' is no member
    assert by_cause["lane_end_stop"] == {"members": 1, "background": 0}
    assert by_cause["other"] == {"members": 0, "background": 1}  # names no vehicle
    assert by_cause["collision"] == {"members": 0, "background": 0}  # every kind, also unseen
    line = summary_line({**counts, "by_cause": by_cause})
    assert "3 warnings" in line and "1 lane end stop (1 about members)" in line
    assert "\n" not in line


def test_three_abreast_through_on_ramps_and_past_exits(tmp_path, scenario, capfd):
    """120 s past three on-ramps and two exits: no collision involving a member, fewer than 5
    placement mismatches (193 before: lanes placed 3.2 m apart, 3.3 m in SUMO), SUMO's messages
    recorded on the formation's clock, and each member's peak lateral acceleration within 20 %
    of v^2 kappa of the smoothed road at its own lateral offset. No move is refused and no member
    dropped: at the first on-ramp a ramp car (29 m/s) appears at zero gap in front of `right`
    (24.8 m/s); the governor's speed cap of ~2 m/s used to brake it at the friction limit until it
    fell 60 m behind and off the road (docs/model.md, "Faster vehicles cutting in"). With all lanes
    allowed to the members SUMO reports 2 false member-member junction collisions here."""
    sc = load_scenario(scenario, **NO_DRAIN)
    res = run_scenario(sc, tmp_path / "run", scenario_path=scenario, progress=False, force=True)
    assert res.status == "completed", res.reason
    out = tmp_path / "run"
    meta = json.loads((out / "run.json").read_text())
    ev = pd.read_parquet(out / "events.parquet")
    members = {"right", "centre", "left"}
    coll = ev[(ev.kind == "collision") & (ev.vehicle_id.isin(members) | ev.other_id.isin(members))]
    assert coll.empty, coll
    assert (ev.kind == "placement_mismatch").sum() < 5
    assert not (ev.kind == "member_removed").any()
    assert not ev.kind.isin(["move_refused", "emergency_brake"]).any()
    assert meta["sumo"]["route"] == ROUTE
    assert "Warning:" not in capfd.readouterr().err  # SUMO's messages are events, not terminal lines
    msgs = ev[ev.kind == "sumo_message"]
    assert sum(meta["sumo"]["messages"]["by_kind"].values()) == len(msgs)
    assert msgs.t.between(-sc.traffic.warmup, sc.run.duration + 0.1).all()
    traj = pd.read_parquet(out / "trajectories.parquet")
    m = traj[(traj.vehicle_id != "vc") & (traj.t > 5.0)]
    assert m.s.max() - m.s.min() > 2500  # it drove through the junctions
    line = build_road(sc, scenario).line
    for vid, g in m.groupby("vehicle_id"):
        kappa = line.curvature(g.s.to_numpy())
        road = (g.v ** 2 * np.abs(kappa / (1 - g.d * kappa))).max()
        assert road > 0.5  # m/s^2: the road really bends
        assert abs(g.a_lat.abs().max() / road - 1) < 0.2, (vid, g.a_lat.abs().max(), road)
