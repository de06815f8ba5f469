"""Checks of the committed SUMO networks in sumo_nets/ against their design values.

Design values are written out here on purpose (not imported from sumo_nets.build), so that a
wrong generator or a wrong netconvert option makes these tests fail.

Tolerances
----------
* lengths: main route 6000 m / 4000 m +- 1 m (the straight edge joints add 0.1 m internal lanes);
  element lengths (clothoids, arcs, ramp, acceleration lane) +- 5 m;
* radii: least-squares circle fit over the arc within 0.2 %, every three-point radius
  (points ~12 m either side) within 1 %;
* clothoids: curvature linear in arc length, residual < 2 % of 1/R;
* smoothness: consecutive segment headings along every driven lane sequence differ by
  < 0.01 rad (0.57 deg), consecutive lanes join with a gap < 1 cm; shape points on curves
  are at most 5 m apart (longer segments only where the polyline does not turn).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

sumolib = pytest.importorskip("sumolib")

REPO = Path(__file__).resolve().parents[1]
NETS = REPO / "sumo_nets"
NAMES = ("straight3", "curved3", "onramp", "lanedrop", "offramp")

LANE_WIDTH = 3.5
V_MOTORWAY = 36.11
V_RAMP = 22.22

# main route and ramp route (edge ids in driving order) per network
ROUTES = {
    "straight3": {"main": ["entry", "main"]},
    "curved3": {"main": ["entry", "main"]},
    "onramp": {"main": ["mw_up", "mw_accel", "mw_down"], "ramp": ["ramp", "mw_accel", "mw_down"]},
    "lanedrop": {"main": ["mw_up", "mw_down"]},
    "offramp": {"main": ["mw_up", "mw_decel", "mw_down"], "exit": ["mw_up", "mw_decel", "offramp"]},
}
LANES = {
    "straight3": {"entry": 3, "main": 3},
    "curved3": {"entry": 3, "main": 3},
    "onramp": {"mw_up": 3, "mw_accel": 4, "mw_down": 3, "ramp": 1},
    "lanedrop": {"mw_up": 3, "mw_down": 2},
    "offramp": {"mw_up": 3, "mw_decel": 4, "mw_down": 3, "offramp": 1},
}
MAIN_LENGTH = {"straight3": 6000.0, "curved3": 6000.0, "onramp": 4000.0, "lanedrop": 4000.0,
               "offramp": 4000.0}


_NET_CACHE: dict[str, object] = {}


def load(name: str, directory: Path = NETS):
    key = str(directory / name)
    if key not in _NET_CACHE:
        _NET_CACHE[key] = sumolib.net.readNet(str(directory / f"{name}.net.xml"), withInternal=True)
    return _NET_CACHE[key]


def sumo_binary(name: str) -> Path:
    import sumo  # eclipse-sumo wheel

    p = Path(sumo.SUMO_HOME) / "bin" / name
    if not p.is_file():
        p = Path(sys.executable).parent / name
    assert p.is_file(), f"{name} of the eclipse-sumo wheel not found"
    return p


# ----------------------------------------------------------------------------------------
# geometry helpers
# ----------------------------------------------------------------------------------------


def dedup(points) -> np.ndarray:
    pts = [tuple(points[0])]
    for p in points[1:]:
        if math.dist(p, pts[-1]) > 1e-6:
            pts.append(tuple(p))
    return np.asarray(pts, dtype=float)


def seg_headings(pts: np.ndarray) -> np.ndarray:
    d = np.diff(pts, axis=0)
    return np.unwrap(np.arctan2(d[:, 1], d[:, 0]))


def arclength(pts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])


def three_point_curvature(pts: np.ndarray, k: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Signed curvature (left positive) of the circle through points i-k, i, i+k."""
    s = arclength(pts)
    a, b, c = pts[:-2 * k], pts[k:-k], pts[2 * k:]
    ab, bc, ca = b - a, c - b, a - c
    cross = ab[:, 0] * bc[:, 1] - ab[:, 1] * bc[:, 0]
    la, lb, lc = (np.hypot(*v.T) for v in (ab, bc, ca))
    kappa = 2.0 * cross / (la * lb * lc)
    return s[k:-k], kappa


