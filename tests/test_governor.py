"""The traffic-aware governor (formation_traci.control.governor.py) against hand-worked cases and
a brute-force search."""
import numpy as np
import pytest

from formation_traci.control.governor import (B_COMFORT, K_GAP, K_REL, K_SPEED, LATERAL_MARGIN, leader_accel,
                                          member_speed_cap, time_gap_accel, vehicles_ahead)

pytestmark = pytest.mark.jit_off  # also run with NUMBA_DISABLE_JIT=1 (README)

HALF_W = 0.9  # m


def test_vehicles_ahead_picks_the_nearest_vehicle_in_the_members_lane():
    """Member front at s = 100 m in the lane d = 0. Others: 30 m ahead in the lane, 10 m ahead
    one lane left (3.5 m: no overlap), 20 m ahead straddling (d = 1.9 m: bodies 0.1 m apart,
    inside the 0.3 m margin), 5 m behind in the lane."""
    rear = np.array([130.0, 110.0, 120.0, 95.0])
    d = np.array([0.0, 3.5, 1.9, 0.0])
    v = np.array([31.0, 32.0, 33.0, 34.0])
    gap, v_lead, idx = vehicles_ahead(np.array([100.0]), np.array([0.0]), np.array([HALF_W]),
                                      rear, d, np.full(4, HALF_W), v)
    assert idx[0] == 2 and gap[0] == pytest.approx(20.0) and v_lead[0] == 33.0
    # the same without the straddling car: the car in the lane, 30 m ahead
    gap, v_lead, idx = vehicles_ahead(np.array([100.0]), np.array([0.0]), np.array([HALF_W]),
                                      rear[[0, 1, 3]], d[[0, 1, 3]], np.full(3, HALF_W), v[[0, 1, 3]])
    assert idx[0] == 0 and gap[0] == pytest.approx(30.0) and v_lead[0] == 31.0


def test_vehicles_ahead_side_by_side_overlap_counts_as_ahead_and_nobody_gives_inf():
    """A car whose rear is 0.5 m behind the member's front (side by side, overlapping) is on a
    collision course: gap -0.5 m. With nobody ahead: gap inf, speed nan, index -1."""
    gap, _, idx = vehicles_ahead(np.array([100.0]), np.array([0.0]), np.array([HALF_W]),
                                 np.array([99.5]), np.array([0.5]), np.array([HALF_W]), np.array([30.0]))
    assert gap[0] == pytest.approx(-0.5) and idx[0] == 0
    gap, v_lead, idx = vehicles_ahead(np.array([100.0, 50.0]), np.zeros(2), np.full(2, HALF_W),
                                      np.empty(0), np.empty(0), np.empty(0), np.empty(0))
    assert np.isinf(gap).all() and np.isnan(v_lead).all() and (idx == -1).all()


def test_vehicles_ahead_equals_a_brute_force_search():
    rng = np.random.default_rng(3)
    for _ in range(50):
        n, k = rng.integers(1, 8), rng.integers(0, 60)
        ms, md = rng.uniform(0, 300, n), rng.uniform(-4, 4, n)
        mw = rng.uniform(0.8, 1.3, n)
        orear, od, ow, ov = rng.uniform(0, 300, k), rng.uniform(-6, 6, k), rng.uniform(0.8, 1.3, k), rng.uniform(0, 40, k)
        gap, v_lead, idx = vehicles_ahead(ms, md, mw, orear, od, ow, ov)
        for i in range(n):
            cands = [(orear[j] - ms[i], j) for j in range(k)
                     if orear[j] - ms[i] > -1.0 and abs(od[j] - md[i]) < ow[j] + mw[i] + LATERAL_MARGIN]
            if not cands:
                assert idx[i] == -1 and np.isinf(gap[i])
            else:
                g, j = min(cands)
                assert idx[i] == j and gap[i] == g and v_lead[i] == ov[j]


