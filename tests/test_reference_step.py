"""The road reference's one compiled step (control/reference_road.py road_reference_step)
gives, bit for bit, what the laws give composed one by one as the reference generator did
before it was fused (issue 18: one compiled call per step instead of six, ~94 -> ~50 us)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from formation_traci.control.governor import (ACCEL_MAX, DECEL_EMERGENCY, DECEL_FOLLOW, DECEL_MAX,
                                              column_caps, free_road_accel, governor_step)
from formation_traci.control.longitudinal import LongitudinalPlanner, PlannerParams, plan_accel, plan_caps
from formation_traci.control.reference_records import (MemberPlanner, MemberRows, NeighbourRows,
                                                       RoadPlan)
from formation_traci.control.reference_road import GovernorLimits, road_reference_step, road_vc_rows
from formation_traci.control.virtual_car import knot_profile_at
from formation_traci.road.geometry import reference_line_from_net
from formation_traci.road.line_pack import packed
from formation_traci.sim.setup import profile
from formation_traci.scenario.schema import ProfileSpec
from sumo_nets import net_path

LIM = GovernorLimits(time_gap=1.2, min_gap=2.0, accel_max=1.5, decel_max=3.0, decel_emergency=6.0)
PP = PlannerParams(decel_comfort=3.0)
DT_C, N_CTRL = 0.01, 5


def composed(G, prof, t, s, v, a_limit, along, slot_d_road, is_road, d_front, half_w, sensed,
             planner, v_prev, ramp=False):
    """The pre-fusion reference step: governor, column caps, limit, planner, virtual-car rows
    (``ramp``: the virtual car's acceleration from the last step's to this step's within the
    step, and the members' caps of the last step returned to ramp from)."""
    m_s, m_d, v_m, active, nb_rear, nb_d, nb_half_w, nb_v = sensed
    slot_d = np.where(is_road, slot_d_road, m_d)
    v_set, v_set_dot = knot_profile_at(prof, 0, float(t))
    slot_s = s + along
    a_gov, gap, lead, v_cap, a_cap_req = governor_step(
        m_s + d_front, m_d, slot_s + d_front, slot_d, half_w, v_m, active, v, v_set, v_set_dot,
        NeighbourRows(nb_rear, nb_d, nb_half_w, nb_v, np.zeros(0, np.bool_), np.zeros(0)),
        LIM.packed())
    v_cap, a_cap_req = column_caps(slot_s, slot_d, half_w, active, v_cap, a_cap_req)
    a_request = min(a_gov, a_limit)
    dt = DT_C * N_CTRL
    off = ~active
    v_c, a_c = np.where(off, np.inf, v_cap), np.where(off, np.inf, a_cap_req)
    a_m = np.zeros(len(v_m)) if v_prev is None else (v_m - v_prev) / dt
    p = planner.p  # the planner's step before it was fused (plan_accel, then plan_caps)
    a_vc0, a_cap_from = planner.a_vc, planner.a_cap.copy()
    lim = LIM.packed()  # the set speed's own request: firm braking only for traffic's
    a_profile = free_road_accel(v, v_set, v_set_dot, lim[ACCEL_MAX], lim[DECEL_EMERGENCY],
                                lim[DECEL_FOLLOW], lim[DECEL_MAX])
    a_vc, planner.emergency_vc = plan_accel(planner.a_vc, float(a_request), dt, p.packed(),
                                            a_request < a_profile)
    planner.a_vc = a_vc
    a_cap = np.empty_like(planner.a_cap)
    plan_caps(planner.a_cap, v_c, a_c, v_m, a_m, dt, p.packed(), a_cap, planner.emergency)
    planner.a_cap = a_cap
    a_cap[off] = np.inf
    vc = np.empty((N_CTRL, len(v_m), 8))
    s1, v1 = road_vc_rows(G, s, v, a_vc0 if ramp else a_vc, a_vc, DT_C, vc)
    return (a_request, a_vc, planner.emergency_vc, s1, v1, gap, lead, a_cap_req, a_cap, vc,
            a_cap_from if ramp else a_cap)


def scene(rng, n, k):
    """Members near their slots on a 3-lane road, k other vehicles around them, one member
    out of the run now and then."""
    m_s = 500.0 + rng.uniform(-40, 5, n)
    m_d = rng.choice([-3.5, 0.0, 3.5], n) + rng.normal(0, 0.2, n)
    v_m = rng.uniform(20, 32, n)
    active = rng.uniform(size=n) > 0.15
    nb_s = 500.0 + rng.uniform(-80, 80, k)
    nb_d = rng.choice([-3.5, 0.0, 3.5], k) + rng.normal(0, 0.3, k)
    return (m_s, m_d, v_m, active, nb_s - 2.5, nb_d, np.full(k, 0.9), rng.uniform(10, 35, k))


@pytest.mark.parametrize("ramp", [False, True])
@pytest.mark.parametrize("seed", [pytest.param(0, marks=pytest.mark.jit_off), 1, 2, 3])  # 0: also as plain Python
def test_fused_reference_step_equals_the_laws_composed(seed, ramp):
    rng = np.random.default_rng(seed)
    G = packed(reference_line_from_net(net_path("curved3"), ["entry", "main"], 1))
    prof = profile(ProfileSpec(t=[0.0, 20.0, 40.0], values=[25.0, 30.0, 28.0], interp="smooth")).packed()
    n = 5
    along = np.array([0.0, -20.0, -20.0, -40.0, -40.0])
    slot_d = np.array([0.0, -3.5, 3.5, -3.5, 3.5])
    is_road = np.array([True, True, True, False, True])
    d_front, half_w = np.full(n, 3.6), np.full(n, 0.9)
    old, new = LongitudinalPlanner(n, PP), LongitudinalPlanner(n, PP)
    v_prev_old, v_prev_new, has_prev = None, np.zeros(n), False
    s, v = 500.0, 27.0
    for step in range(60):
        t = 0.05 * step
        sensed = scene(rng, n, int(rng.integers(0, 12)))
        a_limit = math.inf if step % 3 else float(rng.uniform(-4, 1))
        want = composed(G, prof, t, s, v, a_limit, along, slot_d, is_road, d_front, half_w,
                        sensed, old, v_prev_old, ramp)
        v_prev_old = sensed[2].copy()
        vc, cap_from = np.empty((N_CTRL, n, 8)), np.empty(n)
        got = road_reference_step(
            RoadPlan(G, prof, along, slot_d, is_road, d_front, half_w, LIM.packed(), PP.packed(),
                     DT_C, ramp), t, s, v, a_limit, MemberRows(*sensed[:4]),
            NeighbourRows(*sensed[4:], np.zeros(0, np.bool_), np.zeros(0)), new.a_vc, has_prev,
            MemberPlanner(new.a_cap, v_prev_new, new.emergency), vc, cap_from)
        new.a_vc, has_prev = got[1], True
        for w, g in zip(want[:9], got):
            assert np.asarray(w).tobytes() == np.asarray(g).tobytes()
        assert vc.tobytes() == want[9].tobytes()
        assert cap_from.tobytes() == want[10].tobytes()
        assert new.a_cap.tobytes() == old.a_cap.tobytes()
        assert new.emergency.tobytes() == old.emergency.tobytes()
        s, v = got[3], got[4]
