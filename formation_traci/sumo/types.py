"""What the SUMO adapter (sumo/adapter/__init__.py, the only module that imports libsumo/traci)
shares with the rest of the package, without importing SUMO: its constants, the frame
conversions and the small dataclasses of its results.

SUMO's vehicle position is the front bumper and its angle is degrees clockwise from north;
ours is the centre of gravity (CoG) and radians counter-clockwise from +x. The conversions
are here, once: :func:`cog_to_sumo` / :func:`sumo_to_cog` on arrays, and the compiled
:func:`cog_to_sumo_rows` of the per-step moves, within :func:`sumo_placement`, the new state as
SUMO is told it (the same arithmetic, bit for bit; the per-step
reads convert inside sumo/sense.py's ``sense_step``, with :func:`sumo_to_cog_rows`'s
arithmetic, tests/test_fast_paths.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..core.kernels import kernel, maximum

KEEP_ROUTE = 1
"""moveToXY keepRoute bits: 1 = map only onto edges of the member's route (never off the road,
never a different carriageway); sublane mode keeps the exact lateral position."""

MATCH_THRESHOLD = 5.0
"""moveToXY raises instead of silently snapping a pose farther than this from the road [m]."""

ROUTE_AHEAD_M = 1000.0
"""A member's route in SUMO reaches at least this far past the end of its current edge [m].
``moveToXY`` with keepRoute=1 searches every edge of the vehicle's route (ahead of it and
behind it) for the nearest lane, so on a route of many edges a member carries only the part of
the formation's route up to here, moved on whenever it enters the next edge (SUMO keeps the
edges already driven in the route; a member starts its route at the edge before its own when
it enters: docs/sumo.md)."""

SPEED_MODE_DEFAULT = 31
SPEED_MODE_DRIVEN = 23
"""Speed mode of a member SUMO's car-following model drives (sumo/driven.py): the default's
safe speed, acceleration, deceleration and red-light bits, without the right of way at
junctions (bit 3). Where two lanes of an on-ramp edge merge into one (LuST: -31622#4's on-ramp
edge, lanes 1 and 2 into lane 1) a follower that may not change lanes would otherwise wait at
the merge for a gap in the ramp's traffic for ever, while its head, placed by moveToXY, drives
on along the geometric lane."""
"""SUMO's default speed mode: all safe-speed, acceleration and right-of-way checks on
(https://sumo.dlr.de/docs/TraCI/Change_Vehicle_State.html#speed_mode_0xb3)."""
LANE_CHANGE_MODE_DEFAULT = 1621
"""SUMO's default lane change mode (TraCI/Change_Vehicle_State.html#lane_change_mode_0xb6)."""

REMOVED_REASONS = ("arrived", "vanished")

ORDINARY_CLASS = {"custom1": "passenger", "custom2": "truck"}
"""SUMO class a released member drives on with: the members' own classes are kept off some
junction lanes of real networks (road/lanes.py), an ordinary vehicle is not."""


def cog_to_sumo(x, y, psi, d_front):
    """CoG pose [m, m, rad CCW from +x] -> SUMO front bumper [m, m] and angle [deg, CW from north]."""
    xf = x + d_front * np.cos(psi)
    yf = y + d_front * np.sin(psi)
    angle = np.mod(90.0 - np.degrees(psi), 360.0)
    return xf, yf, angle


def sumo_to_cog(xf, yf, angle_deg, d_front):
    """SUMO front bumper [m] and angle [deg, CW from north] -> CoG [m] and heading [rad CCW from +x]."""
    psi = np.radians(90.0 - np.asarray(angle_deg, dtype=float))
    return xf - d_front * np.cos(psi), yf - d_front * np.sin(psi), psi


@kernel
def cog_to_sumo_one(x, y, psi, d_front):
    """:func:`cog_to_sumo` compiled, for one pose: SUMO's front bumper xf, yf [m] and angle
    [deg, CW from north]."""
    return (x + d_front * np.cos(psi), y + d_front * np.sin(psi),
            np.mod(90.0 - psi * (180.0 / math.pi), 360.0))


@kernel
def sumo_to_cog_one(xf, yf, angle_deg, d_front):
    """:func:`sumo_to_cog` compiled, for one front bumper xf, yf [m] and angle [deg]: CoG
    x, y [m] and heading [rad CCW from +x]."""
    p = (90.0 - angle_deg) * (math.pi / 180.0)
    return xf - d_front * np.cos(p), yf - d_front * np.sin(p), p


@kernel
def cog_to_sumo_rows(x, y, psi, d_front):
    """:func:`cog_to_sumo` compiled, for (n,) arrays: SUMO's front bumper xf, yf [m] and
    angle [deg, CW from north]."""
    n = x.shape[0]
    xf = np.empty(n)
    yf = np.empty(n)
    ang = np.empty(n)
    for i in range(n):
        xf[i], yf[i], ang[i] = cog_to_sumo_one(x[i], y[i], psi[i], d_front[i])
    return xf, yf, ang


@kernel
def sumo_placement(pos, heading, v_before, v_after, d_front, step, place):
    """The members' new state as SUMO is told it (sumo/world.py SumoWorld.actuate, the compiled
    step's actuate), into ``place`` (6, n): SUMO's front bumper x, y [m] and angle [deg] of
    the CoG ``pos`` (n, 2) [m] and ``heading`` (n,) [rad] (:func:`cog_to_sumo_rows`), the speed
    ``v_after`` [m/s], the mean acceleration over the step of ``step`` [s] from ``v_before``
    [m/s^2] and the speed SUMO is told, ``v_after`` not below 0 [m/s] (moveToXY's setSpeed
    and setPreviousSpeed)."""
    xf, yf, ang = cog_to_sumo_rows(pos[:, 0].copy(), pos[:, 1].copy(), heading, d_front)
    for i in range(pos.shape[0]):
        place[0, i] = xf[i]
        place[1, i] = yf[i]
        place[2, i] = ang[i]
        place[3, i] = v_after[i]
        place[4, i] = (v_after[i] - v_before[i]) / step
        place[5, i] = maximum(v_after[i], 0.0)


@kernel
def sumo_to_cog_rows(xy, angle_deg, d_front):
    """:func:`sumo_to_cog` compiled, for SUMO's front bumpers xy (n, 2) [m], angles (n,)
    [deg] and CoG-to-front distances (n,) [m]: CoG x, y [m] and heading [rad CCW from +x]."""
    n = xy.shape[0]
    x = np.empty(n)
    y = np.empty(n)
    psi = np.empty(n)
    for i in range(n):
        x[i], y[i], psi[i] = sumo_to_cog_one(xy[i, 0], xy[i, 1], angle_deg[i], d_front[i])
    return x, y, psi


@dataclass(frozen=True)
class MemberType:
    """SUMO vType of a formation member."""

    id: str
    length: float  # [m]
    width: float  # [m]
    d_front: float  # CoG to front bumper [m]
    color: tuple[int, int, int]
    vclass: str  # SUMO vehicle class
    max_speed: float = 70.0  # [m/s] above anything a member reaches, so SUMO never clamps
    ssm_device: bool = False  # SUMO's SSM device on members of this type (sumo.ssm = "members")
    # what SUMO's own driver model uses (a member placed by moveToXY ignores them; one SUMO
    # drives, sumo/driven.py, does not): the vType copied (its car-following model and its
    # parameters; a CACC one from an additional file), minGap [m], accel, decel, emergency
    # decel [m/s^2]
    base: str = "DEFAULT_VEHTYPE"
    min_gap: float = 0.5
    accel: float = 10.0
    decel: float = 10.0
    emergency_decel: float = 12.0


@dataclass(frozen=True)
class StepEvents:
    """What SUMO reported during one step (ids are SUMO vehicle ids). Frozen: a quiet step
    returns one shared instance (sumo/adapter/__init__.py ``step``)."""

    collisions: list[tuple[str, str, str]] = field(default_factory=list)  # (collider, victim, lane)
    teleports: list[str] = field(default_factory=list)
    arrived: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Neighbours:
    """Vehicles near the members after a step (one entry per vehicle), CoG frame."""

    ids: list[str]
    types: list[str]
    x: np.ndarray  # centre of the vehicle [m]
    y: np.ndarray
    heading: np.ndarray  # [rad]
    v: np.ndarray  # [m/s]
    a: np.ndarray  # [m/s^2]
    length: np.ndarray  # [m]
    width: np.ndarray  # [m]
    lane_ids: list[str]
    lane_index: np.ndarray


class SumoError(RuntimeError):
    """SUMO refused a command or raised during a step."""


START_TIMEOUT_S = 30
"""A SUMO started over a socket (traci backend, sumo-gui) that does not accept the connection
within this many seconds is killed and the run fails with what SUMO printed [s]."""

GUI_VIEW = "View #0"
"""sumo-gui's default view (the one that follows the formation)."""

GUI_ZOOM = 400.0
"""Zoom of that view while following a member [%]: about 150 m of road across the window."""


def sumo_binary(gui: bool = False) -> str:
    """Path of the sumo (or sumo-gui) binary of the eclipse-sumo wheel."""
    import sumolib
    return sumolib.checkBinary("sumo-gui" if gui else "sumo")


