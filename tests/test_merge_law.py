"""The yield law of control/merge.py from first principles: the deceleration it asks opens
exactly the ramp vehicle's own safe gap at the merge point (constant speeds, constant
deceleration); clear vehicles, vehicles beyond the horizon and vehicles that would need more
than the comfort deceleration are left alone; a yield once started is kept."""
import math

import numpy as np
import pytest

from formation_traci.control.governor import K_GAP, K_REL
from formation_traci.control.merge import (BEHIND, CLEAR, OUTSIDE, YIELD, MergeLane, MergeSite, RampTraffic,
                                           merge_params, yield_to_ramp)
from formation_traci.scenario.cooperation import CooperationSpec

SITE = MergeSite(s_start=1500.0, length=300.0)  # merge point at 1650 m (merge_at 0.5)
P = merge_params(CooperationSpec())  # 10 s horizon, 1.5 m/s^2, 2.5 m, merge at mid-lane


def _ramp(dist, v, yielding=False, length=4.5, tau=1.0):
    a = np.atleast_1d
    return RampTraffic(a(np.float64(dist)), a(np.float64(v)), a(np.float64(length)),
                       a(np.float64(tau)), a(np.bool_(yielding)))


def _decide(ramp, lane):
    out = np.empty(ramp.dist.shape[0], dtype=np.int64)
    cap = yield_to_ramp(SITE, ramp, lane, P, out)
    return out, cap


def test_the_asked_deceleration_opens_exactly_the_ramp_vehicles_safe_gap_at_the_merge_point():
    v_f, v_r = 28.0, 27.0
    lane = MergeLane(s_front=1450.0, v_front=v_f, s_rear=1390.0)
    ramp = _ramp(dist=40.0, v=v_r)  # mapped front bumper at 1460 m: 5.5 m ahead of the column
    (d,), cap = _decide(ramp, lane)
    t = (1650.0 - 1460.0) / v_r  # to the merge point at its own speed
    g = P.min_gap_m + 1.0 * v_f
    assert d == YIELD and -P.a_comfort_mps2 <= cap < 0.0
    # the formation's front at constant deceleration -cap over t, the ramp vehicle at v_r
    front_at_t = 1450.0 + v_f * t + 0.5 * cap * t * t
    ramp_rear_at_t = 1460.0 - 4.5 + v_r * t
    assert ramp_rear_at_t - front_at_t == pytest.approx(g, abs=1e-9)


def test_a_ramp_vehicle_clear_ahead_is_followed_like_a_leader_and_a_yield_goes_on():
    lane = MergeLane(s_front=1450.0, v_front=28.0, s_rear=1390.0)
    ramp = _ramp(dist=-20.0, v=26.0)  # at 1520 m: its rear 65.5 m ahead, 2 m/s slower
    (d,), cap = _decide(ramp, lane)
    lead, g = 1520.0 - 4.5 - 1450.0, P.min_gap_m + 1.0 * 28.0
    assert d == CLEAR and cap == pytest.approx(K_GAP * (lead - g) + K_REL * (26.0 - 28.0))
    (d,), again = _decide(ramp._replace(yielding=np.array([True])), lane)
    assert d == YIELD and again == cap
    close = _ramp(dist=-5.0, v=20.0)  # 50.5 m ahead, 8 m/s slower: followed within comfort only
    assert _decide(close, lane)[1] == -P.a_comfort_mps2


@pytest.mark.parametrize("dist, front, code, why", [
    (80.0, 1520.0, CLEAR, "it trails the rear member by more than its gap"),
    (500.0, 1450.0, OUTSIDE, "it reaches the merge point after the horizon")])
def test_clear_behind_and_far_vehicles_are_left_alone(dist, front, code, why):
    lane = MergeLane(s_front=front, v_front=28.0, s_rear=front - 60.0)
    (d,), cap = _decide(_ramp(dist=dist, v=26.0), lane)
    assert d == code and math.isinf(cap), why


