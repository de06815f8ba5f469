"""Maneuver building blocks without SUMO: transition law, slot assignment, gap check,
triggers, planner, schema, and the moving-slot targets of the compiled step."""
import math

import numpy as np
import pytest

from formation_traci.control.maneuvers.assign import assign_slots, min_clearance
from formation_traci.control.maneuvers.gap import GapMargins, Others, check_gaps
from formation_traci.control.maneuvers.planner import ManeuverPlanner, Situation
from formation_traci.control.maneuvers.transition import (ComfortLimits, hold_plan, quintic,
                                                          slots_at, transition_duration)
from formation_traci.control.maneuvers.triggers import queue_behind
from formation_traci.road.lanes import LaneCentres
from formation_traci.scenario import ScenarioError
from formation_traci.scenario.load import parse_scenario
from formation_traci.scenario.maneuvers import ManeuverLimits

LIM = ComfortLimits(lat_accel=1.5, lat_jerk=2.5, lon_accel=1.0, lon_jerk=2.5, min_duration=3.0)


def _profile(D, T, dt=1e-3):
    t = np.arange(0.0, T + dt / 2, dt)
    h = np.array([quintic(ti, 0.0, T) for ti in t])
    return t, D * h[:, 0], D * h[:, 1], D * h[:, 2]


def test_quintic_derivatives_match_finite_differences_and_end_at_rest():
    t, x, v, a = _profile(3.5, 4.0)
    np.testing.assert_allclose(np.gradient(x, t)[1:-1], v[1:-1], atol=2e-5)
    np.testing.assert_allclose(np.gradient(v, t)[1:-1], a[1:-1], atol=2e-5)
    assert x[0] == 0.0 and x[-1] == pytest.approx(3.5, abs=1e-12)
    assert v[0] == v[-1] == 0.0 and abs(a[-1]) < 1e-9
    # peaks from first principles: 15/8 D/T, 10/sqrt(3) D/T^2, 60 D/T^3
    assert v.max() == pytest.approx(15 / 8 * 3.5 / 4.0, rel=1e-6)
    assert np.abs(a).max() == pytest.approx(10 / math.sqrt(3) * 3.5 / 16.0, rel=1e-5)
    jerk = np.gradient(a, t)
    assert np.abs(jerk).max() == pytest.approx(60 * 3.5 / 64.0, rel=2e-3)


@pytest.mark.parametrize("d_along,d_across,binding", [
    (0.0, 3.5, "lat_jerk"),      # one lane: (60 * 3.5 / 2.5)^(1/3) = 4.38 s > sqrt(5.77 * 3.5 / 1.5) = 3.67 s
    (0.0, 12.0, "lat_accel"),    # wide move: acceleration binds
    (50.0, 3.5, "lon_accel"),    # 50 m back: sqrt(5.77 * 50 / 1.0) = 17 s
    (0.0, 0.2, "min"),
])
def test_transition_duration_keeps_every_peak_within_its_limit(d_along, d_across, binding):
    T = transition_duration(d_along, d_across, LIM)
    _, _, _, a_lat = _profile(d_across, T)
    _, _, _, a_lon = _profile(d_along, T)
    j_lat = np.gradient(a_lat, 1e-3)
    j_lon = np.gradient(a_lon, 1e-3)
    peaks = {"lat_accel": np.abs(a_lat).max() / LIM.lat_accel, "lat_jerk": np.abs(j_lat).max() / LIM.lat_jerk,
             "lon_accel": np.abs(a_lon).max() / LIM.lon_accel, "lon_jerk": np.abs(j_lon).max() / LIM.lon_jerk}
    assert max(peaks.values()) <= 1.0 + 3e-3
    if binding == "min":
        assert T == LIM.min_duration
    else:
        assert peaks[binding] == pytest.approx(1.0, abs=3e-3)


