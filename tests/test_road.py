"""Road geometry layer: reference lines, the virtual car on the road, road-frame targets.

Analytic curves are sampled like SUMO stores its shapes (every 4 m, rounded to 0.1 mm), so
the tolerances below are the accuracy the line recovers from real network data.
"""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
from scipy.special import fresnel

from formation_traci.control.formation import rigid_targets
from formation_traci.road.geometry import (
    ReferenceLine,
    clean_polyline,
    lane_offsets,
    load_net,
    reference_line_from_net,
    route_lanes,
    route_shape,
)
from formation_traci.road.leader import road_leader_state
from formation_traci.road.targets import road_targets
from sumo_nets import net_path

ROAD_PKG = Path(__file__).resolve().parents[1] / "formation_traci" / "road"
LANE_WIDTH = 3.5  # [m]
SPACING = 4.0  # SUMO shape point spacing on curves [m]


# ----------------------------------------------------------------------------------------
# analytic curves, sampled like SUMO shapes
# ----------------------------------------------------------------------------------------


def _sumo_round(pts: np.ndarray) -> np.ndarray:
    return np.round(pts, 4)  # netconvert --precision 4


def circle_points(radius: float, length: float, theta0: float = 0.4,
                  p0=(1000.0, -500.0)) -> np.ndarray:
    """Arc of signed radius (left positive) from p0 with initial heading theta0."""
    s = np.arange(0.0, length + 1e-9, SPACING)
    x, y = radius * np.sin(s / radius), radius * (1.0 - np.cos(s / radius))
    c, sn = np.cos(theta0), np.sin(theta0)
    return _sumo_round(np.c_[p0[0] + c * x - sn * y, p0[1] + sn * x + c * y])


def clothoid_xy(s: np.ndarray, a: float) -> np.ndarray:
    """Clothoid kappa = s / a^2 from the origin heading +x (Fresnel integrals)."""
    k = a * np.sqrt(np.pi)
    fs, fc = fresnel(s / k)
    return k * np.c_[fc, fs]


CIRCLES = [(800.0, 1200.0), (-1000.0, 1200.0), (150.0, 600.0)]
CLOTHOID_A, CLOTHOID_L = 400.0, 600.0  # kappa 0 -> 1/266.7 m


@pytest.fixture(scope="module")
def clothoid() -> ReferenceLine:
    s = np.arange(0.0, CLOTHOID_L + 1e-9, SPACING)
    return ReferenceLine.from_points(_sumo_round(clothoid_xy(s, CLOTHOID_A)))


@pytest.fixture(scope="module")
def curved_net():
    return load_net(net_path("curved3"))


@pytest.fixture(scope="module")
def curved(curved_net) -> ReferenceLine:
    return reference_line_from_net(curved_net, ["entry", "main"], 1)


# ----------------------------------------------------------------------------------------
# ReferenceLine on analytic curves
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("radius,length", CIRCLES)
def test_circle_curvature_heading_length(radius, length):
    line = ReferenceLine.from_points(circle_points(radius, length))
    true_len = np.arange(0.0, length + 1e-9, SPACING)[-1]
    assert abs(line.length - true_len) < 1e-3
    s = np.linspace(0.0, line.length, 3001)
    f = line.frame(s)
    # whole line, ends included
    assert np.max(np.abs(f.curvature * radius - 1.0)) < 0.005
    assert np.max(np.abs(f.heading - (0.4 + s / radius))) < 1e-4
    assert np.max(np.abs(f.curvature_rate)) * radius ** 2 < 0.15  # vs 1/R^2
    # the curve passes through the samples
    centre = np.array([1000.0 - radius * np.sin(0.4), -500.0 + radius * np.cos(0.4)])
    assert np.max(np.abs(np.hypot(*(f.position - centre).T) - abs(radius))) < 2e-4


def test_clothoid_curvature_ramp(clothoid):
    a2 = CLOTHOID_A ** 2
    s = np.linspace(0.0, clothoid.length, 3001)
    f = clothoid.frame(s)
    kappa_true = s / a2
    assert abs(clothoid.length - CLOTHOID_L) < 1e-3
    # 0.5 % of the largest curvature everywhere, 0.5 % relative where kappa >= 1/1600
    assert np.max(np.abs(f.curvature - kappa_true)) < 0.005 * CLOTHOID_L / a2
    far = s > 100.0
    assert np.max(np.abs(f.curvature[far] / kappa_true[far] - 1.0)) < 0.005
    assert np.max(np.abs(f.heading - s ** 2 / (2.0 * a2))) < 1e-4
    assert np.max(np.abs(f.position - clothoid_xy(s, CLOTHOID_A))) < 2e-4
    # curvature rate 1/A^2: 1 % inside, 5 % at the ends (one-sided data)
    inner = (s > 40.0) & (s < clothoid.length - 40.0)
    assert np.max(np.abs(f.curvature_rate[inner] * a2 - 1.0)) < 0.01
    assert np.max(np.abs(f.curvature_rate * a2 - 1.0)) < 0.05


