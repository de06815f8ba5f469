"""Compiled per-step formation layer (sim/fast.py, road/fast_line.py) against the numpy path.

The reference is what sim/sumo_loop.py runs today: ``_targets`` -> ``fleet.control`` ->
``fleet.advance`` -> ``_advance_vc`` per control period, ``fleet.member_signals`` at the
start of every SUMO step, ``ReferenceLine.frame`` / ``to_frenet``. Both paths run side by
side for 200 SUMO steps on the straight3 and curved3 reference lines, with road and rigid
slots mixed, both vehicle models, car + truck fleets, the safety caps on and off, and the
virtual car braking to a standstill and starting again.

Tolerances: the two paths use the same formulas in the same order; they differ only in the
last ulp of a transcendental (numpy's SIMD loops vs libm). Over 1000 chained control
periods the closed loop damps these; rtol 1e-10 / atol 1e-9 leaves orders of magnitude of
margin (measured differences are ~1e-12 m and below). ``test_harness_detects_*`` show the
comparisons fail for a gain changed by 1e-7 relative.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from formation_traci.control.formation import LeaderState, rigid_targets
from formation_traci.control.schedule import SPEED_GAINS_CAR, YAW_GAINS_RETUNED
from formation_traci.models.params import (PASSENGER_CAR, SMALL_TRUCK, bicycle_params,
                                           make_tires, stack)
from formation_traci.road.fast_line import FastLine, frame_many, to_frenet_many, to_frenet_one
from formation_traci.road.geometry import reference_line_from_net
from formation_traci.road.leader import road_leader_state
from formation_traci.road.targets import road_targets
from formation_traci.sim import fast
from formation_traci.sim import fleet as fl
from formation_traci.sim.fast import (SIGNAL_COLUMNS, FastFleet, FastPathMismatch,
                                      mixed_targets_nb, rigid_targets_nb, road_targets_nb)
from formation_traci.sim.fleet import FleetConfig, FleetState
from formation_traci.sim.leader import FreeLeader
from formation_traci.sim.profile import Profile
from formation_traci.sim.sumo_loop import _advance_vc, _targets
from sumo_nets import net_path

RTOL, ATOL = 1e-10, 1e-9
POSITION_TOL_AFTER_STOP = 5e-2
"""Through a standstill the closed loop is ill-conditioned: last-bit differences between the
two paths decide discrete branches there (steering at its limit, the low-speed blend, the
'no turning around' fade of formation.py) and then grow (4e-5 rad/s within a step, seen).
After the virtual car has stopped the paths are compared by position to 5 cm (1.1 cm seen after
30 more steps); every single
control period still agrees to 1e-10 (test_control_equals_reference covers standstill)."""
N_STEPS = 200
STEP = 0.05
N_CTRL = 5
DT_C = STEP / N_CTRL


_Road = fast._RoadShim  # the field of sim.road_setup.Road that sumo_loop._targets reads


@pytest.fixture(scope="module", params=["straight3", "curved3"])
def line(request):
    return reference_line_from_net(net_path(request.param), ["entry", "main"], 1)


@pytest.fixture(scope="module")
def curved():
    return reference_line_from_net(net_path("curved3"), ["entry", "main"], 1)


@pytest.fixture(scope="module", autouse=True)
def _compiled():
    fast.warmup()


# ------------------------------------------------------------------------- builders

def make_cfg(model: str, n: int, physics_step: float = 0.01, linear: bool = False,
             mu: float = 1.0, trucks: bool = True) -> FleetConfig:
    """Alternating car / truck (cars only if not ``trucks``); per-member gains."""
    params = None
    if model == "dynamic":
        ps = []
        for i in range(n):
            veh = (PASSENGER_CAR, SMALL_TRUCK if trucks else PASSENGER_CAR)[i % 2]
            ps.append(bicycle_params(veh, mu, make_tires(veh, mu, "load", linear=linear)))
        params = stack(ps)
    k = 2.0 + 0.5 * (np.arange(n) % 3)
    k_theta = 1.5 + 0.25 * (np.arange(n) % 4)
    return FleetConfig(tuple(f"m{i}" for i in range(n)), model, params, k, k_theta,
                       SPEED_GAINS_CAR, YAW_GAINS_RETUNED, physics_step)


def make_slots(n: int, mixed: bool = True):
    """Road slots (along, across) and rigid offsets, NaN rows for the other kind."""
    along = -12.0 * np.arange(n) + 5.0
    across = np.array([0.0, 3.5, -3.5])[np.arange(n) % 3]
    is_road = np.ones(n, bool) if not mixed else (np.arange(n) % 2 == 0)
    slots = np.where(is_road[:, None], np.c_[along, across], np.nan)
    rigid = np.where(is_road[:, None], np.nan, np.c_[along, across + 0.4])
    return slots, rigid, is_road


def initial(cfg, line, slots, rigid, is_road, s_vc, v_vc, seed=0):
    """Members near (not on) their targets, speeds spread; some almost at rest."""
    rng = np.random.default_rng(seed)
    n = cfg.n
    tg = _targets(_Road(line), slots, rigid, is_road, s_vc, v_vc, 0.0)
    pos = tg.p + rng.normal(0.0, 1.0, (n, 2))
    heading = np.arctan2(tg.v[:, 1], tg.v[:, 0]) + rng.normal(0.0, 0.03, n)
    if v_vc == 0.0:
        heading = line.heading(line.to_frenet(pos)[0]) + rng.normal(0.0, 0.03, n)
    speed = np.maximum(v_vc + rng.normal(0.0, 2.0, n), 0.0)
    speed[::4] = 0.0
    yaw = speed * line.curvature(line.to_frenet(pos)[0])
    return fl.initial_state(cfg, pos, heading, speed, yaw, np.zeros(n), tg)


def vc_accel(k, v_vc):
    """Virtual car (from 18 m/s): brake hard to a standstill (t = 3.6 s), stand, start
    again, gentle speed changes."""
    if k < 80:
        a = -5.0
    elif k < 110:
        a = 0.0
    elif k < 170:
        a = 2.0
    else:
        a = -0.3 * math.sin(0.2 * k)
    if v_vc <= 0.0 and a < 0.0:
        a = 0.0
    return a


def caps(k, n, active):
    if not active:
        return None, None
    v_cap = np.full(n, np.inf)
    a_cap = np.full(n, np.inf)
    if 20 <= k < 140:
        v_cap[1::3] = 4.0 + 0.02 * k
        a_cap[::3] = -1.5
    return v_cap, a_cap


def assert_close(a, b, what, rtol=RTOL, atol=ATOL):
    np.testing.assert_allclose(a, b, rtol=rtol, atol=atol, equal_nan=True, err_msg=what)


def assert_state_close(st_f, st_r, what):
    """Positions: |p_f - p_r| <= ATOL + RTOL |p_r| per member (rtol relative to the position
    vector, not per coordinate: a road along x has y near 0); the other states, theta* and
    the unicycle speed elementwise."""
    err = np.hypot(*(st_f.x[:, :2] - st_r.x[:, :2]).T)
    scale = np.hypot(*st_r.x[:, :2].T)
    bad = ~(err <= ATOL + RTOL * scale)
    assert not bad.any(), (f"{what}: position differs by {err[bad]} m at |p| = {scale[bad]} m "
                           f"(members {np.flatnonzero(bad)})")
    assert_close(st_f.x[:, 2:], st_r.x[:, 2:], f"{what}: x[:, 2:]")
    assert_close(st_f.theta_star, st_r.theta_star, f"{what}: theta*")
    assert_close(st_f.speed_in, st_r.speed_in, f"{what}: speed_in")


# --------------------------------------------------------------- the reference path

def ref_record(cfg, road, slots, rigid, is_road, state, s_vc, v_vc, a_vc, v_cap, a_cap):
    """sumo_loop.sumo_steps' record part, numpy path: member_signals, the vc, u."""
    vc = road_leader_state(road.line, s_vc, v_vc, a_vc)
    targets = _targets(road, slots, rigid, is_road, s_vc, v_vc, a_vc)
    u, fo = fl.control(cfg, state, targets, v_cap, a_cap)
    return fl.member_signals(cfg, state, u, fo, targets, vc.theta), vc, u