def test_past_the_merge_point_a_ramp_vehicle_merges_by_the_end_of_its_lane():
    """Still on the acceleration lane beyond mid-lane (1650 m) it is the law's until the lane ends
    (1800 m): the gap is opened by then."""
    v_f, v_r = 28.0, 31.0
    lane = MergeLane(s_front=1680.0, v_front=v_f, s_rear=1620.0)
    (d,), cap = _decide(_ramp(dist=-200.0, v=v_r), lane)  # front bumper at 1700 m
    t = (1800.0 - 1700.0) / v_r
    assert d == YIELD and -P.a_comfort_mps2 < cap < 0.0
    gap = (1700.0 - 4.5 + v_r * t) - (1680.0 + v_f * t + 0.5 * cap * t * t)
    assert gap == pytest.approx(P.min_gap_m + 1.0 * v_f, abs=1e-9)


def _a_req(s_r, v_r, lane, s_to):
    t = max((s_to - s_r) / v_r, 1.0)
    g = P.min_gap_m + 1.0 * lane.v_front
    return 2.0 * (g - (s_r - 4.5 - lane.s_front) - (v_r - lane.v_front) * t) / t ** 2


def test_a_yield_beyond_comfort_is_left_to_the_ramp_vehicle_unless_already_started():
    lane = MergeLane(s_front=1520.0, v_front=28.0, s_rear=1460.0)
    ramp = _ramp(dist=-30.0, v=27.0)  # at 1530 m, 4.4 s from the merge point
    assert P.a_comfort_mps2 < _a_req(1530.0, 27.0, lane, 1650.0) <= 2 * P.a_comfort_mps2
    (d,), cap = _decide(ramp, lane)
    assert d == BEHIND and math.isinf(cap)
    (d,), cap = _decide(ramp._replace(yielding=np.array([True])), lane)
    assert d == YIELD and cap == -P.a_comfort_mps2
    slow = _ramp(dist=-30.0, v=15.0, yielding=True)  # slowed down beside the formation: let go
    assert _a_req(1530.0, 15.0, lane, 1650.0) > 2 * P.a_comfort_mps2
    assert _decide(slow, lane)[0][0] == BEHIND


def test_a_faster_ramp_vehicle_that_clears_by_itself_only_holds_the_formations_speed():
    lane = MergeLane(s_front=1450.0, v_front=25.0, s_rear=1390.0)
    (d,), cap = _decide(_ramp(dist=40.0, v=32.0), lane)  # at 1460 m, 7 m/s faster, 6 s out
    assert d == YIELD and cap == 0.0


def test_the_cap_is_the_most_demanding_of_several_ramp_vehicles():
    lane = MergeLane(s_front=1450.0, v_front=28.0, s_rear=1390.0)
    ramp = _ramp(dist=np.array([30.0, 40.0]), v=np.array([27.0, 27.0]),
                 yielding=np.array([False, False]), length=np.array([4.5, 4.5]), tau=np.array([1.0, 1.0]))
    d, cap = _decide(ramp, lane)
    one = [_decide(_ramp(dist=x, v=27.0), lane)[1] for x in (30.0, 40.0)]
    assert list(d) == [YIELD, YIELD] and cap == min(one) and one[0] != one[1]


def test_with_the_formations_time_gap_the_yield_opens_that_gap_at_the_merge_point():
    """A ramp vehicle that merges ahead is then the formation's leader: the gap opened for it is
    min_gap + max(tau_r, the formation's time gap) v_F, so that the formation follows it at its
    own time gap (1.5 s) rather than the ramp driver's (1 s), from which the merged vehicle's
    braking was an emergency for the member behind it (bundled on-ramp, 600 veh/h, seed 1)."""
    p = merge_params(CooperationSpec(), 1.5)
    v_f, v_r = 28.0, 27.0
    lane = MergeLane(s_front=1450.0, v_front=v_f, s_rear=1390.0)
    ramp = _ramp(dist=20.0, v=v_r)  # mapped front bumper at 1480 m
    out = np.empty(1, dtype=np.int64)
    cap = yield_to_ramp(SITE, ramp, lane, p, out)
    t = (1650.0 - 1480.0) / v_r
    gap = (1480.0 - 4.5 + v_r * t) - (1450.0 + v_f * t + 0.5 * cap * t * t)
    assert out[0] == YIELD and gap == pytest.approx(P.min_gap_m + 1.5 * v_f, abs=1e-9)
    # a ramp driver keeping a longer gap than the formation keeps its own
    out2 = np.empty(1, dtype=np.int64)
    cap2 = yield_to_ramp(SITE, _ramp(dist=0.0, v=v_r, tau=2.0), lane, p, out2)  # at 1500 m
    t = (1650.0 - 1500.0) / v_r
    gap2 = (1500.0 - 4.5 + v_r * t) - (1450.0 + v_f * t + 0.5 * cap2 * t * t)
    assert out2[0] == YIELD
    assert gap2 == pytest.approx(P.min_gap_m + 2.0 * v_f, abs=1e-9)


