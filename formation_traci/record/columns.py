"""Names, dtypes and units of the recorded tables.

This module is the single contract between the recorder (``formation_traci``) and the
analysis package (``analysis``): both import these names; nothing else spells them.
Angles are radians counter-clockwise from +x, positions are the centre of gravity [m].
"""
from __future__ import annotations

from dataclasses import dataclass

VIRTUAL_CAR_ID = "vc"
"""``vehicle_id`` of the virtual car (virtual leader, eq 2.3) in the trajectory table."""


@dataclass(frozen=True, slots=True)
class Column:
    name: str
    dtype: str  # numpy dtype name
    unit: str
    doc: str


TRAJECTORY_COLUMNS: tuple[Column, ...] = (
    Column("t", "float64", "s", "simulated time"),
    Column("vehicle_id", "string", "-", "member id, or 'vc' for the virtual car"),
    Column("x", "float64", "m", "centre-of-gravity x (eq 3.24)"),
    Column("y", "float64", "m", "centre-of-gravity y (eq 3.25)"),
    Column("heading", "float64", "rad", "yaw angle psi, counter-clockwise from +x"),
    Column("v", "float64", "m/s", "speed of the centre of gravity"),
    Column("yaw_rate", "float64", "rad/s", "psi dot"),
    Column("a_lon", "float64", "m/s^2", "acceleration along the body x axis"),
    Column("a_lat", "float64", "m/s^2", "acceleration along the body y axis (left positive)"),
    Column("ex", "float64", "m", "x_des - x, eq 2.5"),
    Column("ey", "float64", "m", "y_des - y, eq 2.5"),
    Column("e_lon", "float64", "m", "error (ex, ey) resolved along the virtual car heading"),
    Column("e_lat", "float64", "m", "error (ex, ey) resolved across the virtual car heading (left positive)"),
    Column("x_des", "float64", "m", "desired x, eq 2.4"),
    Column("y_des", "float64", "m", "desired y, eq 2.4"),
    Column("v_ref", "float64", "m/s", "linear velocity reference, eq 2.6"),
    Column("omega_ref", "float64", "rad/s", "angular velocity reference, eq 2.8"),
    Column("steer", "float64", "rad", "front wheel steering angle delta, eq 3.38"),
    Column("steer_rate", "float64", "rad/s", "steering rate delta dot, eq 3.37 (after limits)"),
    Column("beta", "float64", "rad", "vehicle side-slip angle, eq 3.2"),
    Column("slip_front", "float64", "rad", "front tire slip angle alpha_f, eq 3.7"),
    Column("slip_rear", "float64", "rad", "rear tire slip angle alpha_r, eq 3.8"),
    Column("traction_force", "float64", "N", "applied longitudinal force F_lf, eq 3.13 after clipping"),
    Column("traction_force_max", "float64", "N", "adhesion limit of the driven axle, eq 3.14"),
    Column("friction_usage", "float64", "-", "sqrt(a_lon^2 + a_lat^2) / (mu g); above 1 violates eq 3.16"),
)
"""Columns of ``trajectories.parquet``: one row per vehicle per recorded step.

Signals a vehicle model does not have (the kinematic unicycle has no tires, the virtual
car has no controller) are NaN.
"""

TRAJECTORY_FLOAT_COLUMNS: tuple[str, ...] = tuple(
    c.name for c in TRAJECTORY_COLUMNS if c.dtype == "float64"
)