def assert_signals(sig_f, sig_r, n, what):
    for j, name in enumerate(SIGNAL_COLUMNS):
        assert_close(sig_f[:, j], np.broadcast_to(sig_r[name], (n,)), f"{what}: signal {name}")


def ref_step(cfg, road, slots, rigid, is_road, state, s_vc, v_vc, a_vc, v_cap, a_cap):
    """sumo_loop.sumo_steps' record part and inner loop, numpy path."""
    line = road.line
    vc = road_leader_state(line, s_vc, v_vc, a_vc)
    targets = _targets(road, slots, rigid, is_road, s_vc, v_vc, a_vc)
    u, fo = fl.control(cfg, state, targets, v_cap, a_cap)
    sig = fl.member_signals(cfg, state, u, fo, targets, vc.theta)
    for j in range(N_CTRL):
        if j > 0:
            targets = _targets(road, slots, rigid, is_road, s_vc, v_vc, a_vc)
            u, fo = fl.control(cfg, state, targets, v_cap, a_cap)
        state = fl.advance(cfg, state, u, fo, DT_C)
        s_vc, v_vc = _advance_vc(s_vc, v_vc, a_vc, DT_C)
    return state, s_vc, v_vc, sig, vc


def run_side_by_side(cfg, line, slots, rigid, is_road, s0, v0, caps_active, n_steps=N_STEPS,
                     ff=None, inf_caps=False):
    """Both paths from the same initial state for n_steps SUMO steps. States: the two
    trajectories agree to RTOL / ATOL. Signals and the virtual car: the kernels against the
    numpy record part evaluated on the same (the kernels') state, so that derived signals
    with a large gain on the state (tire forces, accelerations at low speed) are compared
    as functions, not through the closed loop's rounding-level drift."""
    road = _Road(line)
    ff = ff or FastFleet.from_config(cfg, line, slots, rigid, is_road)
    st_r = initial(cfg, line, slots, rigid, is_road, s0, v0)
    st_f = FleetState(st_r.x.copy(), st_r.theta_star.copy(), st_r.speed_in.copy())
    s_r = s_f = s0
    v_r = v_f = v0
    worst = 0.0
    stats = {"v_vc_min": v0, "capped_v": 0, "capped_a": 0}
    for k in range(n_steps):
        a_vc = vc_accel(k, v_r)
        v_cap, a_cap = caps(k, cfg.n, caps_active)
        kv, ka = v_cap, a_cap
        if inf_caps and v_cap is None:
            kv, ka = np.full(cfg.n, np.inf), np.full(cfg.n, np.inf)
        sig_f = ff.signals(st_f, s_f, v_f, a_vc, kv, ka)
        vc_f = ff.leader_state(s_f, v_f, a_vc)
        sig_rf, vc_rf, u_rf = ref_record(cfg, road, slots, rigid, is_road, st_f, s_f, v_f,
                                         a_vc, v_cap, a_cap)
        assert_signals(sig_f, sig_rf, cfg.n, f"step {k}")
        assert_close([getattr(vc_f, f) for f in LeaderState.__slots__],
                     [getattr(vc_rf, f) for f in LeaderState.__slots__], f"step {k}: vc")
        st_r, s_r, v_r, _, _ = ref_step(cfg, road, slots, rigid, is_road, st_r, s_r, v_r, a_vc,
                                        v_cap, a_cap)
        st_f, s_f, v_f = ff.step(st_f, s_f, v_f, a_vc, kv, ka, DT_C, N_CTRL)
        stats["v_vc_min"] = min(stats["v_vc_min"], v_r)
        if v_cap is not None:
            stats["capped_v"] += int(np.sum(sig_rf["v_ref"] == v_cap))
            if cfg.model == "dynamic":
                stats["capped_a"] += int(np.sum(u_rf[:, 0] == a_cap))
        if stats["v_vc_min"] > 0.0:
            assert_state_close(st_f, st_r, f"step {k}")
        else:
            assert np.all(np.isfinite(st_f.x))
            assert_close(st_f.x[:, :2], st_r.x[:, :2], f"step {k}: position after the stop",
                         rtol=0.0, atol=POSITION_TOL_AFTER_STOP)
        assert_close([s_f, v_f], [s_r, v_r], f"step {k}: virtual car")
        worst = max(worst, float(np.max(np.abs(st_f.x - st_r.x))))
    stats["worst_dx"] = worst
    return st_r, st_f, stats, (s_r, v_r)