def test_when_the_formations_gap_costs_more_than_comfort_the_yield_opens_the_drivers_own():
    """The ramp vehicle 5.5 m ahead of the column's front, 1 m/s slower, 7.04 s from the merge
    point: opening the formation's 1.5 s gap (44.5 m) needs 1.86 m/s^2, more than the 1.5 of
    comfort; the driver's own 1 s gap (30.5 m) needs 1.29: the formation yields to that one
    (before the fallback the vehicle was left to merge behind)."""
    p = merge_params(CooperationSpec(), 1.5)
    v_f, v_r = 28.0, 27.0
    lane = MergeLane(s_front=1450.0, v_front=v_f, s_rear=1390.0)
    t = (1650.0 - 1460.0) / v_r
    assert 2 * (P.min_gap_m + 1.5 * v_f - 5.5 + t) / t ** 2 > P.a_comfort_mps2
    out = np.empty(1, dtype=np.int64)
    cap = yield_to_ramp(SITE, _ramp(dist=40.0, v=v_r), lane, p, out)
    gap = (1460.0 - 4.5 + v_r * t) - (1450.0 + v_f * t + 0.5 * cap * t * t)
    assert out[0] == YIELD and gap == pytest.approx(P.min_gap_m + 1.0 * v_f, abs=1e-9)


def test_a_vehicle_standing_at_the_lane_end_is_followed_once_the_formation_reaches_it_within_the_horizon():
    """A truck (12 m) creeping at 0.8 m/s 30 m before the acceleration lane's end (stop-and-go on
    the bundled on-ramp at 900 veh/h): by its own speed it reaches the lane's end after 37 s,
    beyond the 10 s horizon, so it was never watched; it pushed into the merge lane 14 m ahead of
    a member at 7.4 m/s, which braked at 3.3 m/s^2 (an emergency brake). The formation's front
    reaches its rear first: (lead / (v_F - v_r)) = 3.1 s, within the horizon, so it is followed
    like a leader, at most at the comfort deceleration."""
    v_f, v_r = 8.4, 0.8
    lane = MergeLane(s_front=1732.8, v_front=v_f, s_rear=1728.3)
    ramp = _ramp(dist=-(1770.0 - SITE.s_start), v=v_r, length=12.0)  # front at 1770 m, rear 1758 m
    lead = 1758.0 - 1732.8
    assert (SITE.s_start + SITE.length - 1770.0) / v_r > P.horizon_s  # by its own speed: beyond
    assert lead / (v_f - v_r) < P.horizon_s
    (d,), cap = _decide(ramp, lane)
    g = P.min_gap_m + 1.0 * v_f
    assert d == CLEAR
    assert cap == pytest.approx(max(K_GAP * (lead - g) + K_REL * (v_r - v_f), -P.a_comfort_mps2))
    assert cap == -P.a_comfort_mps2
    far = lane._replace(s_front=1600.0, s_rear=1595.5)  # 153 m behind it: 20 s away, beyond
    assert _decide(ramp, far)[0][0] == OUTSIDE
    before = _ramp(dist=20.0, v=v_r, length=12.0)  # still on the ramp before the join: its own T
    assert _decide(before, lane)[0][0] == OUTSIDE
