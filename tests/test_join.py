"""Join and exit-leave building blocks without SUMO: the start-rate quintic, the join
duration from the comfort limits, the choice of the vehicle, the planner's take-over, the
schema."""
import numpy as np
import pytest

from formation_traci.control.maneuvers.gap import Others
from formation_traci.control.maneuvers.join import join_duration, join_peaks, pick_vehicle
from formation_traci.control.maneuvers.planner import ManeuverPlanner, Situation
from formation_traci.control.maneuvers.transition import ComfortLimits, hold_plan, slots_at
from formation_traci.road.lanes import LaneCentres
from formation_traci.scenario import ScenarioError
from formation_traci.scenario.load import parse_scenario
from formation_traci.scenario.maneuvers import ManeuverLimits

LIM = ComfortLimits(lat_accel=1.5, lat_jerk=2.5, lon_accel=1.0, lon_jerk=2.5, min_duration=3.0)


def _others(rows):
    ids, s, d, L, W, v = zip(*rows) if rows else ((),) * 6
    return Others(tuple(ids), *(np.array(x, float) for x in (s, d, L, W, v)))


def test_start_rate_plan_starts_at_the_vehicle_with_its_rate_and_ends_at_rest_in_the_slot():
    """offset = A + h (B - A) + r0 T g: at t0 the offset is A with rate r0 and no
    acceleration, at t0 + T it is B at rest; rates and accelerations are the exact
    derivatives (central differences)."""
    plan = hold_plan(np.array([[-30.0, 3.4]]))
    plan[0] = [-30.0, 3.4, -12.0, 3.5, 2.0, 9.0, 4.0, 0.1]
    off, rate, acc = slots_at(plan, 2.0)
    np.testing.assert_allclose(off, [[-30.0, 3.4]]), np.testing.assert_allclose(rate, [[4.0, 0.1]])
    np.testing.assert_allclose(acc, 0.0, atol=1e-12)
    off, rate, acc = slots_at(plan, 11.0)
    np.testing.assert_allclose(off, [[-12.0, 3.5]]), np.testing.assert_allclose(rate, 0.0, atol=1e-12)
    np.testing.assert_allclose(acc, 0.0, atol=1e-12)
    h = 1e-4
    for t in (2.5, 5.0, 8.7):
        (o0, r0, a0), (om, rm, _), (op, rp, _) = (slots_at(plan, x) for x in (t, t - h, t + h))
        np.testing.assert_allclose((op - om) / (2 * h), r0, atol=1e-6)
        np.testing.assert_allclose((rp - rm) / (2 * h), a0, atol=1e-5)
    # without start rates the plan is the plain quintic of the other maneuvers, bit for bit
    plain = plan.copy()
    plain[0, 6:8] = 0.0
    ref = hold_plan(np.array([[-30.0, 3.4]]))[:, :6]
    ref[0] = plan[0, :6]
    from formation_traci.control.maneuvers.transition import quintic
    hq = quintic(5.0, 2.0, 9.0)[0]
    assert slots_at(plain, 5.0)[0][0, 0] == -30.0 + hq * 18.0


@pytest.mark.parametrize("d,r0", [(30.0, 5.0), (-25.0, 3.0), (27.3, -0.98), (0.0, 4.0)])
def test_join_duration_keeps_the_slot_within_the_comfort_limits(d, r0):
    """The join's duration is the shortest (within 2 %) whose sampled peaks of the slot's
    acceleration and jerk (with its start rate) stay inside the limits; the sampled peaks
    of the profile itself (fine finite differences) confirm them."""
    T = join_duration(d, 0.0, r0, 0.0, LIM)
    a, j = join_peaks(d, r0, T)
    assert a <= LIM.lon_accel + 1e-12 and j <= LIM.lon_jerk + 1e-12
    a2, j2 = join_peaks(d, r0, T / 1.02)
    assert a2 > LIM.lon_accel or j2 > LIM.lon_jerk or T / 1.02 < LIM.min_duration
    plan = hold_plan(np.zeros((1, 2)))
    plan[0] = [0.0, 0.0, d, 0.0, 0.0, T, r0, 0.0]
    t = np.linspace(0.0, T, 2001)
    acc = np.array([slots_at(plan, x)[2][0, 0] for x in t])
    assert np.abs(acc).max() <= LIM.lon_accel * 1.001
    assert np.abs(np.diff(acc) / np.diff(t)).max() <= LIM.lon_jerk * 1.01


LANES = LaneCentres.uniform(3.5)  # m apart