# ----------------------------------------------------------------------- geometry

def test_frame_equals_reference(line):
    rng = np.random.default_rng(4)
    s = np.concatenate([rng.uniform(-60.0, line.length + 60.0, 4000), line.s_nodes,
                        [0.0, line.length, -1e-9, line.length + 1e-9, -500.0, line.length + 500.0]])
    F = frame_many(FastLine.from_reference_line(line).G, s)
    f = line.frame(s)
    assert_close(F[:, 0:2], f.position, "position", rtol=0.0, atol=1e-9)
    assert_close(F[:, 2:4], f.tangent, "tangent", rtol=0.0, atol=1e-12)
    assert_close(F[:, 4], f.heading, "heading", rtol=0.0, atol=1e-12)
    assert_close(F[:, 5], f.curvature, "curvature", rtol=0.0, atol=1e-14)
    assert_close(F[:, 6], f.curvature_rate, "curvature rate", rtol=0.0, atol=1e-16)
    outside = (s < 0.0) | (s > line.length)
    assert np.all(F[outside, 5] == 0.0) and np.all(F[outside, 6] == 0.0)


def test_to_frenet_equals_reference(line):
    fline = FastLine.from_reference_line(line)
    rng = np.random.default_rng(5)
    n = 3000
    s_true = rng.uniform(-120.0, line.length + 120.0, n)  # beyond both ends too
    d_true = rng.uniform(-30.0, 30.0, n)
    xy = np.vstack([line.from_frenet(s_true, d_true),
                    rng.uniform(-500.0, 6500.0, (50, 2))])  # far off the line
    s_ref, d_ref = line.to_frenet(xy)
    m = len(xy)
    guesses = {
        "none": np.full(m, np.nan),
        "good": s_ref + rng.normal(0.0, 2.0, m),
        "far": s_ref + rng.choice([-1.0, 1.0], m) * rng.uniform(200.0, 3000.0, m),
        "zero": np.zeros(m),
        "wild": rng.choice([-1e7, 1e7, np.inf, -np.inf], m),
    }
    for name, g in guesses.items():
        s_f, d_f = to_frenet_many(fline.G, xy, g)
        # the reference's vectorised Newton keeps iterating converged points while others
        # have not (steps < 1e-10 m), so allow its tolerance on top of rounding
        assert_close(s_f, s_ref, f"s, guess {name}", rtol=0.0, atol=1e-9)
        assert_close(d_f, d_ref, f"d, guess {name}", rtol=0.0, atol=1e-9)
    # the round trip itself (sanity of the data, not of the kernel); the reference's Newton
    # moves at most 50 x 2 m from its seed, so points > 100 m past an end do not converge
    # (the kernel reproduces that too)
    near = (s_true > -90.0) & (s_true < line.length + 90.0)
    assert np.max(np.abs(s_ref[:n][near] - s_true[near])) < 1e-7
    assert np.max(np.abs(s_ref[:n][~near] - s_true[~near])) > 1.0
    s1, d1 = fline.to_frenet(xy[:5])
    assert_close(s1, s_ref[:5], "wrapper")