def fit_circle(pts: np.ndarray) -> float:
    """Least-squares (Kasa) circle fit; returns the radius."""
    x, y = pts[:, 0], pts[:, 1]
    xm, ym = x.mean(), y.mean()
    u, v = x - xm, y - ym
    A = np.column_stack([2 * u, 2 * v, np.ones_like(u)])
    sol, *_ = np.linalg.lstsq(A, u * u + v * v, rcond=None)
    uc, vc, c = sol
    return float(math.sqrt(c + uc * uc + vc * vc))


def walk(net, edges: list[str], first_lane: int, change_lanes: bool = False):
    """Follow the lanes a vehicle uses on the route, keeping its lane.

    Returns the list of lanes (normal and internal).  With change_lanes, a lane without a
    connection to the next edge is swapped for the nearest lane of the same edge that has one
    (lane lengths within an edge are equal, so route lengths stay right).
    """
    lane = net.getEdge(edges[0]).getLane(first_lane)
    lanes = [lane]
    for nxt in edges[1:]:
        conns = [c for c in lane.getOutgoing() if c.getTo().getID() == nxt]
        if not conns and change_lanes:
            edge = lane.getEdge()
            for other in sorted(edge.getLanes(), key=lambda ln: abs(ln.getIndex() - lane.getIndex())):
                conns = [c for c in other.getOutgoing() if c.getTo().getID() == nxt]
                if conns:
                    break
        assert conns, f"{lane.getID()} has no connection to {nxt}"
        conn = conns[0]
        via = conn.getViaLaneID()
        if via:
            lanes.append(net.getLane(via))
        lane = conn.getToLane()
        lanes.append(lane)
    return lanes


def joined_shape(lanes) -> tuple[np.ndarray, float]:
    pts = []
    for lane in lanes:
        shape = lane.getShape()
        if pts:
            gap = math.dist(pts[-1], shape[0])
            assert gap < 0.01, f"gap of {gap:.3f} m before {lane.getID()}"
        pts.extend(shape)
    return dedup(pts), sum(lane.getLength() for lane in lanes)


def lane_offset(n_lanes: int, index: int) -> float:
    """Distance of the centre of lane `index` to the right of the edge's reference (left) border."""
    return (n_lanes - index - 0.5) * LANE_WIDTH


# ----------------------------------------------------------------------------------------
# tests common to all networks
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_edges_and_lane_attributes(name):
    net = load(name)
    normal = {e.getID(): e for e in net.getEdges(withInternal=False)}
    assert set(normal) == set(LANES[name])
    for eid, n in LANES[name].items():
        edge = normal[eid]
        assert edge.getLaneNumber() == n, eid
        for lane in edge.getLanes():
            assert lane.getWidth() == pytest.approx(LANE_WIDTH, abs=1e-6)
            assert lane.getSpeed() == pytest.approx(V_RAMP if eid in ("ramp", "offramp") else V_MOTORWAY, abs=1e-3)
            assert not lane.allows("pedestrian") and not lane.allows("bicycle")
            assert lane.allows("passenger") and lane.allows("truck")


@pytest.mark.parametrize("name", NAMES)
def test_net_coordinates_not_shifted(name):
    root = ET.parse(NETS / f"{name}.net.xml").getroot()
    loc = root.find("location")
    assert loc.get("netOffset") in ("0.0000,0.0000", "0.00,0.00")
    # the route starts at the origin (left border of the carriageway) heading +x
    net = load(name)
    first = net.getEdge(ROUTES[name]["main"][0])
    assert first.getFromNode().getCoord() == pytest.approx((0.0, 0.0), abs=1e-6)


@pytest.mark.parametrize("name", NAMES)
def test_main_route_length_and_smoothness(name):
    net = load(name)
    edges = ROUTES[name]["main"]
    n_first = net.getEdge(edges[0]).getLaneNumber()
    # every lane of the first edge that continues to the end of the route
    continuing = range(1, n_first) if name == "lanedrop" else range(n_first)
    for k in continuing:
        lanes = walk(net, edges, k)
        pts, length = joined_shape(lanes)
        assert length == pytest.approx(MAIN_LENGTH[name], abs=1.0), (k, length)
        dth = np.abs(np.diff(seg_headings(pts)))
        assert dth.max() < 0.01, f"kink of {math.degrees(dth.max()):.3f} deg on lane {k}"