def test_derivatives_are_consistent(clothoid):
    """heading' = kappa, kappa' = curvature_rate, |c'| = 1 and c' = t (central FD)."""
    h = 1e-3
    s = np.linspace(1.0, clothoid.length - 1.0, 500)
    fp, fm, f = clothoid.frame(s + h), clothoid.frame(s - h), clothoid.frame(s)
    dpos = (fp.position - fm.position) / (2 * h)
    np.testing.assert_allclose(dpos, f.tangent, atol=1e-8)
    np.testing.assert_allclose(np.hypot(*f.tangent.T), 1.0, atol=1e-12)
    np.testing.assert_allclose((fp.heading - fm.heading) / (2 * h), f.curvature, atol=1e-9)
    np.testing.assert_allclose((fp.curvature - fm.curvature) / (2 * h), f.curvature_rate,
                               atol=1e-10)
    np.testing.assert_allclose(f.normal, np.c_[-np.sin(f.heading), np.cos(f.heading)],
                               atol=1e-12)


def test_heading_unwrapped_full_circle():
    pts = circle_points(60.0, 2.2 * np.pi * 60.0, theta0=3.0)  # more than a full turn
    line = ReferenceLine.from_points(pts)
    s = np.linspace(0.0, line.length, 4001)
    th = line.heading(s)
    assert np.all(np.diff(th) > 0.0)
    assert np.max(np.abs(th - (3.0 + s / 60.0))) < 1e-4


def test_frenet_round_trip(clothoid):
    rng = np.random.default_rng(1)
    s = rng.uniform(0.0, clothoid.length, 400)
    d = rng.uniform(-12.0, 12.0, 400)
    s2, d2 = clothoid.to_frenet(clothoid.from_frenet(s, d))
    np.testing.assert_allclose(s2, s, atol=1e-8)
    np.testing.assert_allclose(d2, d, atol=1e-8)
    # past the ends: the straight extension
    s = np.array([-30.0, -1.0, clothoid.length + 0.5, clothoid.length + 40.0])
    d = np.array([2.0, -3.0, 5.0, -1.0])
    s2, d2 = clothoid.to_frenet(clothoid.from_frenet(s, d))
    np.testing.assert_allclose(s2, s, atol=1e-8)
    np.testing.assert_allclose(d2, d, atol=1e-8)
    # shapes: scalar in, scalar out
    s0, d0 = clothoid.to_frenet(clothoid.from_frenet(100.0, 1.0))
    assert np.shape(s0) == () and abs(s0 - 100.0) < 1e-8 and abs(d0 - 1.0) < 1e-8


def test_extension_past_ends_is_straight(clothoid):
    L = clothoid.length
    end = clothoid.frame(L)
    f = clothoid.frame(np.array([L + 10.0, -5.0]))
    np.testing.assert_allclose(f.position[0], end.position + 10.0 * end.tangent, atol=1e-9)
    start = clothoid.frame(0.0)
    np.testing.assert_allclose(f.position[1], start.position - 5.0 * start.tangent, atol=1e-9)
    np.testing.assert_allclose(f.heading, [end.heading, start.heading], atol=1e-12)
    assert np.all(f.curvature == 0.0) and np.all(f.curvature_rate == 0.0)


def test_clean_polyline_drops_duplicates_and_splits_long_segments():
    pts = [(0.0, 0.0), (0.0, 0.0), (12.0, 0.0), (12.0, 0.0005), (16.0, 0.0)]
    out = clean_polyline(pts, min_segment=1e-3, max_segment=5.0)
    np.testing.assert_allclose(out[:, 0], [0.0, 4.0, 8.0, 12.0, 16.0])
    with pytest.raises(ValueError):
        clean_polyline([(1.0, 1.0), (1.0, 1.0)], 1e-3, 5.0)


# ----------------------------------------------------------------------------------------
# SUMO networks
# ----------------------------------------------------------------------------------------


def test_curved3_length_matches_route(curved, curved_net):
    xy, sumo_len = route_shape(curved_net, ["entry", "main"], 1)
    poly = clean_polyline(xy, 1e-3, 5.0)
    poly_len = float(np.sum(np.hypot(*np.diff(poly, axis=0).T)))
    assert abs(curved.length - poly_len) < 0.01  # chords vs arcs: ~1.5 mm
    assert abs(sumo_len - 6000.1) < 0.01  # README: includes the 0.1 m internal lane
    assert abs(curved.length - (sumo_len - 0.1)) < 0.01  # geometric length 6000 m
    assert route_lanes(curved_net, ["entry", "main"], 1) == ["entry_1", ":n1_0_1", "main_1"]