def test_time_gap_law_is_zero_at_its_equilibrium_and_brakes_as_much_as_a_closing_car_needs():
    T, g0 = 1.5, 5.0
    v = np.array([30.0])
    # at gap = g0 + T v with the leader at the same speed: no acceleration
    assert time_gap_accel(np.array([g0 + T * 30.0]), v, v.copy(), T, g0)[0] == pytest.approx(0.0)
    # nobody ahead: no limit
    assert time_gap_accel(np.array([np.inf]), v, np.array([np.nan]), T, g0)[0] == np.inf
    # closing on a stopped car 150 m ahead: the linear law asks only K_GAP (150 - 50) - K_REL 30
    # = -1 m/s^2, stopping within the 145 m of free gap needs b = 900 / 290 = 3.1 m/s^2
    a = time_gap_accel(np.array([150.0]), v, np.array([0.0]), T, g0)[0]
    assert a == pytest.approx(-900.0 / 290.0)
    # nearer, the linear law asks for more than b and wins
    a = time_gap_accel(np.array([50.0]), v, np.array([10.0]), T, g0)[0]
    assert a == pytest.approx(K_GAP * (50.0 - g0 - T * 30.0) + K_REL * (10.0 - 30.0))
    # a slow car far ahead needs less than B_COMFORT: the linear law alone
    # (b = (900 - 625) / (2 * 395) = 0.35 m/s^2 < B_COMFORT)
    a = time_gap_accel(np.array([400.0]), v, np.array([25.0]), T, g0)[0]
    assert (900.0 - 625.0) / (2 * 395.0) < B_COMFORT
    assert a == pytest.approx(K_GAP * (400.0 - g0 - T * 30.0) + K_REL * (25.0 - 30.0))


def test_member_speed_cap_equals_the_leaders_speed_at_the_desired_gap():
    T, g0 = 1.5, 5.0
    v_lead = np.array([20.0, 20.0, 0.0])
    gap = np.array([g0 + T * 20.0, g0 + T * 20.0 + 15.0, 1.0])
    cap = member_speed_cap(gap, v_lead, T, g0, np.array([25.0, 25.0, 10.0]))
    np.testing.assert_allclose(cap, [20.0, 30.0, 0.0])  # +15 m of gap removed over 1.5 s; never < 0
    assert member_speed_cap(np.array([np.inf]), np.array([np.nan]), T, g0, np.array([25.0]))[0] == np.inf


def test_a_faster_car_cutting_in_close_asks_only_comfortable_braking():
    """LuST on-ramp (tests/test_realnet.py): a ramp car at 29 m/s appears with zero gap in front
    of a member at 24.8 m/s. The gap opens by itself at 4.2 m/s. Before, the speed cap was
    max(29 + (0 - 2 - 1.5 * 29) / 1.5, 0) = 0 m/s: the planner turned it into braking at the
    friction limit and the member fell 60 m behind its slot and off the road; the slot's gap
    law asked 0.2 (0 - 2 - 1.5 * 24.8) + 0.7 * 4.2 = -4.9 m/s^2, an emergency for the virtual
    car. Now the cap is the member's own speed and the law at most B_COMFORT of braking."""
    T, g0, v, v_lead = 1.5, 2.0, 24.8, 29.0
    assert member_speed_cap(np.array([0.0]), np.array([v_lead]), T, g0, np.array([v]))[0] == pytest.approx(v)
    assert time_gap_accel(np.array([0.0]), np.array([v]), np.array([v_lead]), T, g0)[0] == pytest.approx(-B_COMFORT)
    # far enough ahead, the linear law is milder and unchanged
    far = g0 + T * v + 5.0
    assert time_gap_accel(np.array([far]), np.array([v]), np.array([v_lead]), T, g0)[0] == pytest.approx(
        K_GAP * 5.0 + K_REL * (v_lead - v))
    # a slower car at the same gap still gets all the braking it needs, and the old cap
    assert time_gap_accel(np.array([3.0]), np.array([v]), np.array([20.0]), T, g0)[0] < -B_COMFORT
    assert member_speed_cap(np.array([3.0]), np.array([20.0]), T, g0, np.array([v]))[0] == pytest.approx(
        max(20.0 + (3.0 - g0 - T * 20.0) / T, 0.0))