@pytest.mark.parametrize("name", NAMES)
def test_shape_points_dense_on_curves(name):
    net = load(name)
    for edge in net.getEdges(withInternal=True):
        for lane in edge.getLanes():
            pts = dedup(lane.getShape())
            if len(pts) < 3:
                continue
            seg = np.hypot(*np.diff(pts, axis=0).T)
            turn = np.abs(np.diff(seg_headings(pts)))  # turn at interior vertices
            for i in np.nonzero(seg > 5.01)[0]:
                # a long segment is allowed only where the polyline does not turn
                neighbours = [turn[j] for j in (i - 1, i) if 0 <= j < len(turn)]
                assert max(neighbours) < 1e-3, (lane.getID(), i, seg[i])


# ----------------------------------------------------------------------------------------
# straight3
# ----------------------------------------------------------------------------------------


def test_straight3_is_straight():
    net = load("straight3")
    for eid in ("entry", "main"):
        for lane in net.getEdge(eid).getLanes():
            ys = {round(y, 4) for _, y in lane.getShape()}
            assert ys == {-lane_offset(3, lane.getIndex())}, lane.getID()
    assert net.getEdge("main").getToNode().getCoord() == pytest.approx((6000.0, 0.0), abs=1e-6)


# ----------------------------------------------------------------------------------------
# curved3
# ----------------------------------------------------------------------------------------

# design line (left border): 800 straight, 200 clothoid, 600 arc R 800 left, 200 clothoid,
# 600 straight, 200 clothoid, 800 arc R 1000 right, 200 clothoid, 2400 straight
R_LEFT, R_RIGHT = 800.0, 1000.0
L_CLOTHOID = 200.0
L_ARC_LEFT, L_ARC_RIGHT = 600.0, 800.0


def _bend_analysis(pts: np.ndarray, sign: int, radius: float, d: float):
    """Locate the clothoid-arc-clothoid sequence of one bend on a lane centreline.

    Returns (lengths of entry clothoid, arc, exit clothoid along the lane, circle-fit radius,
    three-point radii on the arc, max linear-fit residual on the clothoids).
    """
    s, kap = three_point_curvature(pts)
    r_lane = radius + sign * d  # left bend: lanes to the right are outside
    k_full = sign / r_lane
    kn = kap / k_full  # normalised curvature: 0 on straights, 1 on the arc
    bend = np.nonzero(kn > 0.05)[0]
    assert len(bend), "bend not found"
    # restrict to this bend (contiguous run)
    runs = np.split(bend, np.nonzero(np.diff(bend) > 1)[0] + 1)
    run = max(runs, key=len)
    i0, i1 = run[0], run[-1]
    seg = slice(i0, i1 + 1)
    s_b, kn_b = s[seg], kn[seg]
    on_arc = np.nonzero(kn_b > 0.99)[0]
    a0, a1 = on_arc[0], on_arc[-1]

    def clothoid_fit(mask):
        ss, kk = s_b[mask], kn_b[mask]
        slope, icpt = np.polyfit(ss, kk, 1)
        resid = np.abs(kk - (slope * ss + icpt)).max()
        return slope, icpt, resid

    m_in = (kn_b > 0.15) & (kn_b < 0.85) & (np.arange(len(s_b)) < a0)
    m_out = (kn_b > 0.15) & (kn_b < 0.85) & (np.arange(len(s_b)) > a1)
    sl_in, ic_in, res_in = clothoid_fit(m_in)
    sl_out, ic_out, res_out = clothoid_fit(m_out)
    # where the linear curvature ramps reach 0 and 1
    in0, in1 = -ic_in / sl_in, (1 - ic_in) / sl_in
    out1, out0 = (1 - ic_out) / sl_out, -ic_out / sl_out
    # arc points: strictly inside the arc (3-point window of +-12 m must not touch the clothoids)
    arc_mask = (s > in1 + 15) & (s < out1 - 15)
    arc_pts = pts[3:-3][arc_mask]
    r_fit = fit_circle(arc_pts)
    r3 = 1.0 / np.abs(kap[arc_mask])
    return (in1 - in0, out1 - in1, out0 - out1, r_fit, r3, max(res_in, res_out), r_lane)