def test_plan_rows_hold_and_move_slots():
    plan = hold_plan(np.array([[0.0, -3.5], [0.0, 0.0]]))
    plan[0, 2:4] = [-25.0, 0.0]
    plan[0, 4:6] = [10.0, 8.0]
    off, rate, acc = slots_at(plan, 14.0)
    np.testing.assert_allclose(off, [[-12.5, -1.75], [0.0, 0.0]])
    assert rate[0, 0] == pytest.approx(-25 * 15 / 8 / 8.0) and rate[1].tolist() == [0.0, 0.0]
    np.testing.assert_allclose(slots_at(plan, 30.0)[0], [[-25.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(slots_at(plan, 5.0)[0], [[0.0, -3.5], [0.0, 0.0]])


def test_assignment_avoids_crossing_paths():
    # two abreast swap sides if assigned naively; the optimum keeps them apart
    start = np.array([[0.0, -3.5], [0.0, 3.5]])
    goal = np.array([[0.0, -3.5], [0.0, 3.5]])
    idx = assign_slots(start, goal)
    assert idx.tolist() == [0, 1]
    L, W = 4.6, 1.8
    assert min_clearance(start, goal[idx], L, W) > 0
    assert min_clearance(start, goal[::-1], L, W) < 0  # the swap would collide
    # three abreast -> column in the reference lane: the centre member keeps its place
    abreast = np.array([[0.0, -3.5], [0.0, 0.0], [0.0, 3.5]])
    column = np.array([[-50.0, 0.0], [0.0, 0.0], [-25.0, 0.0]])
    idx = assign_slots(abreast, column)
    assert idx[1] == 1
    assert min_clearance(abreast, column[idx], L, W) > 0.5
    # more slots than members: the nearest ones are taken
    idx = assign_slots(abreast[:2], column)
    assert idx.tolist() == [2, 1]


def _others(rows):
    ids = tuple(r[0] for r in rows)
    a = np.array([r[1:] for r in rows], dtype=float).reshape(-1, 5)
    return Others(ids, a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4])


def test_gap_check_predicts_margins_front_and_rear():
    one = lambda x: np.array([x], dtype=float)
    args = dict(d0=one(0.0), d1=one(-3.5), length=one(4.6), width=one(1.8), v_m=one(25.0),
                duration=5.0, margins=GapMargins(1.0, 5.0), member_ids=["m"])
    behind = lambda gap, v=25.0: _others([("car1", 100.0 - 4.6 / 2 - 4.5 / 2 - gap, -3.5, 4.5, 1.8, v)])
    # behind in the target lane at the same speed: needs 5 + 1.0 * 25 = 30 m bumper to bumper
    v = check_gaps(one(100.0), one(0.0), others=behind(20.0), **args)
    assert not v.ok and "car1" in v.reason and v.shortfall == pytest.approx(10.0)
    assert check_gaps(one(100.0), one(0.0), others=behind(31.0), **args).ok
    # 5 m/s faster: at the end of the 5 s it is 25 m closer and needs 5 + 30 m
    v = check_gaps(one(100.0), one(0.0), others=behind(31.0, 30.0), **args)
    assert not v.ok and v.shortfall == pytest.approx(5 + 30 - (31 - 25))
    # a member that moves 44 m forward enters the lane ahead of a car 10 m behind it: it has
    # moved h = 0.4 of the way (17.6 m) when the bodies first overlap sideways
    assert not check_gaps(one(100.0), one(44.0), others=behind(10.0), **args).ok
    assert check_gaps(one(100.0), one(60.0), others=behind(10.0), **args).ok
    # ahead: the member's time gap; beside: refused; own lane and far lanes: ignored
    ahead = _others([("a", 100.0 + 4.6 / 2 + 4.5 / 2 + 29.0, -3.5, 4.5, 1.8, 25.0)])
    assert "ahead of member" in check_gaps(one(100.0), one(0.0), others=ahead, **args).reason
    ahead = _others([("a", 100.0 + 4.6 / 2 + 4.5 / 2 + 31.0, -3.5, 4.5, 1.8, 25.0)])
    assert check_gaps(one(100.0), one(0.0), others=ahead, **args).ok
    # ahead, the governor's margins when larger: 2 m + 1.5 s * 25 m/s = 39.5 m
    v = check_gaps(one(100.0), one(0.0), others=ahead,
                   **{**args, "margins": GapMargins(1.0, 5.0, 1.5, 2.0)})
    assert not v.ok and v.shortfall == pytest.approx(39.5 - 31.0)
    beside = _others([("b", 101.0, -3.5, 4.5, 1.8, 25.0)])
    assert not check_gaps(one(100.0), one(0.0), others=beside, **args).ok
    other_lanes = _others([("own", 110.0, 0.0, 4.5, 1.8, 25.0), ("far", 100.0, -7.0, 4.5, 1.8, 25.0)])
    assert check_gaps(one(100.0), one(0.0), others=other_lanes, **args).ok


def test_queue_behind_counts_vehicles_in_the_formations_lanes():
    others = _others([("q1", 80.0, 0.0, 4.5, 1.8, 20), ("q2", 60.0, 0.2, 4.5, 1.8, 20),
                      ("far", -50.0, 0.0, 4.5, 1.8, 20), ("other_lane", 80.0, 7.0, 4.5, 1.8, 20),
                      ("ahead", 120.0, 0.0, 4.5, 1.8, 20)])
    m_s, m_d = np.array([100.0, 100.0]), np.array([0.0, 3.5])
    assert queue_behind(m_s, m_d, np.array([4.6, 4.6]), LaneCentres.uniform(3.5), others, 100.0) == 2


def _planner(specs, slots0):
    lim = ManeuverLimits()
    return ManeuverPlanner(specs, np.array(slots0, float), 3.5, lim, 4.6, 1.8, ["a", "b", "c"][:len(slots0)])


def _sensed(t, planner, others, s_vc=500.0):
    sl = planner.slots(t)
    n = len(sl)
    return Situation(t, s_vc, s_vc + sl[:, 0], sl[:, 1], np.full(n, 25.0), np.ones(n, bool), others)


def _doc(maneuvers, members=None):
    return {"run": {"duration": 10.0}, "road": {"net": "straight3"}, "leader": {"speed": 25.0},
            "members": members or [{"id": "a", "slot": {"along": 0.0, "lanes": 0}},
                                   {"id": "b", "slot": {"along": -20.0, "lanes": 0}}],
            "maneuvers": maneuvers}


def test_lane_change_postponed_while_target_lane_occupied_then_done():
    sc = parse_scenario(_doc([{"kind": "lane_change", "lanes": -1, "at": {"time": 2.0}, "timeout": 20.0}]))
    p = _planner(sc.maneuvers, [[0.0, 0.0], [-20.0, 0.0]])
    blocker = _others([("car7", 495.0, -3.5, 4.5, 1.8, 25.0)])
    assert p.step(_sensed(1.0, p, blocker)) == []
    ev = p.step(_sensed(2.0, p, blocker))
    assert [e.kind for e in ev] == ["maneuver_postponed"]
    assert ev[0].detail.startswith("lane_change: no room: car7")
    assert p.step(_sensed(2.05, p, blocker)) == []  # said once
    ev = p.step(_sensed(6.0, p, _others([])))
    assert [e.kind for e in ev] == ["maneuver_start"] and ev[0].detail.startswith("lane_change: T = ")
    T = p.plan[0, 5]
    assert T == pytest.approx((60 * 3.5 / 2.5) ** (1 / 3))
    assert p.step(_sensed(6.0 + T / 2, p, blocker)) == []  # running: nothing re-checked
    ev = p.step(_sensed(6.0 + T, p, _others([])))
    assert [e.kind for e in ev] == ["maneuver_end"] and p.idle
    np.testing.assert_allclose(p.slots(100.0), [[0.0, -3.5], [-20.0, -3.5]])


def test_lane_change_times_out_with_the_reason():
    sc = parse_scenario(_doc([{"kind": "lane_change", "lanes": 1, "at": {"s": 400.0}, "timeout": 5.0}]))
    p = _planner(sc.maneuvers, [[0.0, 0.0], [-20.0, 0.0]])
    blocker = _others([("car9", 480.0, 3.5, 4.5, 1.8, 25.0)])
    kinds = [e.kind for t in np.arange(0.0, 6.0, 0.5) for e in p.step(_sensed(t, p, blocker))]
    assert kinds == ["maneuver_postponed", "maneuver_cancelled"]
    assert p.idle and np.allclose(p.slots(10.0)[:, 1], 0.0)


def test_reshape_assigns_slots_and_respects_road_room():
    sc = parse_scenario(_doc([{"kind": "reshape", "at": {"time": 0.0}, "check_gaps": False,
                               "slots": [{"along": 0.0, "lanes": 0}, {"along": -25.0, "lanes": 0},
                                         {"along": -50.0, "lanes": 0}]}],
                             members=[{"id": i, "slot": {"along": 0.0, "lanes": k}}
                                      for i, k in (("a", -1), ("b", 0), ("c", 1))]))
    p = _planner(sc.maneuvers, [[0.0, -3.5], [0.0, 0.0], [0.0, 3.5]])
    p.room = lambda s0, s1: (-5.25, 5.25)
    ev = p.step(_sensed(0.0, p, _others([])))
    assert ev[0].kind == "maneuver_start"
    assert p.slot_of[1] == 0 and sorted(p.slot_of) == [0, 1, 2]
    assert p.plan[0, 5] == pytest.approx(math.sqrt(10 / math.sqrt(3) * 50 / 1.0))
    # a lane change to the right of the road is refused with its reason
    sc = parse_scenario(_doc([{"kind": "lane_change", "lanes": -2, "at": {"time": 0.0}, "timeout": 1.0}]))
    p = _planner(sc.maneuvers, [[0.0, 0.0], [-20.0, 0.0]])
    p.room = lambda s0, s1: (-5.25, 5.25)
    ev = p.step(_sensed(0.0, p, _others([])))
    assert ev[0].kind == "maneuver_postponed" and "off the road" in ev[0].detail


def test_leave_releases_the_member_at_once():
    sc = parse_scenario(_doc([{"kind": "leave", "member": "b", "at": {"time": 3.0}}]))
    p = _planner(sc.maneuvers, [[0.0, 0.0], [-20.0, 0.0]])
    assert p.step(_sensed(2.0, p, _others([]))) == []
    ev = p.step(_sensed(3.0, p, _others([])))
    assert [(e.kind, e.member) for e in ev] == [("maneuver_start", -1), ("release", 1), ("maneuver_end", -1)]
    assert p.idle


@pytest.mark.parametrize("maneuver,expect", [
    ({"kind": "leave", "at": {"time": 1.0}}, "'member' is given with"),
    ({"kind": "leave", "member": "zz", "at": {"time": 1.0}}, "no member 'zz'"),
    ({"kind": "reshape", "at": {"time": 1.0}}, "needs 'slots'"),
    ({"kind": "lane_change", "at": {"time": 1.0}}, "needs 'lanes'"),
    ({"kind": "lane_change", "lanes": 1, "at": {"time": 1.0, "s": 3.0}}, "exactly one of"),
    ({"kind": "lane_change", "lanes": 1, "at": {}}, "exactly one of"),
    ({"kind": "reshape", "at": {"time": 1.0}, "slots": [{"along": 0.0, "lanes": 0}]}, "1 slots for 2 members"),
])
def test_bad_maneuvers_are_refused_with_the_field(maneuver, expect):
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(_doc([maneuver]))
    assert expect in str(exc.value)


def test_comfort_limit_above_the_medium_band_is_refused():
    doc = _doc([])
    doc["maneuver_limits"] = {"lat_accel": 4.0}
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(doc)
    assert "maneuver_limits.lat_accel" in str(exc.value)


def test_plan_slots_give_exact_target_derivatives_on_a_curved_line():
    """The plan's slots and rates (plan_slots_into, what the PlanSlots transform writes into
    the Reference) through road_target_at: p', p'' of c(s + dx) + dy n(s + dx) with s, dx,
    dy all moving equal central differences on an R = 800 m arc."""
    from formation_traci.control.maneuvers.transition import plan_slots_into
    from formation_traci.road.line_pack import FastLine
    from formation_traci.road.geometry import ReferenceLine
    from formation_traci.road.targets import road_target_at

    R = 800.0
    th = np.linspace(0.0, 0.8, 400)
    line = ReferenceLine.from_points(np.c_[R * np.sin(th), R * (1 - np.cos(th))])
    G = FastLine.from_reference_line(line).G
    plan = hold_plan(np.array([[0.0, 0.0], [-10.0, 3.5]]))
    plan[:, 2:4] = [[-30.0, -3.5], [5.0, 0.0]]
    plan[:, 4:6] = [[1.0, 8.0], [0.5, 6.0]]
    s0, v0, a0 = 100.0, 25.0, 0.8

    def at(t):
        sl = plan_slots_into(plan, t, 0.01, np.empty((2, 2, 6)))
        assert np.allclose(sl[1], plan_slots_into(plan, t + 0.01, 0.01, np.empty((1, 2, 6)))[0])
        s, v = s0 + v0 * t + 0.5 * a0 * t * t, v0 + a0 * t
        return np.array([road_target_at(G, s, v, a0, *sl[0, i]) for i in range(2)])

    t, h = 4.0, 1e-3
    T0, Tm, Tp = at(t), at(t - h), at(t + h)
    np.testing.assert_allclose((Tp[:, 0:2] - Tm[:, 0:2]) / (2 * h), T0[:, 2:4], atol=1e-5)
    np.testing.assert_allclose((Tp[:, 2:4] - Tm[:, 2:4]) / (2 * h), T0[:, 4:6], atol=1e-4)
    assert np.abs(T0[:, 2:4] - at(0.0)[:, 2:4]).max() > 1.0  # the slots really move


def test_room_making_is_planned_ahead_of_the_trigger():
    """The goal the virtual car makes room for is known one look-ahead before a time or
    position trigger fires (the jerk-limited planner's rise time), not only once the
    maneuver is due; a queue trigger is not foreseen."""
    sc = parse_scenario(_doc([{"kind": "lane_change", "lanes": -1, "at": {"s": 600.0}}]))
    p = _planner(sc.maneuvers, [[0.0, 0.0], [-20.0, 0.0]])
    on = np.ones(2, bool)
    lead = 1.75  # s: 43.75 m at 25 m/s
    assert p.goal_ahead(0.0, 556.0, 25.0, on, lead) is None
    np.testing.assert_allclose(p.goal_ahead(0.0, 557.0, 25.0, on, lead), [[0.0, -3.5], [-20.0, -3.5]])
    assert p.goal() is None and p.next == 0  # looking ahead changes nothing in the plan
    sc = parse_scenario(_doc([{"kind": "reshape", "at": {"time": 10.0},
                               "slots": [{"along": 0.0, "lanes": 0}, {"along": -30.0, "lanes": 0}]}]))
    p = _planner(sc.maneuvers, [[0.0, 0.0], [-20.0, 0.0]])
    assert p.goal_ahead(8.2, 0.0, 25.0, on, lead) is None
    np.testing.assert_allclose(p.goal_ahead(8.3, 0.0, 25.0, on, lead), [[0.0, 0.0], [-30.0, 0.0]])
    sc = parse_scenario(_doc([{"kind": "lane_change", "lanes": -1, "at": {"queue_behind": 3}}]))
    p = _planner(sc.maneuvers, [[0.0, 0.0], [-20.0, 0.0]])
    assert p.goal_ahead(0.0, 0.0, 25.0, on, 1e6) is None


def test_room_law_acts_on_the_gaps_one_look_ahead_later():
    """room_accel with a horizon h evaluates the governor's time-gap law on the gaps predicted
    h seconds on at constant speeds: a faster car coming up beside the goal slot is braked for
    before it arrives, a slower car ahead counts K_GAP (v_vc - v_o) h earlier."""
    from formation_traci.control.governor import K_GAP
    from formation_traci.control.maneuvers.generator import ROOM_DECEL, Around, room_accel
    goal = np.array([[0.0, -3.5]])
    one = lambda x: np.array([x], dtype=float)
    front, v = 500.0, 25.0  # the slot's front bumper [m] (the virtual car's front), speed [m/s]
    args = dict(half_w=one(0.9), length=one(4.6), active=np.ones(1, bool), time_gap=1.5,
                min_gap=2.0)
    car = lambda rear, v_o: Around(rear, one(-3.5), one(0.9), one(4.5), v_o)
    # 30 m/s, its front 5 m behind the slot's rear: not there yet, there within 1.75 s
    rear = one(front - 4.6 - 5.0 - 4.5)
    assert room_accel(goal, front, v, others=car(rear, one(30.0)), **args) == np.inf
    assert room_accel(goal, front, v, others=car(rear, one(30.0)), horizon=1.75, **args) == -ROOM_DECEL
    # 20 m/s, 100 m ahead: predicted 8.75 m closer
    far = car(one(front + 100.0), one(20.0))
    a0 = room_accel(goal, front, v, others=far, **args)
    a1 = room_accel(goal, front, v, horizon=1.75, others=far, **args)
    assert a0 - a1 == pytest.approx(K_GAP * 5.0 * 1.75)
