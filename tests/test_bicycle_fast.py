"""Compiled RK4 kernels (models/bicycle_fast.py) against the numpy reference integrate()."""
import zlib

from dataclasses import replace

import numpy as np
import pytest

from formation_traci.models import bicycle, bicycle_fast, kinematic
from formation_traci.models.bicycle import S, U
from formation_traci.models.kinematic import KU
from formation_traci.models.params import (PASSENGER_CAR, SMALL_TRUCK, LowSpeedBlend,
                                           MagicFormula, Tires, bicycle_params, make_tires,
                                           stack)
from formation_traci.sim.integrate import integrate, substeps

RTOL, ATOL = 1e-11, 1e-12  # one call: rounding-level agreement
# 1000 chained calls: the two paths differ only in the last-ulp rounding of the
# transcendentals (libm in the kernel, numpy's SIMD loops in the reference), a few 1e-16
# relative per call. Each call's difference is carried into the next. The speed, side slip
# and yaw rate dynamics are damped, so their differences do not grow; heading and
# positions integrate them and accumulate roughly linearly: 1000 calls x (ulp of the
# value + h v x heading error) ~ 1000 x 1e-13 m = 1e-10 m for positions up to ~1e3 m,
# ~1e-12 rad for the heading. atol = 1e-9 m (positions) / 1e-11 (the rest) keeps a 10x
# margin over that bound; rtol stays 1e-11. Measured: max |difference| 1.2e-13 m.
RTOL_CHAIN = 1e-11
ATOL_CHAIN = (1e-9, 1e-9, 1e-11, 1e-11, 1e-11, 1e-11, 1e-11)  # per state, S order
ATOL_CHAIN_UNICYCLE = (1e-9, 1e-9, 1e-11)  # X, Y, PSI

N = 240  # vehicles per test fleet, split into the speed regimes below


@pytest.fixture(scope="module", autouse=True)
def _compiled():
    bicycle_fast.warmup()


def _params(veh, mu, kind="load", linear=False, blend=None):
    tires = make_tires(veh, mu, kind, linear=linear)
    if blend is None:
        return bicycle_params(veh, mu, tires)
    return bicycle_params(veh, mu, tires, blend)


def _custom_tires_params():
    """Different B, C, D, E front and rear (catches a front/rear mix-up) and a non-default
    low-speed blend (catches hard-coded v_low, v_high, tau, tau_stop)."""
    front = MagicFormula(B=9.1, C=1.5, D=-6.0e3, E=-4.0)
    rear = MagicFormula(B=8.5, C=1.8, D=-9.0e3, E=-7.5)  # stiffer rear: understeer
    blend = LowSpeedBlend(v_low=0.7, v_high=4.0, tau=0.08, tau_stop=0.2)
    return bicycle_params(PASSENGER_CAR, 0.25, Tires(front, rear, False), blend)


def _mixed_fleet(n, linear=False):
    """Alternating car / truck, alternating mu 0.25 / 1.0 / 0.6, load-dependent tires."""
    members = []
    for i in range(n):
        veh = (PASSENGER_CAR, SMALL_TRUCK)[i % 2]
        mu = (0.25, 1.0, 0.6)[i % 3]
        members.append(_params(veh, mu, "load", linear=linear))
    return stack(members)


CASES = {
    "car-seed-mu1": lambda n: _params(PASSENGER_CAR, 1.0, "seed"),
    "car-seed-mu0.25": lambda n: _params(PASSENGER_CAR, 0.25, "seed"),
    "car-load-mu0.25": lambda n: _params(PASSENGER_CAR, 0.25, "load"),
    "car-linear-mu0.25": lambda n: _params(PASSENGER_CAR, 0.25, "load", linear=True),
    "truck-load-mu0.25": lambda n: _params(SMALL_TRUCK, 0.25, "load"),
    "truck-seed-mu0.6": lambda n: _params(SMALL_TRUCK, 0.6, "seed"),
    "car-custom-tires-blend": lambda n: _custom_tires_params(),
    "fleet-car+truck": lambda n: _mixed_fleet(n),
    "fleet-car+truck-linear": lambda n: _mixed_fleet(n, linear=True),
}


def _row(value, n):
    return np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()