@pytest.mark.parametrize("lane_index", [0, 1, 2])
def test_curved3_arcs_and_clothoids(lane_index):
    net = load("curved3")
    pts = dedup(net.getEdge("main").getLane(lane_index).getShape())
    d = lane_offset(3, lane_index)
    # split at the straight between the bends (max heading = end of the left bend)
    th = seg_headings(pts)
    imax = int(np.argmax(th))
    assert th[imax] == pytest.approx(1.0, abs=1e-3)  # left bend turns by 1 rad
    assert th[-1] == pytest.approx(0.0, abs=1e-3)  # right bend turns back by 1 rad
    for part, sign, radius, l_arc in ((pts[: imax + 2], +1, R_LEFT, L_ARC_LEFT),
                                      (pts[imax:], -1, R_RIGHT, L_ARC_RIGHT)):
        l_in, l_arc_lane, l_out, r_fit, r3, resid, r_lane = _bend_analysis(part, sign, radius, d)
        assert r_fit == pytest.approx(r_lane, rel=2e-3), (sign, r_fit, r_lane)
        assert np.all(np.abs(r3 / r_lane - 1) < 0.01), (sign, r3.min(), r3.max(), r_lane)
        scale = r_lane / radius  # lengths along the lane scale with the offset radius
        assert l_arc_lane == pytest.approx(l_arc * scale, abs=5.0)
        assert l_in == pytest.approx(L_CLOTHOID, abs=5.0)
        assert l_out == pytest.approx(L_CLOTHOID, abs=5.0)
        assert resid < 0.02


def test_curved3_design_line_matches_profile():
    """The edge's own shape (design line = left border) ends where the profile says."""
    # closed form of the end point: integrate the documented profile independently (fine Euler)
    prof = [(800, 0, 0), (200, 0, 1 / R_LEFT), (600, 1 / R_LEFT, 1 / R_LEFT), (200, 1 / R_LEFT, 0),
            (600, 0, 0), (200, 0, -1 / R_RIGHT), (800, -1 / R_RIGHT, -1 / R_RIGHT),
            (200, -1 / R_RIGHT, 0), (2400, 0, 0)]
    x = y = th = 0.0
    h = 0.05
    for length, k0, k1 in prof:
        n = int(round(length / h))
        for i in range(n):
            t = (i + 0.5) * h
            thm = th + k0 * t + 0.5 * (k1 - k0) / length * t * t
            x += h * math.cos(thm)
            y += h * math.sin(thm)
        th += k0 * length + 0.5 * (k1 - k0) * length
    net = load("curved3")
    end = net.getEdge("main").getToNode().getCoord()
    assert end == pytest.approx((x, y), abs=0.05)
    raw = dedup(net.getEdge("main").getRawShape())
    assert arclength(raw)[-1] + 300.0 == pytest.approx(6000.0, abs=0.05)


# ----------------------------------------------------------------------------------------
# onramp
# ----------------------------------------------------------------------------------------


def test_onramp_acceleration_lane():
    net = load("onramp")
    ramp, up, acc, down = (net.getEdge(e) for e in ("ramp", "mw_up", "mw_accel", "mw_down"))
    # lane 0 of mw_accel is the acceleration lane, continuing the ramp
    assert acc.getLane(0).isAccelerationLane()
    assert not any(acc.getLane(k).isAccelerationLane() for k in (1, 2, 3))
    ramp_out = [(c.getToLane().getID()) for c in ramp.getLane(0).getOutgoing()]
    assert ramp_out == ["mw_accel_0"]
    for k in range(3):
        assert [c.getToLane().getID() for c in up.getLane(k).getOutgoing()] == [f"mw_accel_{k + 1}"]
        assert [c.getToLane().getID() for c in acc.getLane(k + 1).getOutgoing()] == [f"mw_down_{k}"]
    # the acceleration lane ends: no successor, vehicles must change to lane 1
    assert acc.getLane(0).getOutgoing() == []
    # lengths: ramp ~400 m, acceleration lane ~300 m (incl. internal lanes)
    ramp_lanes = walk(net, ["ramp", "mw_accel"], 0)
    assert sum(lane.getLength() for lane in ramp_lanes[:-1]) == pytest.approx(400.0, abs=5.0)
    acc_len = acc.getLength() + net.getLane(":n_merge_0_0").getLength()
    assert acc_len == pytest.approx(300.0, abs=5.0)
    # the through lanes keep their lateral position, the acceleration lane lies right of them
    for k in range(3):
        y_up = {round(p[1], 4) for p in up.getLane(k).getShape()}
        y_acc = {round(p[1], 4) for p in acc.getLane(k + 1).getShape()}
        assert y_up == y_acc == {-lane_offset(3, k)}
    assert {round(p[1], 4) for p in acc.getLane(0).getShape()} == {-lane_offset(4, 0)}
    # merge point and end of the acceleration lane (x of the nodes)
    assert acc.getFromNode().getCoord() == pytest.approx((1500.0, 0.0))
    assert acc.getToNode().getCoord() == pytest.approx((1800.0, 0.0))


