"""Names, dtypes and units of the recorded tables.

This module is the single contract between the recorder (``formation_traci``) and the
analysis package (``analysis``): both import these names; nothing else spells them.
Angles are radians counter-clockwise from +x, positions are the centre of gravity [m].
"""
from __future__ import annotations

from dataclasses import dataclass

VIRTUAL_CAR_ID = "vc"
"""``vehicle_id`` of the virtual car (virtual leader, eq 2.3) in the trajectory table."""

DEFAULT_FORMATION_ID = "f0"
"""``formation_id`` of a scenario's one formation given by its top-level leader and members."""


INCIDENT_VERDICT: tuple[str, ...] = ("member_collisions", "member_removed", "emergency_brakes",
                                     "stranded", "sumo_emergency_brakes", "lane_departures")
"""run.json ``incidents`` that make a run that reached its end ``completed_with_incidents``
(formation_traci/sim/incidents.py defines each)."""
INCIDENT_KEYS: tuple[str, ...] = INCIDENT_VERDICT + ("sumo_collision_artefacts",)
"""run.json ``incidents``: a count of each (fixed names)."""


@dataclass(frozen=True, slots=True)
class Column:
    name: str
    dtype: str  # numpy dtype name
    unit: str
    doc: str
    derived_from: str = ""  # a string column whose value follows from this one (written by the writer)


TRAJECTORY_COLUMNS: tuple[Column, ...] = (
    Column("t", "float64", "s", "simulated time"),
    Column("vehicle_id", "string", "-", "member id, or 'vc' for the virtual car"),
    Column("formation_id", "string", "-", "the formation the member or virtual car belongs to",
           derived_from="vehicle_id"),
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
    Column("power", "float64", "W", "traction power at the front wheels: F_lf times the wheel's speed along itself (docs/energy.md)"),
    Column("drag_force", "float64", "N", "aerodynamic drag 0.5 rho c_d k A v^2 acting on the member (NaN with resistances off)"),
    Column("drag_ratio", "float64", "-", "k: c_d multiplier from the vehicles around, 1 alone (NaN with resistances off)"),
    Column("s", "float64", "m", "arc length of the CoG along the road's reference line (road runs)"),
    Column("d", "float64", "m", "lateral offset of the CoG from the reference line, left positive (road runs)"),
    Column("lane_index", "float64", "-", "SUMO lane index the member is on, 0 = rightmost (SUMO runs)"),
    Column("sumo_gap", "float64", "m", "distance between our CoG and the CoG SUMO reports (SUMO runs)"),
    Column("slot", "float64", "-", "index of the formation slot the member holds (road runs; changes with reshapes)"),
    Column("leader_age_s", "float64", "s", "age of the newest virtual-car state the member holds (0: perfect communication)"),
)
"""Columns of ``trajectories.parquet``: one row per vehicle per recorded step.

Signals a vehicle model does not have (the kinematic unicycle has no tires, the virtual
car has no controller) are NaN.
"""

COMFORT_COLUMNS: tuple[Column, ...] = tuple(
    c for c in TRAJECTORY_COLUMNS if c.name in ("t", "vehicle_id", "formation_id", "v", "a_lon", "a_lat"))
"""Columns of ``comfort.parquet``: the members' accelerations at the control rate (every
``run.control_step``, 100 Hz by default), for ISO 2631 weighting and jerk; the rows at the
recorded steps equal those of ``trajectories.parquet``."""

TRAJECTORY_FLOAT_COLUMNS: tuple[str, ...] = tuple(
    c.name for c in TRAJECTORY_COLUMNS if c.dtype == "float64"
)


EVENT_COLUMNS: tuple[Column, ...] = (
    Column("t", "float64", "s", "simulated time (formation clock)"),
    Column("kind", "string", "-", "collision | teleport | member_removed | move_refused | lane_change | "
                                  "cut_in | cleared_at_insertion | member_retired | emergency_brake | emergency_end | end_of_road | placement_mismatch | model_range | "
                                  "maneuver_start | maneuver_end | maneuver_postponed | maneuver_cancelled | "
                                  "comm_timeout | comm_restored | law_fallback | law_recovered | "
                                  "merge_yield_start | merge_yield_end"),
    Column("vehicle_id", "string", "-", "the vehicle the event is about"),
    Column("formation_id", "string", "-", "the formation of vehicle_id (a member or a virtual car), "
                                          "else empty", derived_from="vehicle_id"),
    Column("other_id", "string", "-", "the other vehicle involved, or empty"),
    Column("detail", "string", "-", "free text; maneuver events: the maneuver's name first ('reshape: ...')"),
)
"""Columns of ``events.parquet``: one row per event."""