def random_states(rng, p, n=N):
    """States over the whole speed range, steering up to (and exactly at) its limit."""
    v_low, v_high = p.v_low, p.v_high
    smax = _row(p.steer_max, n)
    q = n // 6
    v = np.concatenate([
        np.zeros(q),  # standstill
        rng.uniform(0.0, v_low, q),  # kinematic only
        rng.uniform(v_low, v_high, q),  # blend region
        rng.uniform(v_high, 12.0, q),
        rng.uniform(12.0, 40.0, n - 4 * q),  # highway
    ])
    v[:5] = -1e-9  # roundoff below zero from outside: project() floors it
    rng.shuffle(v)
    x = np.zeros((n, bicycle.N_STATES))
    x[:, S.X] = rng.uniform(-500, 500, n)
    x[:, S.Y] = rng.uniform(-500, 500, n)
    x[:, S.PSI] = rng.uniform(-np.pi, np.pi, n)
    x[:, S.V] = v
    x[:, S.BETA] = rng.uniform(-0.15, 0.15, n)
    x[:, S.R] = rng.uniform(-0.8, 0.8, n)
    delta = rng.uniform(-1.0, 1.0, n) * smax
    kind = rng.integers(0, 4, n)
    delta = np.where(kind == 1, smax * rng.choice([-1.0, 1.0], n), delta)  # at the limit
    delta = np.where(kind == 2, (smax - rng.uniform(0, 2e-3, n)) * rng.choice([-1.0, 1.0], n), delta)
    x[:, S.DELTA] = delta
    return x


def random_inputs(rng, p, n=N):
    """Desired accelerations beyond the traction and braking limits; steering rates beyond
    the rate limit, some pushing into the angle limit, some zero."""
    srm = _row(p.steer_rate_max, n)
    u = np.empty((n, 2))
    u[:, U.A_REF] = rng.uniform(-12.0, 8.0, n)
    rate = rng.uniform(-1.5, 1.5, n) * srm
    u[:, U.STEER_RATE] = np.where(rng.random(n) < 0.1, 0.0, rate)
    return u


def assert_close_per_state(actual, desired, rtol, atol):
    """assert_allclose column by column, with one atol per state column."""
    assert actual.shape == desired.shape and actual.shape[1] == len(atol)
    for j, atol_j in enumerate(atol):
        np.testing.assert_allclose(actual[:, j], desired[:, j], rtol=rtol, atol=atol_j,
                                   err_msg=f"state column {j}")


def reference(x, u, p, dt, max_step):
    return integrate(bicycle.rhs, x, u, p, dt, max_step, bicycle.project)


def kernel(x, u, p, dt, max_step):
    P = bicycle_fast.pack_params(p, x.shape[0])
    return bicycle_fast.integrate_bicycle(x, u, P, dt, substeps(dt, max_step))


def assert_regimes_exercised(x, u, p):
    """The state set really covers the cases the kernel must reproduce."""
    _, _, _, _, f_lf, f_max = bicycle._forces(x, u, p)
    f_brake = bicycle.braking_force_max(p)
    f_max, f_brake = _row(f_max, len(x)), _row(f_brake, len(x))
    assert np.sum(f_lf == f_max) >= 5, "traction limit never active"
    assert np.sum(f_lf == -f_brake) >= 5, "braking limit never active"
    w = bicycle._blend_weight(x[:, S.V], p)
    assert np.sum((w > 0) & (w < 1)) >= 10 and np.sum(w == 0) >= 10 and np.sum(w == 1) >= 10
    assert np.sum(x[:, S.V] == 0) >= 10
    smax = _row(p.steer_max, len(x))
    rate = u[:, U.STEER_RATE]
    pushing = ((x[:, S.DELTA] >= smax) & (rate > 0)) | ((x[:, S.DELTA] <= -smax) & (rate < 0))
    assert np.sum(pushing) >= 3, "steering never pushed into its angle limit"
    assert np.sum(np.abs(rate) > _row(p.steer_rate_max, len(x))) >= 10


@pytest.mark.parametrize("dt,max_step", [(0.01, 0.01), (0.05, 0.01), (0.02, 0.004), (0.1, 0.1)])
@pytest.mark.parametrize("case", sorted(CASES))
def test_one_call_matches_numpy(case, dt, max_step):
    rng = np.random.default_rng([zlib.crc32(case.encode()), int(dt * 1000)])
    p = CASES[case](N)
    x = random_states(rng, p)
    u = random_inputs(rng, p)
    assert_regimes_exercised(x, u, p)
    x_in, u_in = x.copy(), u.copy()
    ref = reference(x, u, p, dt, max_step)
    got = kernel(x, u, p, dt, max_step)
    assert got.shape == ref.shape and got.dtype == np.float64
    np.testing.assert_array_equal(x, x_in)  # inputs untouched
    np.testing.assert_array_equal(u, u_in)
    assert not np.allclose(ref, x, rtol=1e-6, atol=1e-6)  # the step did something
    np.testing.assert_allclose(got, ref, rtol=RTOL, atol=ATOL)