def test_to_frenet_edge_inputs(curved):
    fline = FastLine.from_reference_line(curved)
    s, d = fline.to_frenet(np.array([[np.nan, 0.0], [100.0, -5.0]]))
    assert np.isnan(s[0]) and np.isnan(d[0]) and np.isfinite(s[1])
    s, d = fline.to_frenet(np.empty((0, 2)))
    assert s.shape == (0,) and d.shape == (0,)
    xy = curved.from_frenet(np.array([5.0, 1234.5, 3000.0]), np.array([-3.5, 0.0, 7.0]))
    s_ref, d_ref = curved.to_frenet(xy)
    for g in (None, 1000.0, [5.0, 1234.0, 3001.0]):
        s, d = fline.to_frenet(xy[::-1][::-1], g)  # a non-contiguous view
        assert_close(s, s_ref, f"guess {g}")
        assert_close(d, d_ref, f"guess {g}")
    for i in range(3):
        assert_close(to_frenet_one(fline.G, xy[i, 0], xy[i, 1], np.nan), (s_ref[i], d_ref[i]),
                     "to_frenet_one")
    assert_close(fline.frame(1234.5), frame_many(fline.G, np.array([1234.5]))[0], "frame")


@pytest.mark.parametrize("model", ["dynamic", "kinematic"])
def test_kinematics_equals_reference(curved, model):
    n = 7
    cfg = make_cfg(model, n)
    slots, rigid, is_road = make_slots(n)
    ff = FastFleet.from_config(cfg, curved, slots, rigid, is_road, verify=False)
    st = initial(cfg, curved, slots, rigid, is_road, 1400.0, 12.0)
    if model == "dynamic":
        st.x[:, 4] = np.linspace(-0.05, 0.05, n)
    for a, b in zip(ff.kinematics(st), fl.kinematics(cfg, st)):
        assert_close(a, b, "kinematics")
    vc = ff.leader_state(1400.0, 12.0, -0.4)
    vc_r = road_leader_state(curved, 1400.0, 12.0, -0.4)
    assert_close([getattr(vc, f) for f in LeaderState.__slots__],
                 [getattr(vc_r, f) for f in LeaderState.__slots__], "leader state")