BACKGROUND_COLUMNS: tuple[Column, ...] = (
    Column("t", "float64", "s", "simulated time (formation clock)"),
    Column("vehicle_id", "string", "-", "SUMO vehicle id"),
    Column("type", "string", "-", "SUMO vType id"),
    Column("x", "float64", "m", "centre of the body"),
    Column("y", "float64", "m", "centre of the body"),
    Column("heading", "float64", "rad", "counter-clockwise from +x"),
    Column("v", "float64", "m/s", "speed"),
    Column("a", "float64", "m/s^2", "longitudinal acceleration"),
    Column("length", "float64", "m", "body length"),
    Column("width", "float64", "m", "body width"),
    Column("lane", "string", "-", "SUMO lane id"),
    Column("lane_index", "int32", "-", "SUMO lane index, 0 = rightmost"),
    Column("s", "float64", "m", "arc length of the centre along the reference line"),
    Column("d", "float64", "m", "lateral offset of the centre from the reference line, left positive"),
)
"""Columns of ``background.parquet``: SUMO's vehicles near the formation, one row per vehicle per step."""

FCD_COLUMNS: tuple[Column, ...] = (
    Column("t", "float64", "s", "formation time of the state (the trajectories' t); sumo frame: SUMO's time label"),
    Column("vehicle_id", "string", "-", "SUMO vehicle id (members: the member id)"),
    Column("type", "string", "-", "SUMO vType id"),
    Column("x", "float64", "m", "centre of gravity (members) / body centre; sumo frame: front bumper"),
    Column("y", "float64", "m", "centre of gravity (members) / body centre; sumo frame: front bumper"),
    Column("heading", "float64", "rad", "counter-clockwise from +x; sumo frame: degrees clockwise from north"),
    Column("v", "float64", "m/s", "speed; members in the formation frame: their true speed (the model's)"),
    Column("lane", "string", "-", "SUMO lane id"),
    Column("edge", "string", "-", "SUMO edge id (from the lane where SUMO leaves it empty)"),
    Column("lane_pos", "float64", "m", "SUMO's position of the front bumper along the lane"),
    Column("slope", "float64", "deg", "road slope"),
)
"""Columns of ``sumo/fcd.parquet`` (formation_traci/sumo/fcd.py), one naming in both
``sumo.fcd_frame`` s; the formation frame's units (the sumo frame's differ: :data:`FCD_SUMO_UNITS`)."""

FCD_SUMO_UNITS = {"t": "s (SUMO time)", "x": "m (front bumper)", "y": "m (front bumper)",
                  "heading": "deg (clockwise from north)"}
"""Units of ``sumo/fcd.parquet`` columns in SUMO's frame where they differ."""

SSM_COLUMNS: tuple[Column, ...] = (
    Column("begin", "float64", "s", "encounter start (formation clock)"),
    Column("end", "float64", "s", "encounter end (formation clock)"),
    Column("ego", "string", "-", "vehicle carrying the SSM device"),
    Column("foe", "string", "-", "other vehicle"),
    Column("member_involved", "bool", "-", "ego or foe is a formation member"),
    Column("min_ttc", "float64", "s", "minimum time to collision (NaN if undefined)"),
    Column("min_ttc_time", "float64", "s", "when min_ttc occurred"),
    Column("max_drac", "float64", "m/s^2", "maximum deceleration rate to avoid a crash"),
    Column("max_drac_time", "float64", "s", "when max_drac occurred"),
    Column("pet", "float64", "s", "post-encroachment time (crossing/merging conflicts)"),
    Column("min_ttc_type", "float64", "-", "SUMO's encounter type at min_ttc (2/3 following as "
                                           "follower/leader, 111 collision: gap <= 0, ...)"),
    Column("min_ttc_s", "float64", "m", "where SUMO put min_ttc: arc length along the reference line"),
    Column("min_ttc_d", "float64", "m", "where SUMO put min_ttc: lateral offset, left positive"),
)
"""Columns of ``ssm.parquet``: SUMO's SSM device conflicts, converted from its XML output."""
