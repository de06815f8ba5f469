"""The records of the compiled step of a road run (sumo/fused_step.py): named tuples of
arrays, built by sumo/fused_path.py (once per run for :class:`RoadRun` and :class:`StepOut`,
per step for :class:`SensedRows` and :class:`StepAt`), read by field name in the kernels,
and :class:`FusedRun`, the run's records in one. n members, m neighbours, k formations."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import types
from numba.experimental import structref

from ..core.kernels import kernel


class RoadRun(NamedTuple):
    """The run's fixed sensing and placing data."""

    G: np.ndarray  # the reference line (road/line_pack.py)
    tolerance: float  # distance to where SUMO has a member beyond which it is misplaced [m]
    d_front: np.ndarray  # (n,) CoG to front bumper of the members' SUMO types [m]
    step: float  # SUMO step [s]
    bodies: np.ndarray  # (4, n) CoG to front bumper as the reference takes it, length, width
    # and CoG to front bumper as SUMO has them [m]
    peers: bool  # several formations: each sees the others' members as traffic
    slot_index: np.ndarray  # (n,) the members' slot indices (the trajectory's slot column)
    cols: np.ndarray  # (N_SIGNALS,) signal column of each kernel signal (sim/fleet.py)
    drag_bodies: np.ndarray  # (3, n) the members' chassis length, width, CoG to front bumper
    # [m] for their drag ratios (sim/road_load.py RoadLoad)
    drag_law: np.ndarray  # (5,) the drag interaction's law (models/drag_interaction.py
    # law_row); (0,): no drag ratios computed (no resistances, or without the interaction)
    grade_s: np.ndarray  # (p,) the reference lane's elevation profile: arc length [m] ...
    grade_z: np.ndarray  # (p,) ... and elevation [m] (sim/road_load.py elevation_profile);
    # (0,): no grade computed (no resistances, or a network without elevation)


class StepOut(NamedTuple):
    """The compiled step's outputs beyond its return values (the same arrays every step)."""

    sig: np.ndarray  # (n, signal columns) the members' signals
    periods: np.ndarray  # (n_ctrl, n, 3) speed [m/s], a_lon, a_lat [m/s^2] per control period
    v_m: np.ndarray  # (n,) the members' speeds as sensed [m/s]
    m_gap: np.ndarray  # (n,) their distance to where SUMO has them [m]
    place: np.ndarray  # (6, n) SUMO's front bumper x, y [m], angle [deg], the speed [m/s] and
    # mean acceleration [m/s^2] over the step of the new state, the speed SUMO is told [m/s]
    pos: np.ndarray  # (n, 2) the new state's CoG position [m]
    vel: np.ndarray  # (n, 2) its velocity [m/s]
    heading: np.ndarray  # (n,) its heading [rad]
    lead_obs: np.ndarray  # (n,) each member's leader among SUMO's vehicles (-1: none)


class SensedRows(NamedTuple):
    """What SUMO reports of the step (sumo/adapter/member_reads.py, sumo/adapter/neighbours.py)."""

    members: np.ndarray  # (n, 5) front bumper x, y [m], angle [deg], lateral position [m],
    # lane position [m]; NaN rows for the members out of the run
    li: np.ndarray  # (n,) the members' packed lane rows (-1: out of the run)
    lane_index: np.ndarray  # (n,) their lane indices [-]
    s_guess: np.ndarray  # (n,) their arc lengths at the last sense [m]
    lane_table: np.ndarray  # the packed lanes (sumo/sense.py)
    lane_points: np.ndarray  # the packed lanes' points [m]
    nb: np.ndarray  # (m, 7) front bumper x, y [m], angle [deg], speed [m/s], acceleration
    # [m/s^2], length, width [m] of the neighbours
    nb_guess: np.ndarray  # (m,) their arc lengths at the last sense [m] (NaN: none)
    bg_codes: np.ndarray  # (3, m) their ids', types' and lanes' string codes
    nb_lane_index: np.ndarray  # (m,) their lane indices [-]
    active: np.ndarray  # (n,) the members in the run


class StepAt(NamedTuple):
    """The step's time, the formations' status and where its rows go."""

    t: float  # [s]
    s: np.ndarray  # (k,) the virtual cars' arc lengths [m]
    v: np.ndarray  # (k,) their speeds [m/s]
    at: int  # the step's first row of the trajectory table's buffer
    c_at: int  # of the comfort table's
    bg_at: int  # of the background table's
    running: np.ndarray  # (k,) the formations running (the others' virtual cars stand)
    parked: np.ndarray  # (n,) the rows of the formations not running (held)
    a_limit: np.ndarray  # (k,) the formations' caps on their requested acceleration [m/s^2] (inf: none)


@structref.register
class FusedRunType(types.StructRef):
    """numba's type of a :class:`FusedRun`."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class FusedRun(structref.StructRefProxy):
    """The records the compiled step takes that stay the same over a run, in one object the
    compiled code holds by reference (passed to a compiled call as one pointer: a named
    tuple is unpacked field by field at every call). Fields: ``fleet``
    (sim/fleet_records.py FleetParams), ``road`` (:class:`RoadRun`), ``plan``, ``planner``,
    ``ref`` (control/reference_records.py GroupPlan, PlannerState, ReferenceOut), ``tables``
    (sim/table_records.py TableBuffers), ``inc`` (sim/incidents.py IncidentArrays), ``out``
    (:class:`StepOut`). Made by :func:`fused_run`."""


structref.define_proxy(FusedRun, FusedRunType,
                       ["fleet", "road", "plan", "planner", "ref", "tables", "inc", "out"])


@kernel
def fused_run(fleet, road, plan, planner, ref, tables, inc, out):
    """The :class:`FusedRun` of these records (compiled and cached: no compilation at a run's
    start)."""
    return FusedRun(fleet, road, plan, planner, ref, tables, inc, out)