# ------------------------------------------------------------------------ targets

def test_targets_equal_reference(line):
    fline = FastLine.from_reference_line(line)
    n = 7
    slots, rigid, is_road = make_slots(n)
    offs = np.c_[-12.0 * np.arange(n) + 5.0, np.array([0.0, 3.5, -3.5, 7.0, 0.0, -7.0, 1.0])]
    for s, v, a in [(5.0, 20.0, 1.0), (900.0, 30.0, -2.0), (1500.0, 0.0, 0.0),
                    (2700.0, 33.0, 0.4), (line.length - 10.0, 25.0, -1.0)]:
        ref = road_targets(line, s, v, a, offs)
        T = road_targets_nb(fline.G, s, v, a, offs)
        for blk, arr in zip((slice(0, 2), slice(2, 4), slice(4, 6)), (ref.p, ref.v, ref.a)):
            assert_close(T[:, blk], arr, f"road targets at s={s}")
        vc = road_leader_state(line, s, v, a)
        ref = rigid_targets(vc, offs)
        T = rigid_targets_nb(np.array([vc.x, vc.y, vc.theta, vc.v, vc.omega, vc.v_dot,
                                       vc.omega_dot]), offs)
        for blk, arr in zip((slice(0, 2), slice(2, 4), slice(4, 6)), (ref.p, ref.v, ref.a)):
            assert_close(T[:, blk], arr, f"rigid targets at s={s}")
        full_slots, full_rigid = np.nan_to_num(slots) + offs, np.nan_to_num(rigid) - offs
        for mask, sl, rg in ((is_road, slots, rigid), (np.ones(n, bool), full_slots, rigid),
                             (np.zeros(n, bool), slots, full_rigid)):
            ref = _targets(_Road(line), sl, rg, mask, s, v, a)
            T = mixed_targets_nb(fline.G, np.nan_to_num(sl), np.nan_to_num(rg), mask,
                                 s, v, a)
            for blk, arr in zip((slice(0, 2), slice(2, 4), slice(4, 6)), (ref.p, ref.v, ref.a)):
                assert_close(T[:, blk], arr, f"mixed targets at s={s}")


