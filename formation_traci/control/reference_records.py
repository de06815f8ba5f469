"""The records the compiled road references take (control/reference_road.py,
control/reference_group.py, sumo/fused_step.py): named tuples of arrays, read by field name
in the kernels. k formations of n members in all; a formation's rows ``starts[f]`` ..
``starts[f + 1]`` of the member arrays."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class GroupPlan(NamedTuple):
    """The formations' fixed reference data over a run (sim/formation_group.py
    FormationGroup.plan; one formation: sumo/fused_refs.py OneFormation)."""

    G: np.ndarray  # the reference line (road/line_pack.py)
    profs: np.ndarray  # joined speed profiles (control/virtual_car.py knot_profile_at)
    prof_at: np.ndarray  # (k + 1,) formation f's profile profs[prof_at[f]:prof_at[f + 1]]
    along: np.ndarray  # (n,) slot ahead of the virtual car along the line [m]
    slot_d: np.ndarray  # (n,) road-frame slot across the line [m]
    is_road: np.ndarray  # (n,) road-frame slot (else vehicle frame)
    d_front: np.ndarray  # (n,) CoG to front bumper as the reference takes it [m]
    half_w: np.ndarray  # (n,) half width [m]
    starts: np.ndarray  # (k + 1,) each formation's first member row
    lims: np.ndarray  # (k, 7) GovernorLimits.packed [SI]
    pps: np.ndarray  # (k, n_pp) PlannerParams.packed [SI]
    ramps: np.ndarray  # (k,) the virtual car's acceleration ramps within the step
    frame: np.ndarray  # (n,) slot frame codes (control/reference.py FRAME_ROAD, FRAME_VEHICLE)
    slots: np.ndarray  # the members' slots (control/reference.py constant_slots) [m]
    depart: np.ndarray  # (k,) each formation's departure time [s]


class PlannerState(NamedTuple):
    """The references' state between steps, updated in place (control/longitudinal.py)."""

    a_vc: np.ndarray  # (k,) the virtual car's acceleration [m/s^2]
    emergency_vc: np.ndarray  # (k,) the virtual car on emergency braking
    has_prev: np.ndarray  # (k,) a previous step's v_prev exists
    a_cap_prev: np.ndarray  # (n,) the members' caps of the last step [m/s^2]
    v_prev: np.ndarray  # (n,) the members' speeds at the last step [m/s]
    emergency: np.ndarray  # (n,) member on emergency braking


class ReferenceOut(NamedTuple):
    """What a step of the references writes (one row per member or formation)."""

    vc: np.ndarray  # (n_ctrl, n, 8) each member's virtual car per control period
    a_cap_from: np.ndarray  # (n,) the members' caps at the step's start [m/s^2]
    a_request: np.ndarray  # (k,) the governor's request [m/s^2]
    s_next: np.ndarray  # (k,) the virtual car's arc length at the step's end [m]
    v_next: np.ndarray  # (k,) its speed at the step's end [m/s]
    gap: np.ndarray  # (n,) gap to the leader ahead of each slot [m]
    lead_idx: np.ndarray  # (n,) that leader's neighbour row (-1: none)
    a_cap_req: np.ndarray  # (n,) the caps requested [m/s^2]
    a_cap: np.ndarray  # (n,) the caps in force at the step's end [m/s^2]
    truth: np.ndarray  # (k, 8) each running formation's virtual car at t (NaN: not running)


class StepReference(NamedTuple):
    """A step's reference as the members' kernels take it (control/reference.py Reference;
    sim/fleet.py step_members, member_signals)."""

    G: np.ndarray  # the reference line (road/line_pack.py)
    frame: np.ndarray  # (n,) slot frame codes
    vc: np.ndarray  # (n_ctrl, n, 8) each member's virtual car per control period
    slots: np.ndarray  # the members' slots [m]
    v_cap: np.ndarray  # (n,) speed caps [m/s] (inf: none)
    a_cap: np.ndarray  # (n,) acceleration caps at the step's end [m/s^2]
    a_cap_from: np.ndarray  # (n,) at its start [m/s^2] (control/reference.py cap_at)
    moving: np.ndarray  # (n,) bool: rows stepped (the others keep their state in step_members:
    # the members of a formation not running, which the caller holds)


class RoadPlan(NamedTuple):
    """One formation's fixed road-reference data (control/reference_road.py RoadReference;
    a formation's rows of a :class:`GroupPlan`)."""

    G: np.ndarray  # the reference line (road/line_pack.py)
    prof: np.ndarray  # the speed profile (control/virtual_car.py knot_profile_at)
    along: np.ndarray  # (n,) slot ahead of the virtual car along the line [m]
    slot_d: np.ndarray  # (n,) road-frame slot across the line [m]
    is_road: np.ndarray  # (n,) road-frame slot (else vehicle frame: the member's own offset)
    d_front: np.ndarray  # (n,) CoG to front bumper [m]
    half_w: np.ndarray  # (n,) half width [m]
    lim: np.ndarray  # GovernorLimits.packed [SI]
    pp: np.ndarray  # PlannerParams.packed [SI]
    dt_c: float  # control period [s]
    ramp: bool  # the virtual car's acceleration ramps within the step


class MemberRows(NamedTuple):
    """The members as sensed (sim/world.py Sensed)."""

    s: np.ndarray  # (n,) arc length along the line [m]
    d: np.ndarray  # (n,) offset across it [m]
    v: np.ndarray  # (n,) speed [m/s]
    active: np.ndarray  # (n,) in the run


class NeighbourRows(NamedTuple):
    """The vehicles around the members as the governor takes them (control/governor.py)."""

    rear: np.ndarray  # (m,) rear bumper's arc length [m]
    d: np.ndarray  # (m,) offset [m]
    half_w: np.ndarray  # (m,) half width [m]
    v: np.ndarray  # (m,) speed [m/s]
    in_formation: np.ndarray  # (m,) a released member inside the formation
    mate_rear: np.ndarray  # (m,) the rear of the slot it held [m] (NaN; empty: none inside)


class MemberPlanner(NamedTuple):
    """A formation's members' planner state, updated in place (control/longitudinal.py)."""

    a_cap_prev: np.ndarray  # (n,) the caps of the last step [m/s^2]
    v_prev: np.ndarray  # (n,) the speeds at the last step [m/s]
    emergency: np.ndarray  # (n,) on emergency braking