def test_a_cut_in_a_little_slower_than_the_member_asks_only_comfortable_braking():
    """The bundled on-ramp, 600 veh/h, seed 1: a ramp car merges 33 m ahead of a member at
    25.0 m/s, at 24.8 m/s. Matching its speed within the free gap needs
    b = (25.0^2 - 24.8^2) / (2 (33 - 2)) = 0.16 m/s^2, yet the speed cap
    24.8 + (33 - 2 - 1.5 * 24.8) / 1.5 = 20.67 m/s, folded into the request as
    (cap - v) / 1 s, asked -4.3 m/s^2: an emergency brake (below -3 m/s^2) for a car at
    nearly the member's own speed. The cap is now not below the leader's speed and the law not
    below -B_COMFORT, as for a faster car; a leader that needs more than B_COMFORT to match
    keeps the full cap and law."""
    T, g0, v, v_lead, gap = 1.5, 2.0, 25.0, 24.8, 33.0
    b = (v * v - v_lead * v_lead) / (2 * (gap - g0))
    assert b < B_COMFORT
    old_cap = v_lead + (gap - g0 - T * v_lead) / T
    assert (old_cap - v) / 1.0 < -3.0  # what the old cap asked
    cap = member_speed_cap(np.array([gap]), np.array([v_lead]), T, g0, np.array([v]))[0]
    assert cap == pytest.approx(v_lead)
    law = K_GAP * (gap - g0 - T * v) + K_REL * (v_lead - v)
    assert time_gap_accel(np.array([gap]), np.array([v]), np.array([v_lead]), T, g0)[0] == pytest.approx(
        max(law, -B_COMFORT))
    # 2.4 m/s slower at 30 m: matching needs (625 - 510.76) / 56 = 2.04 m/s^2 > B_COMFORT
    slow, near = 22.6, 30.0
    b = (v * v - slow * slow) / (2 * (near - g0))
    assert b > B_COMFORT
    assert member_speed_cap(np.array([near]), np.array([slow]), T, g0, np.array([v]))[0] == pytest.approx(
        slow + (near - g0 - T * slow) / T)
    assert time_gap_accel(np.array([near]), np.array([v]), np.array([slow]), T, g0)[0] == pytest.approx(
        min(K_GAP * (near - g0 - T * v) + K_REL * (slow - v), -b))


def test_leader_accel_free_road_law_limits_and_no_reversing():
    assert leader_accel(25.0, 30.0, 0.0, np.array([np.inf]), 2.0, 8.0) == pytest.approx(min(K_SPEED * 5.0, 2.0))
    assert leader_accel(25.0, 30.0, 0.0, np.array([-3.0, 1.0]), 2.0, 8.0) == pytest.approx(-3.0)
    assert leader_accel(25.0, 30.0, 0.0, np.array([-20.0]), 2.0, 8.0) == pytest.approx(-8.0)
    assert leader_accel(0.0, 0.0, 0.0, np.array([-3.0]), 2.0, 8.0) == 0.0


