"""Linearised model (3.26-3.31), understeer and steady-state yaw gain from first principles."""
import numpy as np
import pytest

from formation_traci.models import bicycle
from formation_traci.models.bicycle import S, U
from formation_traci.models.linear import (critical_speed, full_ab, lateral_ab,
                                           steady_state_yaw_gain, understeer_gradient)
from formation_traci.models.integrator import DYNAMIC, integrate
from formation_traci.models.params import (pack_params, MF_SEED, PASSENGER_CAR, SMALL_TRUCK, axle_loads,
                                           bicycle_params, make_tires)

pytestmark = pytest.mark.jit_off  # also run with NUMBA_DISABLE_JIT=1 (README)

SEED_TIRES = make_tires(PASSENGER_CAR, 1.0, "seed", linear=True)


def jacobian(f, z, h):
    """Central-difference Jacobian of f at z (test-side check of analytic matrices)."""
    cols = []
    for i in range(len(z)):
        dz = np.zeros_like(z)
        dz[i] = h
        cols.append((f(z + dz) - f(z - dz)) / (2 * h))
    return np.stack(cols, axis=1)


def test_eq_3_31_numbers():
    """Eq (3.31) at v = 10 m/s with Tables 3.1 and 3.2, to the seed's two decimals."""
    A, B = lateral_ab(10.0, PASSENGER_CAR, SEED_TIRES)
    np.testing.assert_allclose(A, [[-31.16, -1.61], [-46.35, -36.40]], atol=0.006)
    np.testing.assert_allclose(B[:, 0], [15.58, 168.02], atol=0.006)


def test_eq_3_28_as_printed_is_off_by_v():
    """The seed's (3.28) prints BCD(a^2+b^2)/Izz without 1/v: 10x the (3.31) entry at 10 m/s."""
    bcd = MF_SEED.B * MF_SEED.C * MF_SEED.D
    printed = bcd * (PASSENGER_CAR.a ** 2 + PASSENGER_CAR.b ** 2) / PASSENGER_CAR.Izz
    A, _ = lateral_ab(10.0, PASSENGER_CAR, SEED_TIRES)
    assert printed == pytest.approx(-363.96, abs=0.01)
    assert A[1, 1] == pytest.approx(printed / 10.0, rel=1e-12)


def test_full_model_eq_3_29_structure():
    A, B = full_ab(10.0, PASSENGER_CAR, SEED_TIRES)
    assert np.all(A[0] == 0) and np.all(A[:, 0] == 0)  # v is decoupled (3.26)
    assert B[0, 1] == 1.0 and B[0, 0] == 0.0 and np.all(B[1:, 1] == 0.0)


@pytest.mark.parametrize("v", [5.0, 10.0, 25.0])
@pytest.mark.parametrize("tire_kind", ["seed", "load"])
def test_nonlinear_rhs_linearises_to_lateral_ab(v, tire_kind):
    """Jacobian of the nonlinear rhs (linear tire) at the straight-line equilibrium equals A, B."""
    tires = make_tires(PASSENGER_CAR, 1.0, tire_kind, linear=True)
    p = bicycle_params(PASSENGER_CAR, 1.0, tires)
    x0 = np.zeros(bicycle.N_STATES)
    x0[S.V] = v

    def f(z):  # z = [beta, r, delta] -> [beta dot, r dot]
        x = x0.copy()
        x[S.BETA], x[S.R], x[S.DELTA] = z
        dx = bicycle.rhs(x[None, :], np.zeros((1, 2)), p)[0]
        return np.array([dx[S.BETA], dx[S.R]])

    J = jacobian(f, np.zeros(3), h=1e-7)
    A, B = lateral_ab(v, PASSENGER_CAR, tires)
    np.testing.assert_allclose(J[:, :2], A, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(J[:, 2], B[:, 0], rtol=1e-5, atol=1e-6)


def test_seed_tire_oversteers_with_critical_speed_near_49():
    k = understeer_gradient(PASSENGER_CAR, SEED_TIRES)
    assert k < 0
    vc = critical_speed(PASSENGER_CAR, SEED_TIRES)
    # closed form with identical tires: K_us = m (b - a) / (L |BCD|), v_crit = L sqrt(|BCD| / (m (a - b)))
    bcd = abs(MF_SEED.B * MF_SEED.C * MF_SEED.D)
    L = PASSENGER_CAR.wheelbase
    expected = L * np.sqrt(bcd / (PASSENGER_CAR.m * (PASSENGER_CAR.a - PASSENGER_CAR.b)))
    assert vc == pytest.approx(expected, rel=1e-12)
    assert vc == pytest.approx(48.84, abs=0.05)
    # the linear model loses stability exactly there: det(A) changes sign
    below, _ = lateral_ab(vc * 0.99, PASSENGER_CAR, SEED_TIRES)
    above, _ = lateral_ab(vc * 1.01, PASSENGER_CAR, SEED_TIRES)
    assert np.all(np.linalg.eigvals(below).real < 0)
    assert np.max(np.linalg.eigvals(above).real) > 0


def test_load_tire_is_neutral_steer_and_scales_with_mu():
    """D proportional to axle load gives cornering stiffness proportional to load: K_us = 0."""
    for veh in (PASSENGER_CAR, SMALL_TRUCK):
        tires = make_tires(veh, 1.0, "load")
        assert understeer_gradient(veh, tires) == pytest.approx(0.0, abs=1e-12)
        assert critical_speed(veh, tires) == np.inf or critical_speed(veh, tires) > 1e5
        fz_f, fz_r = axle_loads(veh)
        assert fz_f + fz_r == pytest.approx(veh.m * 9.81)
        ice = make_tires(veh, 0.25, "load")
        assert ice.front.D == pytest.approx(0.25 * tires.front.D)
        assert ice.rear.D == pytest.approx(-0.25 * fz_r)
    # the seed tire ignores the road
    assert make_tires(PASSENGER_CAR, 0.25, "seed").front.D == MF_SEED.D


@pytest.mark.parametrize("tire_kind,v", [("seed", 10.0), ("seed", 25.0), ("load", 10.0), ("load", 25.0)])
def test_steady_state_yaw_gain_matches_single_track_closed_form(tire_kind, v):
    """Nonlinear model with linear tire, constant v and small constant delta: psi dot / delta
    settles at v / (L + K_us v^2) (the textbook single-track steady-state yaw gain)."""
    tires = make_tires(PASSENGER_CAR, 1.0, tire_kind, linear=True)
    p = bicycle_params(PASSENGER_CAR, 1.0, tires)
    delta = np.deg2rad(0.5)
    x = np.zeros((1, bicycle.N_STATES))
    x[0, S.V], x[0, S.DELTA] = v, delta
    u = np.zeros((1, 2))  # a_ref = 0 keeps v constant through (3.13)
    x = integrate(DYNAMIC, x, u, pack_params(p, 1), 15.0, 0.005)  # 3000 RK4 steps of 5 ms
    gain = x[0, S.R] / delta
    expected = steady_state_yaw_gain(v, PASSENGER_CAR, tires)
    assert x[0, S.V] == pytest.approx(v, rel=1e-9)
    # 0.2 %: small-angle terms (sin delta, atan of slip) left out of the closed form
    assert gain == pytest.approx(expected, rel=2e-3)