@pytest.mark.parametrize("model", ["dynamic", "kinematic"])
def test_control_equals_reference(curved, model):
    n = 12
    cfg = make_cfg(model, n)
    slots, rigid, is_road = make_slots(n)
    ff = FastFleet.from_config(cfg, curved, slots, rigid, is_road)
    for seed, (s, v, a) in enumerate([(950.0, 28.0, 0.5), (1200.0, 0.0, 0.0), (20.0, 3.0, -1.0)]):
        st = initial(cfg, curved, slots, rigid, is_road, s, v, seed)
        if model == "dynamic":
            st.x[:, 6] = np.linspace(-0.7, 0.7, n)  # steering at and inside its limit
            st.x[:, 4] = np.linspace(-0.02, 0.02, n)
        tg = _targets(_Road(curved), slots, rigid, is_road, s, v, a)
        for v_cap, a_cap in [(None, None), caps(50, n, True),
                             (np.full(n, np.nan), np.full(n, np.nan))]:
            u_r, fo_r = fl.control(cfg, st, tg, v_cap, a_cap)
            u_f, fo_f = ff.control(st, tg, v_cap, a_cap)
            assert_close(u_f, u_r, "u")
            for name in fo_r.__dataclass_fields__:
                assert_close(getattr(fo_f, name), getattr(fo_r, name), name)


# --------------------------------------------------------------- closed loop, 200 steps

@pytest.mark.parametrize("model", ["dynamic", "kinematic"])
@pytest.mark.parametrize("caps_active", [True, False])
def test_step_equals_reference(line, model, caps_active):
    n = 6
    cfg = make_cfg(model, n)
    slots, rigid, is_road = make_slots(n)
    st_r, st_f, stats, (s_end, v_end) = run_side_by_side(cfg, line, slots, rigid, is_road,
                                                         s0=850.0, v0=18.0,
                                                         caps_active=caps_active)
    # the scenario reached a standstill of the virtual car and started again; the caps bit
    assert stats["v_vc_min"] == 0.0 and v_end > 0.0
    if caps_active:
        assert stats["capped_v"] > 50
        assert model == "kinematic" or stats["capped_a"] > 50
    print(f"max |x_fast - x_ref| over {N_STEPS} steps: {stats['worst_dx']:.2e}")