def chain_states(rng, p, group):
    """Start states of the three groups of :func:`chain_inputs`."""
    n = len(group)
    x = np.zeros((n, bicycle.N_STATES))
    x[:, S.X] = rng.uniform(-500, 500, n)
    x[:, S.Y] = rng.uniform(-500, 500, n)
    x[:, S.PSI] = rng.uniform(-np.pi, np.pi, n)
    x[:, S.V] = np.select([group == 0, group == 1],
                          [rng.uniform(0.0, 2.5, n), rng.uniform(12.0, 40.0, n)],
                          rng.uniform(3.0, 20.0, n))
    x[:, S.V] = np.where((rng.random(n) < 0.3) & (group != 1), 0.0, x[:, S.V])  # some at rest
    x[:, S.BETA] = rng.uniform(-0.01, 0.01, n)
    x[:, S.R] = rng.uniform(-0.05, 0.05, n)
    x[:, S.DELTA] = np.where(group == 0, rng.uniform(-1, 1, n) * _row(p.steer_max, n),
                             rng.uniform(-0.005, 0.005, n))
    return x


def chain_inputs(rng, x, t, p, group, phase):
    """Closed-loop-like inputs computed from the (reference) state at time t.

    group 0: manoeuvring at walking pace (kinematic model and blend region), steering
             swept lock to lock at 1.5 x the rate limit, pushing into the angle limit;
    group 1: highway, random desired accelerations far beyond the traction and braking
             limits, a gentle slalom (lateral acceleration < 1 m/s^2, no spin-out);
    group 2: braking at -8 m/s^2 through the blend region to an exponential standstill.
    """
    n = len(x)
    v, delta = x[:, S.V], x[:, S.DELTA]
    srm = _row(p.steer_rate_max, n)
    u = np.empty((n, 2))
    sweep = 1.5 * srm * np.sign(np.sin(2 * np.pi * t / 6.0 + phase))
    slalom = 0.05 / np.maximum(v, 1.0) * np.sin(2 * np.pi * t / 5.0 + phase)
    track = np.clip(4.0 * (slalom - delta), -1.5 * srm, 1.5 * srm)
    a_hwy = np.where(v < 12.0, 3.0, np.where(v > 40.0, -3.0, rng.uniform(-12.0, 8.0, n)))
    a_slow = np.where(v > 2.5, -1.5, rng.uniform(-2.0, 2.0, n))
    u[:, U.A_REF] = np.select([group == 0, group == 1], [a_slow, a_hwy], -8.0)
    u[:, U.STEER_RATE] = np.select([group == 0, group == 1], [sweep, track],
                                   np.clip(-4.0 * delta, -srm, srm))
    return u