def test_curved3_arcs_and_continuity(curved):
    s = np.arange(0.0, curved.length, 0.05)
    f = curved.frame(s)
    # lane 1 is 5.25 m right of the design line: radii 805.25 (left) and 994.75 (right)
    for lo, hi, r_design, r_lane in [(1030.0, 1570.0, 800.0, 805.25),
                                     (2640.0, 3360.0, -1000.0, -994.75)]:
        on_arc = (s > lo) & (s < hi)
        k = f.curvature[on_arc]
        assert np.max(np.abs(k * r_design - 1.0)) < 0.01
        assert np.max(np.abs(k * r_lane - 1.0)) < 0.002
    # straights
    for lo, hi in [(20.0, 770.0), (1840.0, 2370.0), (3640.0, 5980.0)]:
        assert np.max(np.abs(f.curvature[(s > lo) & (s < hi)])) < 2e-6
    # continuity: curvature changes no faster than 1.2x the design clothoid rate
    # 1/(800*200) m^-2, heading steps follow curvature, no jumps at the edge joint (s = 300)
    assert np.max(np.abs(np.diff(f.curvature))) / 0.05 < 1.2 / (800.0 * 200.0)
    assert np.max(np.abs(np.diff(f.heading))) < 0.05 * 1.3e-3
    # the road turns +1 rad, then -1 rad, and ends heading +x
    assert abs(f.heading[0]) < 1e-6 and abs(curved.heading(curved.length)) < 1e-6
    assert abs(curved.heading(1850.0) - 1.0) < 1e-5


def test_curved3_neighbour_lanes_at_lane_offsets(curved, curved_net):
    offs = lane_offsets(curved_net, "main", 1)
    np.testing.assert_allclose(offs, [-LANE_WIDTH, 0.0, LANE_WIDTH])
    for k in (0, 2):
        pts = np.asarray(curved_net.getLane(f"main_{k}").getShape())
        _, d = curved.to_frenet(pts)
        np.testing.assert_allclose(d, offs[k], atol=1e-3)


def test_lane_offsets_straight3_multiples_of_lane_width():
    net = load_net(net_path("straight3"))
    for edge in ("entry", "main"):
        for ref in range(3):
            offs = lane_offsets(net, edge, ref)
            np.testing.assert_allclose(offs, (np.arange(3) - ref) * LANE_WIDTH)
            # and they are the distances between the lane shapes (left positive)
            y = np.array([ln.getShape()[0][1] for ln in net.getEdge(edge).getLanes()])
            np.testing.assert_allclose(offs, y - y[ref], atol=1e-9)
    line = reference_line_from_net(net, ["entry", "main"], 1)
    assert abs(line.length - 6000.0) < 1e-3
    np.testing.assert_allclose(line.position(np.array([0.0, 3000.0])), [[0, -5.25], [3000, -5.25]],
                               atol=1e-6)


def test_onramp_route_follows_connections():
    net = load_net(net_path("onramp"))
    lanes = route_lanes(net, ["mw_up", "mw_accel", "mw_down"], 1)
    assert lanes == ["mw_up_1", ":n_merge_0_1", "mw_accel_2", ":n_accel_end_0_1", "mw_down_1"]
    line = reference_line_from_net(net, ["mw_up", "mw_accel", "mw_down"], 1)
    assert abs(line.length - 4000.0) < 1e-3
    s = np.linspace(0.0, line.length, 801)
    assert np.max(np.abs(line.curvature(s))) < 1e-8
    np.testing.assert_allclose(lane_offsets(net, "mw_accel", 2), [-7.0, -3.5, 0.0, 3.5])


def test_lane_without_connection_raises():
    with pytest.raises(ValueError, match="no connection"):
        route_lanes(net_path("lanedrop"), ["mw_up", "mw_down"], 0)


# ----------------------------------------------------------------------------------------
# virtual car and road targets
# ----------------------------------------------------------------------------------------


def _trajectory(t):
    """s(t) with varying acceleration: s, s_dot, s_ddot."""
    s0, v0, a0, j = 60.0, 28.0, 1.2, -0.3
    return (s0 + v0 * t + a0 * t ** 2 / 2 + j * t ** 3 / 6, v0 + a0 * t + j * t ** 2 / 2,
            a0 + j * t)


OFFSETS = np.array([[0.0, 0.0], [10.0, 3.5], [-15.0, -3.5], [5.0, -7.0], [-8.0, 7.0]])


def _check_fd(line, traj, offsets, times, h=0.002, tol_v=1e-6, tol_a=2e-5):
    for t in times:
        s, v, a = traj(t)
        tg = road_targets(line, s, v, a, offsets)
        pp = road_targets(line, *traj(t + h), offsets).p
        pm = road_targets(line, *traj(t - h), offsets).p
        np.testing.assert_allclose((pp - pm) / (2 * h), tg.v, atol=tol_v)
        np.testing.assert_allclose((pp - 2 * tg.p + pm) / h ** 2, tg.a, atol=tol_a)