def test_onramp_ramp_geometry():
    net = load("onramp")
    pts, _ = joined_shape(walk(net, ["ramp", "mw_accel"], 0))
    th = seg_headings(pts)
    # approaches from the right at a small angle and joins tangentially
    assert 0.05 < th[0] < math.radians(10)
    assert abs(th[-1]) < 1e-6
    assert np.all(np.diff(th) <= 1e-6)  # only turns right (towards the motorway direction)
    assert pts[0][1] < -3 * LANE_WIDTH - 10  # starts >10 m right of the motorway border
    # the ramp stays to the right of the motorway's right border
    assert np.all(pts[:, 1] <= -3 * LANE_WIDTH - LANE_WIDTH / 2 + 1e-6)
    assert np.max(np.abs(np.diff(th))) < 0.01


# ----------------------------------------------------------------------------------------
# offramp
# ----------------------------------------------------------------------------------------


def test_offramp_deceleration_lane_and_exit():
    net = load("offramp")
    up, dec, down, ramp = (net.getEdge(e) for e in ("mw_up", "mw_decel", "mw_down", "offramp"))
    for k in range(3):  # the through lanes shift up one index on mw_decel and back down after it
        assert [c.getToLane().getID() for c in up.getLane(k).getOutgoing()] == [f"mw_decel_{k + 1}"]
        assert [c.getToLane().getID() for c in dec.getLane(k + 1).getOutgoing()] == [f"mw_down_{k}"]
        y = [{round(p[1], 4) for p in e.getLane(i).getShape()}
             for e, i in ((up, k), (dec, k + 1), (down, k))]
        assert y[0] == y[1] == y[2] == {-lane_offset(3, k)}
    # the deceleration lane is entered by a lane change only and leads to the off-ramp only
    assert not any(c.getToLane().getID() == "mw_decel_0" for k in range(3)
                   for c in up.getLane(k).getOutgoing())
    assert [c.getToLane().getID() for c in dec.getLane(0).getOutgoing()] == ["offramp_0"]
    assert {round(p[1], 4) for p in dec.getLane(0).getShape()} == {-lane_offset(4, 0)}
    assert dec.getLength() + net.getLane(":n_decel_0_0").getLength() == pytest.approx(250.0, abs=5.0)
    assert ramp.getLength() == pytest.approx(400.0, abs=5.0)
    # the off-ramp leaves tangentially, turning right only, and ends 15 m right of the motorway
    pts, _ = joined_shape(walk(net, ["mw_decel", "offramp"], 0))
    th = seg_headings(pts)
    assert abs(th[0]) < 1e-6 and -math.radians(10) < th[-1] < -0.05
    assert np.all(np.diff(th) <= 1e-6) and np.max(np.abs(np.diff(th))) < 0.01
    assert pts[-1][1] < -3 * LANE_WIDTH - 10


# ----------------------------------------------------------------------------------------
# lanedrop
# ----------------------------------------------------------------------------------------