@pytest.mark.parametrize("case", sorted(CASES))
def test_1000_chained_calls_match_numpy(case):
    """1000 calls of 10 ms with new inputs each call and the state carried over, as in a
    run. The inputs come from the reference state and are fed to both paths.

    Not covered: spin-outs (|beta| -> pi, e.g. full lock at highway speed on ice). There the
    model is chaotic (with the linear tire also unbounded), any last-ulp difference
    grows to O(1) within a few hundred calls, and no two floating-point implementations
    (numpy's own SIMD and scalar loops included) agree; a single call from such states
    still agrees (test_one_call_extreme_states).
    """
    rng = np.random.default_rng(7)
    p = CASES[case](N)
    P = bicycle_fast.pack_params(p, N)
    dt, n_sub = 0.01, 1
    group = np.arange(N) % 3
    phase = rng.uniform(0, 2 * np.pi, N)
    x_ref = chain_states(rng, p, group)
    x_fast = x_ref.copy()
    smax = _row(p.steer_max, N)
    seen = dict(traction=0, braking=0, blend=0, at_limit=0)
    for step in range(1000):
        u = chain_inputs(rng, x_ref, step * dt, p, group, phase)
        _, _, _, _, f_lf, f_max = bicycle._forces(x_ref, u, p)
        w = bicycle._blend_weight(x_ref[:, S.V], p)
        seen["traction"] += np.sum(f_lf == f_max)
        seen["braking"] += np.sum(f_lf == -bicycle.braking_force_max(p))
        seen["blend"] += np.sum((w > 0) & (w < 1))
        rate = u[:, U.STEER_RATE]
        seen["at_limit"] += np.sum(((x_ref[:, S.DELTA] >= smax) & (rate > 0))
                                   | ((x_ref[:, S.DELTA] <= -smax) & (rate < 0)))
        x_ref = integrate(bicycle.rhs, x_ref, u, p, dt, 0.01, bicycle.project)
        x_fast = bicycle_fast.integrate_bicycle(x_fast, u, P, dt, n_sub)
    assert all(count >= 100 for count in seen.values()), seen
    assert np.all(np.isfinite(x_ref))
    assert np.abs(x_ref[group == 1, S.BETA]).max() < 0.1  # no spin-out (see docstring)
    assert np.all(x_ref[group == 2, S.V] < 1e-3)  # all brought to (exponential) standstill
    assert np.all(x_ref[group == 1, S.V] > 10.0)
    assert_close_per_state(x_fast, x_ref, RTOL_CHAIN, ATOL_CHAIN)


@pytest.mark.parametrize("case", sorted(CASES))
def test_one_call_extreme_states(case):
    """Spinning, sliding and reversing-course states (beta up to pi, high yaw rates)."""
    rng = np.random.default_rng(zlib.crc32(case.encode()))
    p = CASES[case](N)
    x = random_states(rng, p)
    x[:, S.BETA] = rng.uniform(-np.pi, np.pi, N)
    x[:, S.R] = rng.uniform(-3.0, 3.0, N)
    x[:, S.V] = np.where(rng.random(N) < 0.2, rng.uniform(40.0, 70.0, N), x[:, S.V])
    u = random_inputs(rng, p)
    ref = reference(x, u, p, 0.01, 0.01)
    got = kernel(x, u, p, 0.01, 0.01)
    assert np.all(np.isfinite(ref))
    np.testing.assert_allclose(got, ref, rtol=RTOL, atol=ATOL)


_RESISTANCE_PARAMS = ("resistances", "c_d", "frontal_area", "rho_air", "drag_ratio", "grade")


@pytest.mark.parametrize("name", bicycle_fast.PARAM_NAMES)
def test_every_parameter_reaches_the_kernel(name):
    """The comparison can fail: nudging any one packed parameter (or flipping the tire law)
    moves the result far beyond the tolerance, so a wrong column, a hard-coded value or a
    missing term would be caught."""
    rng = np.random.default_rng(3)
    p = _custom_tires_params()
    if name in _RESISTANCE_PARAMS:  # with resistances on (docs/energy.md), off they do nothing
        p = replace(p, resistances=True, drag_ratio=0.7, grade=0.03)
    x = random_states(rng, p)
    u = random_inputs(rng, p)
    dt, n_sub = 0.01, 1
    ref = reference(x, u, p, dt, 0.01)
    P = bicycle_fast.pack_params(p, N)
    np.testing.assert_allclose(bicycle_fast.integrate_bicycle(x, u, P, dt, n_sub), ref,
                               rtol=RTOL, atol=ATOL)
    j = bicycle_fast.PARAM_NAMES.index(name)
    if name in ("linear_tire", "resistances"):
        P[:, j] = 1.0 - P[:, j]
    else:
        P[:, j] *= 1.0 + 1e-6
    got = bicycle_fast.integrate_bicycle(x, u, P, dt, n_sub)
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(got, ref, rtol=RTOL, atol=ATOL)


