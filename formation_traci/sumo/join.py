"""Join on the SUMO side: a vehicle from the traffic becomes a formation member where it is.

The planner (control/maneuvers/join.py) picks the vehicle; :func:`take_over` (called from the
reference generator in the step of the decision) makes it a member in SUMO
(sumo/adapter/__init__.py ``take_over``), drops it from the neighbours the governor and the recorder
see in this step, puts its road coordinates and speed into the member's sensed values, and
queues its state; :func:`adopt` (the loop calls ``world.adopt`` before the members' signals
are recorded) writes that state into the fleet: the member's CoG where SUMO has the vehicle
(its front bumper where SUMO's is), its heading and speed, no sideslip, yaw rate or steering,
and theta* from eq (2.11) against its slot, so the controller starts from where the vehicle
is, with no jump.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..control.formation import initial_theta_star_at
from ..control.targets import desired_point_at
from ..models.bicycle import S
from ..models.state import KINEMATIC
from .traffic import CAR


def drop_neighbour(sensed, j: int) -> None:
    """Remove neighbour j from ``sensed`` (its Neighbours and road-coordinate arrays)."""
    nb = sensed.nb
    keep = np.arange(len(nb.ids)) != j
    lists = {f: [v for k, v in enumerate(getattr(nb, f)) if k != j] for f in ("ids", "types", "lane_ids")}
    arrays = {f: getattr(nb, f)[keep] for f in ("x", "y", "heading", "v", "a", "length", "width",
                                                 "lane_index")}
    sensed.nb = replace(nb, **lists, **arrays)
    for f in ("nb_s", "nb_d", "nb_rear", "nb_half_w", "nb_v"):
        setattr(sensed, f, getattr(sensed, f)[keep])
    if len(sensed.nb_in_formation) == len(keep):
        sensed.nb_in_formation = sensed.nb_in_formation[keep]


def inside_formation(released: set, sensed, m_front, vehicles, active) -> np.ndarray:
    """Which neighbours in ``sensed`` are released members still inside the formation: behind
    the front bumper (``m_front``, arc length [m]) of an active member whose lateral band they
    overlap (members' chassis ``vehicles``). The virtual car's slot law ignores them
    (control/governor.py governor_step): braking for a released member that follows a member
    ahead of it would brake that member, which it follows, down to a standstill."""
    nb = sensed.nb
    out = np.zeros(len(nb.ids), dtype=np.bool_)
    for j, vid in enumerate(nb.ids):
        if vid not in released:
            continue
        for i in np.flatnonzero(active):
            if m_front[i] > sensed.nb_rear[j] and abs(sensed.m_d[i] - sensed.nb_d[j]) < \
                    0.5 * vehicles[i].width + sensed.nb_half_w[j]:
                out[j] = True
                break
    return out


def take_over(world, t: float, i: int, vid: str, sensed) -> None:
    """SUMO vehicle ``vid`` becomes member i of ``world`` (a SumoWorld) in this step."""
    nb = sensed.nb
    j = nb.ids.index(vid)
    psi, v = float(nb.heading[j]), float(nb.v[j])
    c, s = math.cos(psi), math.sin(psi)
    to_cog = nb.length[j] / 2 - world.plan.vehicles[i].cog_to_front_bumper  # centre -> CoG
    x, y = nb.x[j] + to_cog * c, nb.y[j] + to_cog * s
    lane = nb.lane_ids[j]
    world.adapter.take_over(vid, world.mtypes[i], world.route_id)
    world.sumo_ids[i] = vid
    world.active[i] = True
    world.in_sumo[i] = True
    world.adopting.append((i, x, y, psi, v))
    m_s, m_d = world.line.to_frenet(np.array([[x, y]]))
    sensed.m_s[i], sensed.m_d[i], sensed.v_m[i] = m_s[0], m_d[0], v
    drop_neighbour(sensed, j)
    world.rec.add_event(t, "join", world.ids[i], vid,
                        f"join: took over {vid} at {v:.2f} m/s on lane {lane}")


def enter(world, t: float, i: int, s: float, d: float, v: float) -> None:
    """Member i's own vehicle enters the road under SUMO's driver (a join with ``enter``):
    on the route edge and lane at arc length s, lateral offset d [m] of the reference line,
    front bumper at s + its CoG-to-front distance, speed v [m/s]; SUMO inserts it there as
    soon as that is safe and drives it, in its lane (lane-change mode 0), with a SUMO car's
    acceleration and deceleration, until the join takes it over."""
    road, vid = world.plan.road, world.ids[i]
    s_front = s + world.plan.vehicles[i].cog_to_front_bumper
    seg = next((g for g in road.segments if g.s0 <= s_front < g.s1), None)
    if seg is None:
        world.rec.add_event(t, "member_entered", vid, "", f"join: no road at s = {s_front:.1f} m: not entered")
        return
    lane = int(np.argmin(np.abs(road.lane_d[seg.edge] - d)))
    pos = s_front - seg.s0
    world.adapter.add_driven(vid, road.route[road.route.index(seg.edge):], lane, pos, v,
                             world.mtypes[i], float(CAR["accel"]), float(CAR["decel"]))
    world.rec.add_event(t, "member_entered", vid, "",
                        f"join: enters {seg.edge}_{lane} at {pos:.1f} m, {v:.2f} m/s, under SUMO's driver")


def adopt(fleet, state, ref, adopting: list) -> None:
    """Write the queued take-overs (i, x, y, psi, v) into ``state`` in place (module docstring)."""
    kind = fleet.kind
    for i, x, y, psi, v in adopting:
        row = state.x[i]
        row[:] = 0.0
        row[S.X], row[S.Y], row[S.PSI] = x, y, psi
        if state.u_last is not None:
            state.u_last[i] = 0.0  # a platoon law's memory starts afresh
        if kind == KINEMATIC:
            state.speed_in[i] = v
        else:
            row[S.V] = v
        px, py, tvx, tvy, _, _ = desired_point_at(ref.frame[i], ref.line, ref.vc, ref.slots, 0, i)
        state.theta_star[i] = initial_theta_star_at(px, py, tvx, tvy, x, y, psi, fleet.k[i])
    adopting.clear()