def test_lanedrop_three_to_two():
    net = load("lanedrop")
    up, down = net.getEdge("mw_up"), net.getEdge("mw_down")
    assert up.getLaneNumber() == 3 and down.getLaneNumber() == 2
    # the rightmost lane (index 0) ends; lanes 1, 2 continue as lanes 0, 1
    assert up.getLane(0).getOutgoing() == []
    assert [c.getToLane().getID() for c in up.getLane(1).getOutgoing()] == ["mw_down_0"]
    assert [c.getToLane().getID() for c in up.getLane(2).getOutgoing()] == ["mw_down_1"]
    assert up.getToNode().getCoord() == pytest.approx((2500.0, 0.0))
    for k_up, k_down in ((1, 0), (2, 1)):
        y_up = {round(p[1], 4) for p in up.getLane(k_up).getShape()}
        y_down = {round(p[1], 4) for p in down.getLane(k_down).getShape()}
        assert y_up == y_down == {-lane_offset(3, k_up)}


# ----------------------------------------------------------------------------------------
# rebuild reproduces the committed nets
# ----------------------------------------------------------------------------------------


def _build(outdir: Path) -> None:
    res = subprocess.run([sys.executable, "-m", "sumo_nets.build", "--outdir", str(outdir)],
                         cwd=REPO, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    # netconvert printed nothing but "built ..." lines: no warnings
    noise = [ln for ln in res.stdout.splitlines() + res.stderr.splitlines()
             if ln.strip() and not ln.startswith("built ")]
    assert noise == [], noise


@pytest.fixture(scope="module")
def rebuilt(tmp_path_factory):
    a = tmp_path_factory.mktemp("nets_a")
    b = tmp_path_factory.mktemp("nets_b")
    _build(a)
    _build(b)
    return a, b


def _summary(net):
    lanes = {}
    for edge in net.getEdges(withInternal=True):
        for lane in edge.getLanes():
            lanes[lane.getID()] = (round(lane.getLength(), 3), [tuple(p) for p in lane.getShape()])
    conns = set()
    for edge in net.getEdges(withInternal=False):
        for lane in edge.getLanes():
            for c in lane.getOutgoing():
                conns.add((lane.getID(), c.getToLane().getID(), c.getViaLaneID()))
    return lanes, conns


@pytest.mark.parametrize("name", NAMES)
def test_rebuild_reproduces_committed(rebuilt, name):
    a, _ = rebuilt
    lanes_c, conns_c = _summary(load(name))
    lanes_r, conns_r = _summary(load(name, a))
    assert set(lanes_r) == set(lanes_c)
    assert conns_r == conns_c
    for lid, (length, shape) in lanes_c.items():
        length_r, shape_r = lanes_r[lid]
        assert length_r == pytest.approx(length, abs=1e-3), lid
        assert np.allclose(shape_r, shape, atol=1e-3), lid
    # the plain-XML sources are regenerated byte for byte
    for f in sorted(NETS.glob(f"{name}.*.xml")):
        if not f.name.endswith(".net.xml"):
            assert (a / f.name).read_bytes() == f.read_bytes(), f.name


@pytest.mark.parametrize("name", NAMES)
def test_build_is_deterministic(rebuilt, name):
    a, b = rebuilt
    for f in sorted(a.glob(f"{name}.*")):
        assert f.read_bytes() == (b / f.name).read_bytes(), f.name
    assert "generated on" not in (a / f"{name}.net.xml").read_text(encoding="utf-8")


# ----------------------------------------------------------------------------------------
# a short SUMO run: vehicles drive every route to its end without teleports or warnings
# ----------------------------------------------------------------------------------------


def _routes_xml(name: str) -> tuple[str, dict[str, str]]:
    lines = ['<routes>', '  <vType id="car" vClass="passenger" length="5" maxSpeed="40"/>']
    for rid, edges in ROUTES[name].items():
        lines.append(f'  <route id="{rid}" edges="{" ".join(edges)}"/>')
    route_of = {}
    n_first = LANES[name][ROUTES[name]["main"][0]]
    for t in range(0, 60, 5):
        for lane in range(n_first):
            vid = f"main_l{lane}_t{t}"
            route_of[vid] = "main"
            lines.append(f'  <vehicle id="{vid}" type="car" route="main" depart="{t}" '
                         f'departLane="{lane}" departPos="0" departSpeed="max"/>')
        for rid in ("ramp", "exit"):
            if rid in ROUTES[name]:
                vid = f"{rid}_t{t}"
                route_of[vid] = rid
                lines.append(f'  <vehicle id="{vid}" type="car" route="{rid}" depart="{t}" '
                             f'departLane="0" departPos="0" departSpeed="max"/>')
    lines.append("</routes>")
    return "\n".join(lines) + "\n", route_of


@pytest.mark.parametrize("name", NAMES)
def test_sumo_drives_all_routes(name, tmp_path):
    routes, route_of = _routes_xml(name)
    (tmp_path / "r.rou.xml").write_text(routes)
    import sumo

    env = dict(os.environ, SUMO_HOME=str(sumo.SUMO_HOME))
    cmd = [str(sumo_binary("sumo")), "-n", str(NETS / f"{name}.net.xml"), "-r", "r.rou.xml",
           "--end", "400", "--no-step-log", "--xml-validation", "never",
           "--tripinfo-output", "trip.xml", "--statistic-output", "stats.xml",
           "--lanechange-output", "lc.xml"]
    res = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=60, env=env)
    assert res.returncode == 0, res.stderr
    assert "Warning" not in res.stderr and "Error" not in res.stderr, res.stderr
    stats = ET.parse(tmp_path / "stats.xml").getroot()
    assert int(stats.find("teleports").get("total")) == 0
    trips = {t.get("id"): t for t in ET.parse(tmp_path / "trip.xml").getroot().iter("tripinfo")}
    assert set(trips) == set(route_of), "not every vehicle reached the end of its route"
    net = load(name)
    expected = {rid: sum(lane.getLength() for lane in walk(net, edges, 0, change_lanes=True))
                for rid, edges in ROUTES[name].items()}
    for vid, trip in trips.items():
        assert float(trip.get("routeLength")) == pytest.approx(expected[route_of[vid]], abs=0.5), vid
    changes = [lc.get("from") for lc in ET.parse(tmp_path / "lc.xml").getroot().iter("change")]
    if name == "lanedrop":
        # vehicles starting on the ending lane had to merge left before x = 2500
        assert changes.count("mw_up_0") >= 12
    if name == "onramp":
        # every ramp vehicle left the acceleration lane
        assert changes.count("mw_accel_0") >= 12
    if name == "offramp":
        # every exiting vehicle changed into the deceleration lane (it has no predecessor)
        assert changes.count("mw_decel_1") >= 12