def test_pack_params_broadcasts_and_validates():
    car = _params(PASSENGER_CAR, 0.25, "load")
    P = bicycle_fast.pack_params(car, 3)
    assert P.shape == (3, bicycle_fast.N_PARAMS) and P.dtype == np.float64
    assert P.flags.c_contiguous
    for j, name in enumerate(bicycle_fast.PARAM_NAMES):
        assert np.all(P[:, j] == float(getattr(car, name)))
    lin = bicycle_fast.pack_params(_params(PASSENGER_CAR, 0.25, "load", linear=True), 2)
    assert np.all(lin[:, bicycle_fast.PARAM_NAMES.index("linear_tire")] == 1.0)
    assert np.all(P[:, bicycle_fast.PARAM_NAMES.index("linear_tire")] == 0.0)

    fleet = stack([car, _params(SMALL_TRUCK, 1.0, "load")])
    Pf = bicycle_fast.pack_params(fleet, 2)
    m = bicycle_fast.PARAM_NAMES.index("m")
    assert list(Pf[:, m]) == [PASSENGER_CAR.m, SMALL_TRUCK.m]
    with pytest.raises(ValueError):
        bicycle_fast.pack_params(fleet, 3)  # (2,) arrays cannot fill 3 rows
    assert bicycle_fast.pack_params(car, 0).shape == (0, bicycle_fast.N_PARAMS)


def test_kernel_rejects_bad_shapes_and_handles_empty_fleet():
    p = _params(PASSENGER_CAR, 1.0)
    x = np.zeros((2, 7))
    u = np.zeros((2, 2))
    P = bicycle_fast.pack_params(p, 2)
    with pytest.raises(ValueError):
        bicycle_fast.integrate_bicycle(x, np.zeros((3, 2)), P, 0.01, 1)
    with pytest.raises(ValueError):
        bicycle_fast.integrate_bicycle(x, u, bicycle_fast.pack_params(p, 3), 0.01, 1)
    with pytest.raises(ValueError):
        bicycle_fast.integrate_bicycle(np.zeros((2, 6)), u, P, 0.01, 1)
    with pytest.raises(ValueError):
        bicycle_fast.integrate_bicycle(x, u, P, 0.01, 0)
    empty = bicycle_fast.integrate_bicycle(np.zeros((0, 7)), np.zeros((0, 2)),
                                           bicycle_fast.pack_params(p, 0), 0.01, 1)
    assert empty.shape == (0, 7)


# --- kinematic unicycle ---------------------------------------------------------------

def _unicycle_inputs(rng, n):
    u = np.empty((n, 2))
    u[:, KU.V] = rng.uniform(-5.0, 40.0, n)  # negative speed requests are floored at 0
    u[:, KU.OMEGA] = rng.uniform(-1.0, 1.0, n)
    return u


@pytest.mark.parametrize("dt,max_step", [(0.01, 0.01), (0.05, 0.01), (0.1, 0.1)])
def test_unicycle_one_call_matches_numpy(dt, max_step):
    rng = np.random.default_rng(11)
    n = 100
    x = np.column_stack([rng.uniform(-500, 500, n), rng.uniform(-500, 500, n),
                         rng.uniform(-np.pi, np.pi, n)])
    u = _unicycle_inputs(rng, n)
    assert np.any(u[:, KU.V] < 0)
    x_in = x.copy()
    ref = integrate(kinematic.rhs, x, u, None, dt, max_step)
    got = bicycle_fast.integrate_unicycle(x, u, dt, substeps(dt, max_step))
    np.testing.assert_array_equal(x, x_in)
    stopped = u[:, KU.V] < 0
    np.testing.assert_array_equal(ref[stopped, :2], x[stopped, :2])  # no reversing
    np.testing.assert_allclose(got, ref, rtol=RTOL, atol=ATOL)
    # and the comparison can fail: a sign error in the floor would be caught
    u_bad = u.copy()
    u_bad[:, KU.V] = np.abs(u_bad[:, KU.V])
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(
            bicycle_fast.integrate_unicycle(x, u_bad, dt, substeps(dt, max_step)), ref,
            rtol=RTOL, atol=ATOL)


def test_unicycle_1000_chained_calls_match_numpy():
    rng = np.random.default_rng(12)
    n = 50
    x_ref = np.column_stack([rng.uniform(-500, 500, n), rng.uniform(-500, 500, n),
                             rng.uniform(-np.pi, np.pi, n)])
    x_fast = x_ref.copy()
    for _ in range(1000):
        u = _unicycle_inputs(rng, n)
        x_ref = integrate(kinematic.rhs, x_ref, u, None, 0.01, 0.01)
        x_fast = bicycle_fast.integrate_unicycle(x_fast, u, 0.01, 1)
    assert_close_per_state(x_fast, x_ref, RTOL_CHAIN, ATOL_CHAIN_UNICYCLE)
    with pytest.raises(ValueError):
        bicycle_fast.integrate_unicycle(np.zeros((2, 7)), np.zeros((2, 2)), 0.01, 1)
