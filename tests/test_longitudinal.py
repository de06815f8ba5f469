"""Jerk-limited longitudinal references (control/longitudinal.py, issue 19 item 1)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from analysis.metrics.comfort import emergency_mask, jerk_window_mean
from formation_traci.control.longitudinal import LongitudinalPlanner, PlannerParams, plan_accel

P = PlannerParams()
DT = 0.05


def _run(requests, a0=0.0, p=P):
    """The planner's virtual car on its own profile (no firm braking, no release)."""
    a, out, em = a0, [], []
    pp = replace(p, jerk_release=0.0).packed()
    for r in requests:
        a, e = plan_accel(a, r, DT, pp, False)
        out.append(a)
        em.append(e)
    return np.array(out), np.array(em)


def test_a_step_request_is_followed_with_bounded_jerk_then_as_a_first_order_lag():
    a, em = _run([-2.0] * 200)
    jerk = np.diff(np.r_[0.0, a]) / DT
    assert np.max(np.abs(jerk)) <= P.jerk_max + 1e-12 and not em.any()
    # the jerk bound holds while the lag would ask for more: 2/0.5 = 4 > 1 m/s^3
    assert abs(a[9] - (-P.jerk_max * 10 * DT)) < 1e-12
    # once the lag asks for less than the bound it is exact: a -> -2 with time constant tau
    k = int(np.argmax(np.abs(jerk) < P.jerk_max - 1e-9))
    w = 1 - math.exp(-DT / P.tau)
    np.testing.assert_allclose(a[k + 1] + 2.0, (a[k] + 2.0) * (1 - w), rtol=1e-12)
    assert abs(a[-1] + 2.0) < 1e-3


def test_step_to_step_noise_is_attenuated_not_amplified():
    rng = np.random.default_rng(3)
    noise = 0.3 * rng.standard_normal(2000)  # +-0.3 m/s^2 white request noise
    a, _ = _run(noise)
    assert np.std(np.diff(a)) < 0.1 * np.std(np.diff(noise))
    assert np.max(np.abs(np.diff(a))) / DT <= P.jerk_max + 1e-12


def test_an_emergency_request_brakes_at_the_emergency_jerk_and_is_flagged():
    a, em = _run([-6.0] * 20)
    assert em.all()
    assert abs(a[0] - (-P.jerk_emergency * DT)) < 1e-12  # 1 m/s^2 in the first step
    assert abs(a[5] - (-6.0)) < 1e-12  # -6 reached after 0.3 s (6 / 20 m/s^3)
    inf, em_inf = plan_accel(-1.0, math.inf, DT, P.packed(), True)
    assert inf == -1.0 and not em_inf


def test_member_caps_become_smooth_acceleration_caps_starting_from_the_member():
    pl = LongitudinalPlanner(2, P)
    _, v_cap, a_cap = pl.step(0.0, [np.inf, 24.0], [np.inf, -0.5], [25.0, 25.0], [0.0, 0.5], DT)
    assert np.all(v_cap == np.inf) and a_cap[0] == np.inf  # speed caps act through a_cap
    # request min(-0.5, (24 - 25) / tau_speed_cap) = -1; starts at the member's 0.5 m/s^2
    assert abs(a_cap[1] - (0.5 - P.jerk_max * DT)) < 1e-12 and not pl.emergency.any()
    _, _, a_cap = pl.step(0.0, [np.inf, 24.0], [np.inf, -5.0], [25.0, 25.0], [0.0, 0.0], DT)
    assert pl.emergency[1] and not pl.emergency[0]
    assert abs(a_cap[1] - (0.5 - P.jerk_max * DT - P.jerk_emergency * DT)) < 1e-12


def test_one_second_jerk_and_emergency_windows():
    t = np.arange(0, 10, 0.05)
    a = np.where(t < 5, 0.0, 2.0 * (t - 5))  # 2 m/s^3 ramp from t = 5 s
    j = jerk_window_mean(np.minimum(a, 1.0), 0.05)
    assert abs(np.nanmax(j) - 1.0) < 1e-12  # 1 m/s^2 reached in 0.5 s: 1 m/s^3 over 1 s
    assert np.isnan(j[-20:]).all()
    m = emergency_mask(t, [4.0], [5.0])
    assert not m[t <= 3.0].any() and m[(t > 3.05) & (t < 7.95)].all() and not m[t >= 8.0].any()
    assert emergency_mask(t, [9.0], []).sum() == (t > 8.0).sum()