@pytest.mark.jit_off
def test_road_targets_derivatives_clothoid(clothoid):
    # up to kappa = 1/267 m, kappa' = 1/A^2, with dx and dy != 0 and varying speed
    _check_fd(clothoid, _trajectory, OFFSETS, np.linspace(0.0, 14.0, 15))
    tg = road_targets(clothoid, 400.0, 30.0, 0.0, OFFSETS)
    assert np.max(np.linalg.norm(tg.a, axis=1)) > 2.0  # the test sees curvature terms


@pytest.mark.jit_off
def test_road_targets_derivatives_curved3(curved):
    # across the first clothoid and into the left arc (s = 750 .. 1100)
    traj = lambda t: (750.0 + 30.0 * t + 0.5 * t ** 2, 30.0 + t, 1.0)  # noqa: E731
    _check_fd(curved, traj, OFFSETS, np.linspace(0.0, 11.0, 23))


@pytest.mark.jit_off
def test_road_targets_on_lane_centrelines(curved):
    tg = road_targets(curved, 1300.0, 30.0, 0.0, np.array([[0.0, 3.5], [20.0, -3.5]]))
    s, d = curved.to_frenet(tg.p)
    np.testing.assert_allclose(s, [1300.0, 1320.0], atol=1e-8)
    np.testing.assert_allclose(d, [3.5, -3.5], atol=1e-8)
    # the inner lane's slot moves slower in the left bend: v (1 - dy kappa)
    speeds = np.linalg.norm(tg.v, axis=1)
    np.testing.assert_allclose(speeds, 30.0 * (1.0 - np.array([3.5, -3.5]) / 805.25), rtol=2e-3)


@pytest.mark.parametrize("exact", [True, False])
@pytest.mark.jit_off
def test_road_targets_equal_rigid_targets_on_straight(exact):
    th = 0.3
    ends = np.array([[100.0, 50.0], [100.0 + 800.0 * np.cos(th), 50.0 + 800.0 * np.sin(th)]])
    if exact:
        pts = ends
    else:  # sampled every 4 m and rounded, like SUMO
        pts = _sumo_round(ends[0] + np.linspace(0.0, 1.0, 201)[:, None] * (ends[1] - ends[0]))
    line = ReferenceLine.from_points(pts)
    # rounded samples: heading noise ~1e-6 rad times |dx| <= 15 m or v ~ 30 m/s
    tol = 1e-9 if exact else 1e-4
    for s, v, a in [(200.0, 25.0, 0.0), (350.0, 31.0, -1.5)]:
        vc = road_leader_state(line, s, v, a)
        assert abs(vc.theta - th) < tol and abs(vc.omega) < tol and abs(vc.omega_dot) < tol
        rt = road_targets(line, s, v, a, OFFSETS)
        rig = rigid_targets(vc, OFFSETS)
        np.testing.assert_allclose(rt.p, rig.p, atol=tol)
        np.testing.assert_allclose(rt.v, rig.v, atol=tol)
        np.testing.assert_allclose(rt.a, rig.a, atol=tol)


@pytest.mark.jit_off
def test_road_leader_state(clothoid):
    h = 0.002
    for t in np.linspace(0.0, 14.0, 8):
        s, v, a = _trajectory(t)
        vc = road_leader_state(clothoid, s, v, a)
        np.testing.assert_allclose([vc.x, vc.y], clothoid.position(s), atol=1e-12)
        assert vc.v == v and vc.v_dot == a
        assert abs(vc.omega - v * s / CLOTHOID_A ** 2) < 0.002 * v * CLOTHOID_L / CLOTHOID_A ** 2
        # omega = d theta / dt and omega_dot = d omega / dt along s(t)
        vp, vm = road_leader_state(clothoid, *_trajectory(t + h)), road_leader_state(
            clothoid, *_trajectory(t - h))
        assert abs((vp.theta - vm.theta) / (2 * h) - vc.omega) < 1e-7
        assert abs((vp.omega - vm.omega) / (2 * h) - vc.omega_dot) < 1e-6
        # the zero-offset slot is the virtual car: rigid and road targets agree
        z = np.zeros((1, 2))
        rt, rig = road_targets(clothoid, s, v, a, z), rigid_targets(vc, z)
        for x, y in [(rt.p, rig.p), (rt.v, rig.v), (rt.a, rig.a)]:
            np.testing.assert_allclose(x, y, atol=1e-9)


def test_road_package_imports_no_traci():
    for path in ROAD_PKG.glob("*.py"):
        tree = ast.parse(path.read_text())
        names = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split(".")[0])
        assert not names & {"libsumo", "traci"}, path.name