@pytest.mark.parametrize("k_others", [0, 1, 12])
def test_governor_step_is_the_composition_of_the_laws(k_others):
    """The compiled one-step kernel of the SUMO loop gives exactly what the public functions give
    when composed as the loop composed them: gaps to the members' and the slots' leaders, the
    virtual car's law over the active members' slot gaps, the speed cap and the acceleration cap."""
    from formation_traci.control.governor import governor_step
    from formation_traci.control.reference_records import NeighbourRows
    rng = np.random.default_rng(k_others)
    n = 5
    m_s = 1000.0 + rng.uniform(-40, 0, n)
    m_d = rng.choice([-3.5, 0.0, 3.5], n) + rng.normal(0, 0.3, n)
    slot_s, slot_d = m_s + rng.normal(0, 2, n), np.round(m_d / 3.5) * 3.5
    half_w, v_m = np.full(n, HALF_W), rng.uniform(25, 32, n)
    active = np.array([True, True, False, True, True])
    o_rear = 1000.0 + rng.uniform(-60, 80, k_others)
    o_d, o_hw, o_v = rng.choice([-3.5, 0.0, 3.5], k_others), np.full(k_others, HALF_W), rng.uniform(20, 35, k_others)
    v_vc, v_set, v_set_dot, tg, mg, a_max, d_em = 29.0, 30.0, 0.1, 1.2, 2.0, 2.0, 6.0
    a_vc, gap, idx, v_cap, a_cap = governor_step(
        m_s, m_d, slot_s, slot_d, half_w, v_m, active, v_vc, v_set, v_set_dot,
        NeighbourRows(o_rear, o_d, o_hw, o_v, np.zeros(0, np.bool_), np.zeros(0)),
        np.array([tg, mg, a_max, d_em, np.inf, np.inf, 1.0]))
    g_ref, vl_ref, idx_ref = vehicles_ahead(m_s, m_d, half_w, o_rear, o_d, o_hw, o_v)
    gs, vls, _ = vehicles_ahead(slot_s, slot_d, half_w, o_rear, o_d, o_hw, o_v)
    acc_slot = time_gap_accel(gs, np.full(n, v_vc), vls, tg, mg)
    assert a_vc == leader_accel(v_vc, v_set, v_set_dot, acc_slot[active], a_max, d_em)
    np.testing.assert_array_equal(gap, g_ref)
    np.testing.assert_array_equal(idx, idx_ref)
    np.testing.assert_array_equal(v_cap, member_speed_cap(g_ref, vl_ref, tg, mg, v_m))
    np.testing.assert_array_equal(a_cap, np.maximum(time_gap_accel(g_ref, v_m, vl_ref, tg, mg), -d_em))
    if k_others == 12:
        assert np.isfinite(gap).sum() >= 2 and a_vc < K_SPEED * (v_set - v_vc) + v_set_dot  # traffic binds
    if k_others == 0:
        assert a_vc == pytest.approx(K_SPEED * (v_set - v_vc) + v_set_dot) and np.isinf(v_cap).all()


def test_time_gap_accel_takes_broadcast_inputs_without_a_warning(monkeypatch):
    """Gaps of several vehicles against one leader's speed (a maneuver's room check): the
    arguments broadcast, and the kernel gets arrays of its own (not numpy's read-only broadcast
    views, whose writeable flag numba reads when it compiles for them: numpy's 'will not create
    a writeable array from broadcast_array' warning, once printed on the terminal of maneuver
    runs on a cold cache, where one vehicle made the speed a 1-element broadcast view); each
    value equals the scalar call's."""
    import warnings

    from formation_traci.control import governor

    handed = []
    kernel = governor._gap_laws  # the compiled law behind time_gap_accel

    def recording(gap, v, v_lead, time_gap, min_gap, out):
        handed.append((gap, v, v_lead))
        return kernel(gap, v, v_lead, time_gap, min_gap, out)

    monkeypatch.setattr(governor, "_gap_laws", recording)
    for gaps, v_lead in ((np.array([10.0, 30.0, 80.0]), np.array([20.0, 22.0, 30.0])),
                         (np.array([10.0]), np.array([20.0]))):  # one vehicle: a 1-element view
        handed.clear()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            a = time_gap_accel(gaps, 25.0, v_lead, 1.5, 2.0)
        assert a.shape == gaps.shape
        with warnings.catch_warnings():  # what numba reads of each argument when it compiles for it
            warnings.simplefilter("error")
            assert all(x.flags.writeable and x.flags.c_contiguous for x in handed[0])
        for g, vl, ai in zip(gaps, v_lead, a):
            assert ai == time_gap_accel(np.array([g]), np.array([25.0]), np.array([vl]), 1.5, 2.0)[0]