# ----------------------------------------------------------------------------------------
# motorway100: the 100 km road of scale and penetration studies
# ----------------------------------------------------------------------------------------

M100_INTERCHANGES_KM = range(10, 100, 10)  # an off-ramp at x0 and an on-ramp at x0 + 1 km


def _m100_main():
    net = load("motorway100")
    edges, e = [], net.getEdge("mw_0")
    while True:
        edges.append(e.getID())
        nxt = [o for o in e.getOutgoing() if o.getID().startswith("mw_")]
        if not nxt:
            return net, edges
        e = nxt[0]


def test_motorway100_layout():
    """100 km of 4 lanes at 130 km/h along +x, edges of at most 1 km, and at every 10 km a 250 m
    deceleration lane with an off-ramp, then 1 km on an on-ramp with a 300 m acceleration lane."""
    net, main = _m100_main()
    start = [net.getEdge(e).getFromNode().getCoord()[0] for e in main]
    end = net.getEdge(main[-1]).getToNode().getCoord()
    assert start[0] == 0.0 and end == pytest.approx((100_000.0, 0.0), abs=1e-6)
    assert np.diff(start + [end[0]]).max() == pytest.approx(1000.0, abs=1e-6)
    for e in main:
        edge = net.getEdge(e)
        for lane in edge.getLanes():  # the left border stays on y = 0: through lanes never move
            assert {round(y, 4) for _, y in lane.getShape()} == {-lane_offset(edge.getLaneNumber(), lane.getIndex())}
        assert all(lane.getSpeed() == pytest.approx(V_MOTORWAY, abs=1e-3) for lane in edge.getLanes())
    five = [e for e in main if net.getEdge(e).getLaneNumber() == 5]
    assert len(five) == 2 * len(M100_INTERCHANGES_KM)
    assert {net.getEdge(e).getLaneNumber() for e in main} == {4, 5}
    for km in M100_INTERCHANGES_KM:
        x0 = 1000 * km
        decel, accel = net.getEdge(f"mw_{x0 - 250}"), net.getEdge(f"mw_{x0 + 1000}")
        assert decel.getLaneNumber() == 5 and accel.getLaneNumber() == 5
        for edge, length in ((decel, 250.0), (accel, 300.0)):  # node to node (junctions shorten the lanes)
            assert edge.getToNode().getCoord()[0] - edge.getFromNode().getCoord()[0] == pytest.approx(length, abs=1e-6)
        off, on = net.getEdge(f"off_{km // 10}"), net.getEdge(f"on_{km // 10}")
        assert [c.getTo().getID() for c in decel.getLane(0).getOutgoing()] == [off.getID()]
        assert [c.getTo().getID() for c in on.getLane(0).getOutgoing()] == [accel.getID()]
        assert accel.getLane(0).getOutgoing() == []  # the acceleration lane ends
        assert off.getLane(0).getSpeed() == pytest.approx(V_RAMP, abs=1e-3)
        # the ramps meet the lane's line tangentially (heading within 0.01 rad of +x)
        for shape in (off.getLane(0).getShape()[:2], on.getLane(0).getShape()[-2:]):
            (xa, ya), (xb, yb) = shape
            assert abs(math.atan2(yb - ya, xb - xa)) < 0.01


