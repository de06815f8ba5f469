"""Per-member parameter arrays: a formation mixing a car and a truck, each with its own gain
schedules, steps every member exactly as a fleet of that member alone would (the kernels
index every parameter by member)."""
from __future__ import annotations

import numpy as np
import pytest

from formation_traci.control.reference import FRAME_VEHICLE, Reference, constant_slots
from formation_traci.control.reference_free import free_vc_rows
from formation_traci.control.schedule import (SPEED_GAINS_CAR, SPEED_GAINS_TRUCK, YAW_GAINS,
                                              YAW_GAINS_RETUNED)
from formation_traci.control.virtual_car import Profile, pack_profiles
from formation_traci.models.params import (PASSENGER_CAR, SMALL_TRUCK, bicycle_params,
                                           make_tires, stack)
from formation_traci.sim.fleet import Fleet, FleetConfig, FleetState

pytestmark = pytest.mark.jit_off


def _ref(n_members, offsets, t, pose):
    prof = pack_profiles(Profile((0.0, 5.0), (20.0, 24.0), "smooth"), Profile.constant(0.05))
    vc = np.empty((5, n_members, 8))
    free_vc_rows(prof, t, *pose, 0.01, 1, vc)
    inf = np.full(n_members, np.inf)
    return Reference(t, 0.01, vc, constant_slots(offsets, 5),
                     np.full(n_members, FRAME_VEHICLE), np.ones(n_members, bool), inf, inf,
                     truth=vc[0, 0])


def test_car_and_truck_in_one_fleet_equal_each_alone():
    car = bicycle_params(PASSENGER_CAR, 1.0, make_tires(PASSENGER_CAR, 1.0, "load"))
    truck = bicycle_params(SMALL_TRUCK, 0.6, make_tires(SMALL_TRUCK, 0.6, "load"))
    offsets = np.array([[-8.0, 3.5], [-16.0, -3.5]])
    x0 = np.array([[-10.0, 4.5, 0.05, 19.0, 0.0, 0.0, 0.0],
                   [-15.0, -2.0, -0.1, 21.0, 0.01, 0.02, 0.01]])
    ts0 = np.array([0.1, -0.05])
    mixed = Fleet(FleetConfig(("car", "truck"), "dynamic", stack([car, truck]),
                              np.array([1.0, 0.6]), np.array([3.0, 2.0]),
                              (SPEED_GAINS_CAR, SPEED_GAINS_TRUCK),
                              (YAW_GAINS_RETUNED, YAW_GAINS), 0.01))
    st = FleetState(x0.copy(), ts0.copy(), x0[:, 3].copy())
    alone = []
    for i, (p, k, kt, sg, yg) in enumerate([(car, 1.0, 3.0, SPEED_GAINS_CAR, YAW_GAINS_RETUNED),
                                            (truck, 0.6, 2.0, SPEED_GAINS_TRUCK, YAW_GAINS)]):
        f = Fleet(FleetConfig((f"m{i}",), "dynamic", p, np.array([k]), np.array([kt]), sg, yg, 0.01))
        alone.append((f, FleetState(x0[i:i + 1].copy(), ts0[i:i + 1].copy(), x0[i:i + 1, 3].copy())))
    pose = (0.0, 0.0, 0.0)
    for step in range(40):  # 2 s
        t = step * 0.05
        st = mixed.step(st, _ref(2, offsets, t, pose))
        for i, (f, s) in enumerate(alone):
            alone[i] = (f, f.step(s, _ref(1, offsets[i:i + 1], t, pose)))
        vc = np.empty((5, 1, 8))
        prof = pack_profiles(Profile((0.0, 5.0), (20.0, 24.0), "smooth"), Profile.constant(0.05))
        pose = free_vc_rows(prof, t, *pose, 0.01, 1, vc)
    for i, (f, s) in enumerate(alone):
        np.testing.assert_array_equal(st.x[i], s.x[0])
        np.testing.assert_array_equal(st.theta_star[i], s.theta_star[0])
    # and the two members really differ in their parameters (the truck is heavier and slower
    # to respond): swapping the truck's gains for the car's changes its trajectory
    swapped = Fleet(FleetConfig(("car", "truck"), "dynamic", stack([car, truck]),
                                np.array([1.0, 0.6]), np.array([3.0, 2.0]), SPEED_GAINS_CAR,
                                YAW_GAINS_RETUNED, 0.01))
    st2 = swapped.step(FleetState(x0.copy(), ts0.copy(), x0[:, 3].copy()),
                       _ref(2, offsets, 0.0, (0.0, 0.0, 0.0)))
    st1 = mixed.step(FleetState(x0.copy(), ts0.copy(), x0[:, 3].copy()),
                     _ref(2, offsets, 0.0, (0.0, 0.0, 0.0)))
    np.testing.assert_array_equal(st2.x[0], st1.x[0])
    assert not np.array_equal(st2.x[1], st1.x[1])