@pytest.mark.parametrize("fleet", ["car+truck", "cars"])
def test_step_standstill_and_low_speed(curved, fleet):
    """Start at rest near the line start (slots behind s = 0: the straight extension), the
    virtual car standing, then creeping: the low-speed blend of the bicycle and V_EPS.

    The car + truck fleet runs with physics_step 0.005 s: at the default 0.01 s the small
    truck's yaw mode (about 900 / v 1/s with load-dependent tires at mu = 1) is outside RK4's
    stability region between about 2 and 3.3 m/s, and the numpy path itself then amplifies
    a 1e-15 perturbation ~20x per SUMO step (see the report of this change)."""
    n = 5
    cfg = make_cfg("dynamic", n, physics_step=0.005 if fleet == "car+truck" else 0.01,
                   trucks=fleet == "car+truck")
    slots, rigid, is_road = make_slots(n)
    road = _Road(curved)
    ff = FastFleet.from_config(cfg, curved, slots, rigid, is_road)
    st_r = initial(cfg, curved, slots, rigid, is_road, 8.0, 0.0)
    st_r = FleetState(st_r.x, st_r.theta_star, np.zeros(n))
    st_r.x[:, 3] = 0.0
    st_f = FleetState(st_r.x.copy(), st_r.theta_star.copy(), st_r.speed_in.copy())
    s_r = s_f = 8.0
    v_r = v_f = 0.0
    speeds = []
    for k in range(N_STEPS):
        speeds.append(st_r.x[:, 3].copy())
        a_vc = 0.0 if k < 40 else (0.3 if k < 120 else -0.5)
        if v_r <= 0.0 and a_vc < 0.0:
            a_vc = 0.0
        sig_f = ff.signals(st_f, s_f, v_f, a_vc)
        sig_rf, _, _ = ref_record(cfg, road, slots, rigid, is_road, st_f, s_f, v_f, a_vc, None,
                                  None)
        assert_signals(sig_f, sig_rf, n, f"step {k}")
        st_r, s_r, v_r, _, _ = ref_step(cfg, road, slots, rigid, is_road, st_r, s_r, v_r,
                                        a_vc, None, None)
        st_f, s_f, v_f = ff.step(st_f, s_f, v_f, a_vc, None, None, DT_C, N_CTRL)
        assert_state_close(st_f, st_r, f"step {k}")
        assert_close([s_f, v_f], [s_r, v_r], f"step {k}: vc")
    speeds = np.array(speeds)
    assert np.all(speeds[0] == 0.0)  # from rest, through the kinematic and blend regions
    assert np.sum((speeds > 1.0) & (speeds < 3.0)) > 100


@pytest.mark.parametrize("model", ["dynamic", "kinematic"])
def test_step_all_road_all_rigid_substeps_linear_tires(curved, model):
    """All-road and all-rigid fleets; physics_step 0.004 (3 RK4 sub-steps per period);
    linear tires on ice; explicit +inf caps."""
    n = 4
    cfg = make_cfg(model, n, physics_step=0.004, linear=True, mu=0.25)
    for mixed_mask in (np.ones(n, bool), np.zeros(n, bool)):
        slots, rigid, _ = make_slots(n, mixed=False)
        rigid = np.where(mixed_mask[:, None], np.nan, slots)
        slots = np.where(mixed_mask[:, None], slots, np.nan)
        run_side_by_side(cfg, curved, slots, rigid, mixed_mask, s0=2500.0, v0=20.0,
                         caps_active=False, n_steps=80, inf_caps=True)


def test_end_of_line(curved):
    """Slots past the line's end: the straight extension in targets and projection."""
    n = 3
    cfg = make_cfg("dynamic", n)
    slots = np.array([[30.0, 0.0], [10.0, 3.5], [-10.0, -3.5]])
    rigid = np.full((n, 2), np.nan)
    run_side_by_side(cfg, curved, slots, rigid, np.ones(n, bool), s0=curved.length - 15.0,
                     v0=20.0, caps_active=False, n_steps=60)


# ----------------------------------------------------------------- free space