def test_pick_vehicle_takes_the_nearest_car_in_the_slots_lane_within_reach():
    o = _others([("far", 560.0, 3.5, 4.5, 1.8, 27.0), ("truck", 492.0, 3.5, 12.0, 2.5, 27.0),
                 ("centre_lane", 490.0, 0.0, 4.5, 1.8, 27.0), ("changing", 491.0, 2.3, 4.5, 1.8, 27.0),
                 ("car", 475.0, 3.45, 4.5, 1.8, 30.0), ("car2", 470.0, 3.5, 4.5, 1.8, 30.0)])
    j = pick_vehicle(o, 488.0, 3.5, 30.0, LANES, 4.6, 1.8, None)
    assert o.ids[j] == "car"
    assert o.ids[pick_vehicle(o, 488.0, 3.5, 30.0, LANES, 4.6, 1.8, "truck")] == "truck"
    assert pick_vehicle(o, 488.0, 3.5, 30.0, LANES, 4.6, 1.8, "far") == -1
    assert pick_vehicle(o, 488.0, -3.5, 30.0, LANES, 4.6, 1.8, None) == -1


def _doc(maneuvers, members=None):
    return {"run": {"duration": 10.0}, "road": {"net": "straight3"}, "leader": {"speed": 25.0},
            "members": members or [{"id": "a", "slot": {"along": 0.0, "lanes": 0}},
                                   {"id": "b", "slot": {"along": -20.0, "lanes": 0}},
                                   {"id": "j", "slot": {"along": -10.0, "lanes": 1}}],
            "maneuvers": maneuvers}


def test_planner_takes_a_vehicle_over_into_the_free_slot_from_where_it_is():
    sc = parse_scenario(_doc([{"kind": "join", "member": "j", "at": {"time": 1.0}, "reach": 30.0}]))
    p = ManeuverPlanner(sc.maneuvers, np.array([[0.0, 0.0], [-20.0, 0.0], [-10.0, 3.5]]), 3.5,
                        ManeuverLimits(), 4.6, 1.8, ["a", "b", "j"], d_front=2.5)
    active = np.array([True, True, False])

    def sn(t, others):
        return Situation(t, 500.0, np.array([500.0, 480.0, 0.0]), np.array([0.0, 0.0, 0.0]),
                         np.full(3, 25.0), active, others, 25.0)

    ev = p.step(sn(1.0, _others([("car", 440.0, 3.5, 4.5, 1.8, 28.0)])))
    assert [e.kind for e in ev] == ["maneuver_postponed"] and "no vehicle within 30 m" in ev[0].detail
    car = _others([("bus", 470.0, 3.5, 12.0, 2.5, 28.0), ("car", 470.0, 3.5, 4.5, 1.8, 28.0)])
    ev = p.step(sn(3.0, car))
    assert [(e.kind, e.member, e.name) for e in ev] == [("take_over", 2, "car"), ("maneuver_start", -1, "")]
    T = p.plan[2, 5]
    assert T == pytest.approx(join_duration(-10.0 - (-30.0 + 2.25 - 2.5), 0.0, 3.0, 0.0,
                                            ComfortLimits(1.5, 2.5, 1.0, 2.5, 3.0)))
    off, rate, _ = slots_at(p.plan, 3.0)
    np.testing.assert_allclose(off[2], [470.0 + 2.25 - 2.5 - 500.0, 3.5])  # the car's CoG
    np.testing.assert_allclose(rate[2], [3.0, 0.0])  # its own speed relative to the formation
    np.testing.assert_allclose(slots_at(p.plan, 3.0 + T)[0][2], [-10.0, 3.5])
    active[2] = True
    assert [e.kind for e in p.step(sn(3.0 + T, car))] == ["maneuver_end"] and p.idle


@pytest.mark.parametrize("maneuver,expect", [
    ({"kind": "join", "at": {"time": 1.0}}, "'member' is given with"),
    ({"kind": "join", "member": "zz", "at": {"time": 1.0}}, "no member 'zz'"),
    ({"kind": "join", "member": "j", "exit": "offramp", "at": {"time": 1.0}}, "'exit' is given with"),
    ({"kind": "leave", "member": "a", "vehicle": "x", "at": {"time": 1.0}}, "'vehicle' is given with"),
    ({"kind": "join", "member": "j", "slots": [], "at": {"time": 1.0}}, "takes 'member', not"),
])
def test_bad_joins_and_exits_are_refused_with_the_field(maneuver, expect):
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(_doc([maneuver]))
    assert expect in str(exc.value)


def test_a_member_joins_at_most_once_and_someone_starts_in_the_formation():
    twice = [{"kind": "join", "member": "j", "at": {"time": t}} for t in (1.0, 2.0)]
    with pytest.raises(ScenarioError, match="joins at most once"):
        parse_scenario(_doc(twice))


