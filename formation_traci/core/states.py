"""Small value types shared by the controllers (control/) and the road (road/): the virtual
car's state at one instant and the members' desired points. They live below both packages so
that neither imports the other for them."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class LeaderState:
    """Virtual car kinematics at one instant (eq 2.3) and the rates the controller needs."""

    x: float  # [m]
    y: float  # [m]
    theta: float  # heading [rad], counter-clockwise from +x
    v: float  # [m/s]
    omega: float  # [rad/s]
    v_dot: float  # [m/s^2]
    omega_dot: float  # [rad/s^2]


@dataclass(frozen=True, slots=True)
class Targets:
    """Desired position, velocity and acceleration of every member, shape (n, 2) each."""

    p: np.ndarray  # [m]
    v: np.ndarray  # [m/s]
    a: np.ndarray  # [m/s^2]
