"""Limits of seed section 3.3.1: masks and episode counting."""
from __future__ import annotations

import math

import numpy as np
import pytest

from analysis.metrics import limits


def test_episodes_and_time_of_a_constructed_mask():
    dt = 0.1
    m = np.zeros(100, dtype=bool)
    m[10:20] = True   # 1.0 s
    m[30:31] = True   # 0.1 s
    m[95:] = True     # 0.5 s, runs to the end
    r = limits.exceedance(m, dt)
    assert r.episodes == 3
    assert r.time_s == pytest.approx(1.6)


def test_slip_limit_is_4_degrees_on_either_axle():
    lim = math.radians(4.0)
    assert limits.SLIP_ANGLE_LIMIT == pytest.approx(lim)
    front = np.array([0.0, lim * 0.999, -lim * 1.001, 0.0, np.nan])
    rear = np.array([0.0, 0.0, 0.0, lim * 1.001, 0.0])
    np.testing.assert_array_equal(limits.slip_mask(front, rear), [0, 0, 1, 1, 0])
    # episodes: the two neighbouring violations (front then rear) form one episode
    assert limits.exceedance(limits.slip_mask(front, rear), 0.01).episodes == 1


def test_traction_friction_and_lateral_masks():
    np.testing.assert_array_equal(
        limits.traction_mask([100.0, 2000.0, 2000.0, np.nan], [1000.0, 2000.0, 1999.0, 1.0]),
        [0, 0, 1, 0])
    np.testing.assert_array_equal(limits.friction_mask([0.5, 1.0, 1.01]), [0, 0, 1])
    np.testing.assert_array_equal(limits.lat_acc_mask([3.6, -3.61, 3.59]), [0, 1, 0])


def test_friction_usage_is_eq_3_16():
    u = limits.friction_usage([3.0 * 9.81 / 5], [4.0 * 9.81 / 5], mu=1.0)
    assert u[0] == pytest.approx(1.0)
    assert limits.friction_usage([0.0], [4.905], mu=0.5)[0] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="mu"):
        limits.friction_usage([0.0], [0.0], mu=0.0)


def test_sinusoidal_lateral_acceleration_episodes():
    dt = 0.01
    t = np.arange(0.0, 10.0, dt)
    a = 4.0 * np.sin(2 * np.pi * 0.5 * t)  # 10 half-waves above 3.6 in |a|
    r = limits.exceedance(limits.lat_acc_mask(a), dt)
    assert r.episodes == 10
    frac = 1 - 2 / np.pi * np.arcsin(3.6 / 4.0)
    assert r.time_s == pytest.approx(10.0 * frac, abs=10 * dt)