@pytest.mark.parametrize("model", ["dynamic", "kinematic"])
@pytest.mark.parametrize("interp", ["linear", "smooth"])
def test_free_space_equals_reference(model, interp):
    n = 5
    cfg = make_cfg(model, n)
    offsets = np.array([[0.0, 0.0], [-10.0, 4.0], [-10.0, -4.0], [-20.0, 0.0], [5.0, 8.0]])
    leader = FreeLeader(Profile((0.0, 2.0, 5.0, 8.0), (15.0, 22.0, 0.0, 6.0), interp),
                        Profile((1.0, 4.0, 9.0), tuple(np.radians([0.0, 6.0, -4.0])), interp),
                        0.004)
    ff = FastFleet.free_space(cfg, offsets, leader)
    pose = (3.0, -2.0, 0.2)
    st_r = fl.initial_state(cfg, rigid_targets(leader.sample(0.0, pose), offsets).p
                            + np.random.default_rng(2).normal(0.0, 1.0, (n, 2)),
                            np.full(n, 0.2), np.full(n, 15.0), np.zeros(n), np.zeros(n),
                            rigid_targets(leader.sample(0.0, pose), offsets))
    st_f = FleetState(st_r.x.copy(), st_r.theta_star.copy(), st_r.speed_in.copy())
    pose_r = pose_f = pose
    for k in range(N_STEPS):
        t = k * STEP
        sig_f = ff.signals_free(st_f, t, pose_f)
        vc_f = leader.sample(t, pose_f)
        tg_f = rigid_targets(vc_f, offsets)
        u_f, fo_f = fl.control(cfg, st_f, tg_f)
        assert_signals(sig_f, fl.member_signals(cfg, st_f, u_f, fo_f, tg_f, vc_f.theta), n,
                       f"step {k}")
        for j in range(N_CTRL):  # runner.free_space_steps
            tc = t + j * DT_C
            vc = leader.sample(tc, pose_r)
            tg = rigid_targets(vc, offsets)
            u, fo = fl.control(cfg, st_r, tg)
            if j == 0:
                sig_r = fl.member_signals(cfg, st_r, u, fo, tg, vc.theta)
            st_r = fl.advance(cfg, st_r, u, fo, DT_C)
            pose_r = leader.advance(tc, pose_r, DT_C)
        st_f, pose_f = ff.step_free(st_f, t, pose_f, DT_C, N_CTRL)
        assert_signals(sig_f, sig_r, n, f"step {k} (reference trajectory)")
        assert_state_close(st_f, st_r, f"step {k}")
        assert_close(pose_f, pose_r, f"step {k}: pose", atol=1e-9)


# ---------------------------------------------------------- the tests can fail

def test_harness_detects_a_tiny_gain_change(curved):
    """The side-by-side comparison fails when the kernels use k (1 + 1e-7)."""
    n = 4
    cfg = make_cfg("dynamic", n)
    slots, rigid, is_road = make_slots(n)
    ff = FastFleet.from_config(cfg, curved, slots, rigid, is_road)
    ff.k = ff.k * (1.0 + 1e-7)
    with pytest.raises(AssertionError):
        run_side_by_side(cfg, curved, slots, rigid, is_road, 850.0, 24.0, True, n_steps=40,
                         ff=ff)


def test_harness_detects_a_signal_column_swap(curved):
    n = 3
    cfg = make_cfg("kinematic", n)
    slots, rigid, is_road = make_slots(n)
    ff = FastFleet.from_config(cfg, curved, slots, rigid, is_road)
    cols = ff.cols.copy()
    cols[[7, 8]] = cols[[8, 7]]  # ex <-> ey
    ff.cols = cols
    with pytest.raises(AssertionError, match="signal e[xy]"):
        run_side_by_side(cfg, curved, slots, rigid, is_road, 850.0, 24.0, False, n_steps=3,
                         ff=ff)


def test_verify_raises_on_mismatch(curved, monkeypatch):
    """from_config(verify=True) compares with the numpy path and refuses a mismatch."""
    n = 3
    cfg = make_cfg("dynamic", n)
    slots, rigid, is_road = make_slots(n)
    real = fl.control

    def off(cfg_, state, targets, v_cap=None, a_cap=None):
        u, fo = real(cfg_, state, targets, v_cap, a_cap)
        return u * (1.0 + 1e-6), fo

    monkeypatch.setattr(fl, "control", off)
    monkeypatch.setattr(fast, "recompile_all", lambda: None)
    with pytest.raises(FastPathMismatch):
        FastFleet.from_config(cfg, curved, slots, rigid, is_road)


def test_signal_columns_follow_the_contract():
    from formation_traci.record.columns import TRAJECTORY_COLUMNS

    names = [c.name for c in TRAJECTORY_COLUMNS]
    assert list(SIGNAL_COLUMNS) == [c for c in names if c not in fast.FILLED_BY_CALLER]
    assert len(SIGNAL_COLUMNS) == 26  # 23 of the seed's model + power, drag_force, drag_ratio


# ------------------------------------------------------------------------- timings