def test_a_lifted_cap_is_eased_out_at_the_jerk_limit_not_dropped():
    """docs/maneuvers.md, Known limits (issue 16, after a cut-in): a member's cap that lifts
    (the car ahead changes lanes again) while it binds rises at the planner's jerk bound until
    the member's own law no longer reaches it, then goes; the requested acceleration
    min(law, cap) never jumps (before: from the cap to the law in one step). A member whose
    law sits below the cap loses the cap at once (nothing to ease)."""
    law = np.array([1.5, -1.0])  # the formation law's acceleration request [m/s^2]
    pl = LongitudinalPlanner(2, P)
    a_m, asked = np.zeros(2), []
    for k in range(400):
        lifted = k >= 100
        a_cap_req = np.full(2, np.inf if lifted else -0.5)
        _, _, a_cap = pl.step(0.0, np.full(2, np.inf), a_cap_req, np.full(2, 25.0), a_m, DT)
        a_r = np.minimum(law, a_cap)
        asked.append(a_r)
        if k == 101:
            assert a_cap[1] == np.inf  # not binding when lifted: dropped at once
        a_m = a_r  # ideal tracking of the request
    asked = np.array(asked)
    rate = np.abs(np.diff(asked[:, 0])) / DT
    assert rate[95:].max() <= P.jerk_max * (1 + 1e-9)
    assert asked[-1, 0] == law[0] and pl.a_cap[0] == np.inf  # eased out, then gone
    # it really rose at the jerk bound: from -0.5 to 1.5 in 2 / jerk_max seconds
    k_law = int(np.argmax(asked[:, 0] >= law[0]))
    assert abs((k_law - 100) * DT - 2.0 / P.jerk_max) <= 2 * DT


def test_firm_braking_sets_in_at_jerk_brake_and_everything_else_at_jerk_max():
    """From rest, a request of -2.5 m/s^2 (below -brake_firm = -2.0: a vehicle ahead braking
    firmly) is followed at jerk_brake (2.0 m/s^3: 0.1 m/s^2 per 50 ms step, the lag asking
    0.24); a request of -1.9 at jerk_max (0.04 per step); braking that eases towards a firm
    request, acceleration that rises, at jerk_max too."""
    pp = PlannerParams()
    assert (pp.jerk_max, pp.jerk_brake, pp.brake_firm) == (0.8, 2.0, 2.0)

    def step(a_prev, req, p=pp):
        return plan_accel(a_prev, req, DT, p.packed(), True)[0]

    assert DT == 0.05
    assert step(0.0, -2.5) == pytest.approx(-2.0 * DT, abs=1e-15)
    assert step(0.0, -1.9) == pytest.approx(-0.8 * DT, abs=1e-15)
    assert step(-2.9, -2.0) == pytest.approx(-2.9 + 0.8 * DT, abs=1e-15)  # easing: jerk_max
    assert step(-1.0, 1.0) == pytest.approx(-1.0 + 0.8 * DT, abs=1e-15)
    one = PlannerParams(jerk_brake=0.8)  # one bound throughout: the former planner
    assert step(0.0, -2.5, one) == pytest.approx(-0.8 * DT, abs=1e-15)

    def steps_to(p, a_to=-2.4, req=-2.5):
        a, n = 0.0, 0
        while a > a_to:
            a, n = step(a, req, p), n + 1
        return n

    # the jerk bound j holds while the lag asks more, |req - a| (1 - exp(-DT/tau)) > j DT; then the
    # lag alone shrinks |req - a| by exp(-DT/tau) per step down to 0.1
    lag = 1.0 - math.exp(-DT / pp.tau)
    for p, j in ((pp, 2.0), (one, 0.8)):
        gap = j * DT / lag
        expected = (2.5 - gap) / (j * DT) + math.log(gap / 0.1) / (DT / pp.tau)
        assert abs(steps_to(p) - expected) <= 2.0, j
    assert steps_to(pp) * DT < 2.0 < 3.0 < steps_to(one) * DT  # -2.4 m/s^2 within 2 s, not 3.3 s


def test_braking_the_set_speed_asks_keeps_jerk_max_and_only_traffics_sets_in_at_jerk_brake():
    """plan_step's virtual car: a request of -2.5 m/s^2 that is the speed profile's own
    (a_request == a_profile: a lower set speed, no vehicle) sets in at jerk_max; the same
    request from a vehicle ahead (a_request < a_profile) at jerk_brake. The members' caps are
    traffic's: at jerk_brake."""
    from formation_traci.control.longitudinal import plan_step
    pp = P.packed()
    inf1 = np.full(1, np.inf)

    def vc(a_profile):
        out, em = np.empty(1), np.zeros(1, dtype=np.bool_)
        a, _ = plan_step(0.0, -2.5, a_profile, inf1.copy(), inf1.copy(), np.array([-2.5]),
                         np.array([20.0]), np.zeros(1), DT, pp, out, em)
        return a, out[0]

    own, cap = vc(-2.5)
    assert own == pytest.approx(-P.jerk_max * DT, abs=1e-15)
    traffic, _ = vc(0.3)
    assert traffic == pytest.approx(-P.jerk_brake * DT, abs=1e-15)
    # the member's acceleration cap of -2.5 appears at its own acceleration (0)
    assert cap == pytest.approx(-P.jerk_brake * DT, abs=1e-15)
