"""Lateral closed-loop stability (linearised, then simulated): the seed's gains on ice.

First principles: eigenvalues of the linearised member loop (models/linear.closed_loop_lateral).
Finding recorded in docs/model.md: with Table 3.8 and k_theta = 3 the loop is stable on a dry
road with either tire, but with the load-consistent tire on ice (mu = 0.25) it is unstable from
11.5 m/s; k_theta = 1 restores it up to about 36 m/s.
"""
import numpy as np
import pandas as pd
import pytest

from formation_traci.control.schedule import YAW_GAINS_RETUNED
from formation_traci.models.linear import closed_loop_lateral
from formation_traci.models.params import PASSENGER_CAR, make_tires
from formation_traci.scenario import parse_scenario
from formation_traci.runner import run_scenario

K = YAW_GAINS_RETUNED.g_max


def max_re(v, mu, k_theta, kind="load"):
    return np.linalg.eigvals(closed_loop_lateral(v, PASSENGER_CAR, make_tires(PASSENGER_CAR, mu, kind),
                                                 K, k_theta)).real.max()


@pytest.mark.parametrize("kind", ["seed", "load"])
@pytest.mark.parametrize("v", [10.0, 20.0, 30.0])
def test_seed_gains_are_stable_on_a_dry_road(kind, v):
    assert max_re(v, 1.0, 3.0, kind) < -0.5


def test_seed_gains_are_unstable_on_ice_and_k_theta_1_fixes_it():
    speeds = np.arange(8.0, 30.5, 0.5)
    re3 = np.array([max_re(v, 0.25, 3.0) for v in speeds])
    from scipy.optimize import brentq
    onset = brentq(lambda v: max_re(v, 0.25, 3.0), 8.0, 20.0)
    assert onset == pytest.approx(11.51, abs=0.02)  # unstable above 11.5 m/s
    assert re3[speeds == 20.0][0] == pytest.approx(0.54, abs=0.02)
    assert all(max_re(v, 0.25, 1.0) < 0 for v in speeds)


def _ice_run(tmp_path, k_theta):
    doc = {"run": {"duration": 30.0}, "vehicle": {"surface": "ice"},
           "controller": {"k": 1.0, "k_theta": k_theta},
           "leader": {"speed": 20.0},
           "members": [{"id": "a", "offset": [0.0, 0.0], "position": [0.0, 0.3]}]}
    res = run_scenario(parse_scenario(doc), tmp_path / f"kth{k_theta}", progress=False)
    assert res.status == "completed"
    df = pd.read_parquet(tmp_path / f"kth{k_theta}" / "trajectories.parquet")
    return df[df.vehicle_id == "a"]


def test_simulation_agrees_with_the_eigenvalues(tmp_path):
    """20 m/s on ice, 0.3 m initial lateral error: the oscillation grows with k_theta = 3
    (until the tires saturate) and dies out with k_theta = 1."""
    bad, good = _ice_run(tmp_path, 3.0), _ice_run(tmp_path, 1.0)
    early = lambda g: g[(g.t > 1) & (g.t < 5)].e_lat.abs().max()
    late = lambda g: g[(g.t > 20)].e_lat.abs().max()
    assert late(bad) > 5 * early(bad)
    assert late(good) < 0.01 * early(good) + 1e-3


def test_blend_speed_keeps_the_explicit_step_stable():
    """Below the blend speed the kinematic bicycle acts alone: the dynamic model must only act
    where h |lambda| <= 2 (RK4's real-axis limit is 2.785). The truck's load-consistent tires
    make its yaw mode ~6x stiffer than the car's at the same speed."""
    from formation_traci.models.linear import lateral_ab, stable_blend_speed
    from formation_traci.models.params import SMALL_TRUCK
    h = 0.01
    for veh, expected in ((PASSENGER_CAR, 1.0), (SMALL_TRUCK, 4.6)):
        tires = make_tires(veh, 1.0, "load")
        v = stable_blend_speed(veh, tires, h)
        assert v == pytest.approx(expected, abs=0.05)
        lam = np.abs(np.linalg.eigvals(lateral_ab(max(v, 1.0), veh, tires)[0])).max()
        assert h * lam <= 2.0 + 1e-9


def test_truck_stops_and_starts_without_chatter(tmp_path):
    """The small truck driven to a standstill and off again at the default 10 ms step: its yaw
    rate does not chatter (it reversed sign hundreds of times when the dynamic model acted
    down to 1 m/s, where h |lambda| = 9)."""
    # the car's speed schedule: with Table 3.6 the truck cannot brake for this stop at all
    # (test_truck_speed_schedule_brakes_at_most_half_a_metre_per_second_squared)
    doc = {"run": {"duration": 40.0}, "vehicle": {"preset": "small_truck"},
           "controller": {"speed_gains": "table_3_4"},
           "leader": {"speed": {"t": [0, 5, 15, 25, 35], "values": [15, 15, 0, 0, 8], "interp": "smooth"},
                      "yaw_rate_deg_s": {"t": [0, 30, 32], "values": [0, 0, 2], "interp": "smooth"}},
           "members": [{"id": "t", "offset": [0.0, 0.0], "position": [0.0, 0.2]}]}
    res = run_scenario(parse_scenario(doc), tmp_path / "truck", progress=False)
    assert res.status == "completed"
    df = pd.read_parquet(tmp_path / "truck" / "trajectories.parquet")
    g = df[df.vehicle_id == "t"]
    r = g.yaw_rate.to_numpy()
    reversals = np.sum(np.sign(r[1:]) * np.sign(r[:-1]) < 0)
    assert reversals < 20
    assert np.abs(r).max() < 0.1  # rad/s
    assert np.isfinite(g[["x", "y", "v"]].to_numpy()).all()


def test_truck_speed_schedule_brakes_at_most_half_a_metre_per_second_squared():
    """Table 3.6 (G_min 0.05, G_max 1.3, K_min 1): the speed loop's output K(e) e stays below
    0.52 m/s^2 for every speed error up to 10 m/s (peak 0.513 at 1.12 m/s, then G_min e): a
    truck with it cannot follow a virtual car that slows at 1.5 m/s^2 (docs/model.md)."""
    from formation_traci.control.schedule import SPEED_GAINS_TRUCK, gain
    e = np.linspace(0.0, 10.0, 100001)
    a = gain(e, SPEED_GAINS_TRUCK) * e
    assert a.max() == pytest.approx(0.513, abs=0.002)
    assert e[np.argmax(a)] == pytest.approx(1.12, abs=0.01)
