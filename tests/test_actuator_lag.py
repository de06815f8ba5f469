"""Actuator dynamics of the dynamic bicycle model (issue 28, docs/model.md "Actuator
dynamics"): first-order lags on the drive/brake demand and on the steering, as the named
state slots A_D and DELTA_C; 0 (the default) is the seed's model bit for bit."""
import math
from dataclasses import replace

import numpy as np
import pytest

from formation_traci.models import bicycle
from formation_traci.models.bicycle import S
from formation_traci.models.integrator import DYNAMIC, integrate
from formation_traci.models.params import PASSENGER_CAR, bicycle_params, make_tires, pack_params
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.sim.setup import build_fleet

pytestmark = pytest.mark.jit_off


def packed(drive=0.0, steer=0.0, n=1):
    veh = replace(PASSENGER_CAR, drive_lag_s=drive, steer_lag_s=steer)
    return pack_params(bicycle_params(veh, 1.0, make_tires(veh, 1.0, "seed")), n)


def cruise(v=20.0):
    x = np.zeros((1, bicycle.N_STATES))
    x[0, S.V] = v
    return x


def test_drive_lag_is_a_first_order_response():
    """Straight ahead (no cornering force) the traction law delivers v dot = a_d exactly, so
    under a step a_r = 1 m/s^2 from rest of the actuator: a_d = 1 - exp(-t / tau) and
    v(t) = v0 + t - tau (1 - exp(-t / tau)) (RK4 at 10 ms: error far below 1e-6)."""
    tau, t = 0.5, 2.0
    x = integrate(DYNAMIC, cruise(), np.array([[1.0, 0.0]]), packed(drive=tau), t, 0.01)
    e = math.exp(-t / tau)
    assert x[0, S.A_D] == pytest.approx(1.0 - e, abs=1e-7)
    assert x[0, S.V] == pytest.approx(20.0 + t - tau * (1.0 - e), abs=1e-6)
    assert x[0, S.Y] == 0.0 and x[0, S.PSI] == 0.0


def test_steer_lag_is_a_first_order_response():
    """A held steering rate of 0.1 rad/s (inside the 30 deg/s limit) ramps the command,
    delta_c = 0.1 t, and the wheel follows delta = 0.1 (t - tau (1 - exp(-t / tau)))."""
    tau, t = 0.2, 1.0
    x = integrate(DYNAMIC, cruise(10.0), np.array([[0.0, 0.1]]), packed(steer=tau), t, 0.01)
    assert x[0, S.DELTA_C] == pytest.approx(0.1 * t, abs=1e-12)
    assert x[0, S.DELTA] == pytest.approx(0.1 * (t - tau * (1 - math.exp(-t / tau))), abs=1e-7)


def test_no_lag_is_the_model_without_actuator_slots_bit_for_bit():
    """Lags 0: the first seven slots evolve exactly as a row of the seven core slots alone
    (the seed's model), the actuator slots stay where they are."""
    u = np.array([[0.7, 0.05]])
    full = integrate(DYNAMIC, cruise(), u, packed(), 3.0, 0.01)
    core = integrate(DYNAMIC, cruise()[:, :bicycle.N_CORE], u, packed(), 3.0, 0.01)
    assert np.array_equal(full[:, :bicycle.N_CORE], core)
    assert full[0, S.A_D] == 0.0 and full[0, S.DELTA_C] == 0.0


def test_lags_from_the_scenario_and_per_member(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('[run]\nduration = 1.0\n[vehicle]\nmodel = "dynamic"\n[vehicle.params]\n'
                 'drive_lag_s = 0.5\n[leader]\nspeed = 20.0\n'
                 '[[members]]\nid = "a"\noffset = [0.0, 0.0]\nposition = [0.0, 0.0]\n'
                 '[[members]]\nid = "b"\noffset = [-20.0, 0.0]\nposition = [-20.0, 0.0]\n'
                 'params = { drive_lag_s = 0.0, steer_lag_s = 0.1 }\n')
    cfg = build_fleet(load_scenario(p))
    assert list(cfg.params.drive_lag_s) == [0.5, 0.0]
    assert list(cfg.params.steer_lag_s) == [0.0, 0.1]
    p.write_text(p.read_text().replace("drive_lag_s = 0.5", "drive_lag_s = -1"))
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    assert "vehicle.params.drive_lag_s" in str(ei.value)