def test_an_exit_that_is_not_an_off_ramp_of_the_network_is_refused(tmp_path):
    """Bad input: exit 2 with file, field and expectation, nothing created."""
    import subprocess
    import sys
    doc = ('name = "x"\n[run]\nduration = 5.0\n[road]\nnet = "offramp"\nlane = 1\nstart = 300.0\n'
           '[leader]\nspeed = 25.0\n[[members]]\nid = "a"\nslot = { along = 0.0, lanes = 0 }\n'
           '[[members]]\nid = "b"\nslot = { along = 0.0, lanes = -1 }\n'
           '[[maneuvers]]\nkind = "leave"\nmember = "b"\nexit = "mw_down"\nat = { time = 1.0 }\n')
    path = tmp_path / "bad.toml"
    path.write_text(doc)
    res = subprocess.run([sys.executable, "-m", "formation_traci.cli", "run", str(path), "-o",
                          str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "maneuvers.0.exit" in res.stderr and "off-ramp" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("d_along,d_across", [(30.0, 0.0), (0.0, 3.5), (20.0, 3.5)])
def test_join_duration_without_a_start_rate_is_the_transition_duration(d_along, d_across):
    from formation_traci.control.maneuvers.transition import transition_duration
    T0 = transition_duration(d_along, d_across, LIM)
    assert T0 <= join_duration(d_along, d_across, 0.0, 0.0, LIM) <= T0 * 1.02


def test_an_entering_member_waits_for_a_free_entry_then_is_the_vehicle_taken_over():
    sc = parse_scenario(_doc([{"kind": "join", "member": "j", "at": {"time": 1.0},
                               "enter": {"along": -60.0, "lanes": 1}}]))
    p = ManeuverPlanner(sc.maneuvers, np.array([[0.0, 0.0], [-20.0, 0.0], [-10.0, 3.5]]), 3.5,
                        ManeuverLimits(), 4.6, 1.8, ["a", "b", "j"], d_front=2.5)
    active = np.array([True, True, False])

    def sn(t, others):
        return Situation(t, 500.0, np.array([500.0, 480.0, 0.0]), np.zeros(3), np.full(3, 25.0),
                         active, others, 25.0)

    # a car 20 m ahead of the entry point in its lane: inside 4.55 + 5 + 1 s * 25 m/s
    ev = p.step(sn(1.0, _others([("car", 460.0, 3.5, 4.5, 1.8, 25.0)])))
    assert [e.kind for e in ev] == ["maneuver_postponed"] and "blocked by car" in ev[0].detail
    ev = p.step(sn(1.5, _others([("car", 480.0, 3.5, 4.5, 1.8, 25.0)])))  # 40 m: free
    assert [(e.kind, e.member, e.where) for e in ev] == [("enter", 2, (440.0, 3.5, 25.0))]
    near = [("car", 480.0, 3.5, 4.5, 1.8, 25.0), ("j", 470.0, 3.5, 4.6, 1.8, 30.0)]
    assert p.step(sn(2.0, _others(near[:1]))) == []  # entered once; the car is not taken
    ev = p.step(sn(3.0, _others(near)))
    assert [(e.kind, e.name) for e in ev] == [("take_over", "j"), ("maneuver_start", "")]


def test_enter_goes_with_a_join_of_the_members_own_vehicle_only():
    for bad in ({"kind": "join", "member": "j", "vehicle": "x", "enter": {"along": -50.0, "lanes": 1},
                 "at": {"time": 1.0}},
                {"kind": "leave", "member": "a", "enter": {"along": -50.0, "lanes": 1}, "at": {"time": 1.0}}):
        with pytest.raises(ScenarioError, match="'enter' is given with"):
            parse_scenario(_doc([bad]))


def test_path_clearance_follows_the_real_path_with_its_start_rate():
    """A car closing at r0 = 8 m/s from behind overshoots its slot (by 0.84 m over T = 12 s
    for a 30 m move): a member 0.5 m clear of the slot ahead in the same lane is clear of
    the straight path but not of the real one."""
    from formation_traci.control.maneuvers.assign import min_clearance
    from formation_traci.control.maneuvers.join import path_clearance
    start, goal, held = np.array([-40.0, 3.5]), np.array([-10.0, 3.5]), np.array([[-4.9, 3.5]])
    straight = min_clearance(np.vstack([held, start]), np.vstack([held, goal]), 4.6, 1.8)
    assert straight == pytest.approx(0.5)
    assert path_clearance(start, goal, 0.0, held, 4.6, 1.8, [4.6], [1.8]) == pytest.approx(straight, abs=1e-9)
    T, r0 = 12.0, 8.0
    tau = np.linspace(0, 1, 100001)
    along = -40.0 + tau ** 3 * (10 - 15 * tau + 6 * tau ** 2) * 30.0 + r0 * T * (tau - 6 * tau ** 3 + 8 * tau ** 4 - 3 * tau ** 5)
    expect = -4.9 - along.max() - 4.6
    got = path_clearance(start, goal, r0 * T, held, 4.6, 1.8, [4.6], [1.8])
    assert got == pytest.approx(expect, abs=0.01) and got < 0.0 < straight