def test_sumo_drives_motorway100_end_to_end_and_ramp_to_ramp(tmp_path):
    """SUMO's own cars drive the 100 km end to end in every lane, and from each on-ramp to the
    next off-ramp, without a warning or a teleport, every ramp car leaving the acceleration lane."""
    net, main = _m100_main()
    lines = ['<routes>', '  <vType id="car" vClass="passenger" length="5" maxSpeed="40"/>',
             f'  <route id="main" edges="{" ".join(main)}"/>']
    ramps = range(1, len(M100_INTERCHANGES_KM))
    for j in ramps:
        a = main.index(f"mw_{10_000 * j + 1000}")
        b = main.index(f"mw_{10_000 * (j + 1) - 250}")
        lines.append(f'  <route id="r{j}" edges="on_{j} {" ".join(main[a:b + 1])} off_{j + 1}"/>')
    for lane in range(4):
        lines.append(f'  <vehicle id="main_l{lane}" type="car" route="main" depart="0" departLane="{lane}" '
                     'departPos="0" departSpeed="max"/>')
    for t in (0, 10):
        for j in ramps:
            lines.append(f'  <vehicle id="r{j}_t{t}" type="car" route="r{j}" depart="{t}" departLane="0" '
                         'departPos="0" departSpeed="max"/>')
    n_ramp = 2 * len(ramps)
    lines.append("</routes>")
    (tmp_path / "r.rou.xml").write_text("\n".join(lines) + "\n")
    import sumo

    env = dict(os.environ, SUMO_HOME=str(sumo.SUMO_HOME))
    cmd = [str(sumo_binary("sumo")), "-n", str(NETS / "motorway100.net.xml"), "-r", "r.rou.xml",
           "--step-length", "1", "--end", "3600", "--no-step-log", "--xml-validation", "never",
           "--tripinfo-output", "trip.xml", "--statistic-output", "stats.xml", "--lanechange-output", "lc.xml"]
    res = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert res.returncode == 0, res.stderr
    assert "Warning" not in res.stderr and "Error" not in res.stderr, res.stderr
    assert int(ET.parse(tmp_path / "stats.xml").getroot().find("teleports").get("total")) == 0
    trips = {t.get("id"): float(t.get("routeLength")) for t in ET.parse(tmp_path / "trip.xml").getroot().iter("tripinfo")}
    assert len(trips) == n_ramp + 4, "not every car reached the end of its route"
    for lane in range(4):
        assert trips[f"main_l{lane}"] == pytest.approx(100_000.0, abs=50.0)
    accel_lanes = {f"mw_{1000 * km + 1000}_0" for km in M100_INTERCHANGES_KM}
    left_accel = {c.get("id") for c in ET.parse(tmp_path / "lc.xml").getroot().iter("change")
                  if c.get("from") in accel_lanes}
    assert left_accel == {f"r{j}_t{t}" for j in ramps for t in (0, 10)}
