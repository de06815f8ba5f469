"""Per-step inputs of the members' driving resistance: drag ratio and road grade.

Called once per outer step by the loops (runner.free_space_steps, sumo_loop.sumo_steps)
before the step's signals are recorded; the values are held over the step's control
periods (FastFleet.set_road_load). The drag law itself is models/drag_interaction.py. The
grade comes from the elevation (z) of the reference lane's shape in the SUMO network; a
network without elevation (all bundled ones) and free space give 0 (docs/energy.md).
"""
from __future__ import annotations

import numpy as np

from ..models.drag_interaction import PLATOON_DRAG, along_heading, drag_ratios
from ..models.params import VehicleParams
from ..scenario.schema import Scenario


def interaction_on(sc: Scenario) -> bool:
    """True when the scenario asks for resistances with the formation-aware drag."""
    return sc.energy.resistances and sc.energy.drag_interaction


def free_space_ratios(veh: VehicleParams, pos: np.ndarray, heading: float) -> np.ndarray:
    """Drag ratio [-] of each member in free space (members only), positions (n, 2) [m]
    resolved along the virtual car's heading [rad]."""
    s, d = along_heading(pos[:, 0], pos[:, 1], heading)
    n = len(s)
    return drag_ratios(s, d, np.full(n, veh.length), np.full(n, veh.width), n, PLATOON_DRAG)


def road_ratios(veh: VehicleParams, m_s, m_d, active, nb_s, nb_d, nb_length, nb_width) -> np.ndarray:
    """Drag ratio [-] of each member on a road among SUMO's vehicles: members' centres of
    gravity (m_s, m_d) [m] (``active``: still in SUMO), other vehicles' centres, lengths, widths [m]."""
    n = len(m_s)
    centre = np.asarray(m_s, float) + (veh.cog_to_front_bumper - 0.5 * veh.length)  # CoG -> body
    s = np.concatenate([centre, np.asarray(nb_s, float)])
    d = np.concatenate([np.asarray(m_d, float), np.asarray(nb_d, float)])
    length = np.concatenate([np.full(n, veh.length), np.asarray(nb_length, float)])
    width = np.concatenate([np.full(n, veh.width), np.asarray(nb_width, float)])
    present = np.concatenate([np.asarray(active, bool), np.ones(len(s) - n, bool)])
    return drag_ratios(s, d, length, width, n, PLATOON_DRAG, present)


GRADE_BASE = 1.0
"""Half the base of the central difference that gives the grade from the elevation [m]."""


def elevation_profile(net, edges, lane_index: int, line) -> tuple[np.ndarray, np.ndarray] | None:
    """Elevation of the reference lane against arc length: (s [m], z [m]), or None when the
    network has no elevation. The lane's 3-D shape points (internal lanes included) are
    projected onto the reference line ``line`` (road/geometry.py)."""
    from ..road.geometry import load_net, route_lanes

    net = load_net(net)
    pts = [p for lid in route_lanes(net, edges, lane_index) for p in net.getLane(lid).getShape3D()]
    xyz = np.asarray(pts, dtype=float).reshape(-1, 3)
    if not len(xyz) or not np.any(xyz[:, 2] != 0.0):
        return None
    s, _ = line.to_frenet(xyz[:, :2])
    order = np.argsort(s, kind="stable")
    s, z = s[order], xyz[order, 2]
    keep = np.concatenate([[True], np.diff(s) > 1e-6])  # shared points of joined lanes
    return s[keep], z[keep]


def grade_at(profile: tuple[np.ndarray, np.ndarray], s) -> np.ndarray:
    """Road grade [rad] (positive uphill) at arc lengths s [m]: atan of the central difference
    of the piecewise-linear elevation over +-GRADE_BASE."""
    ps, pz = profile
    s = np.asarray(s, dtype=float)
    dz = np.interp(s + GRADE_BASE, ps, pz) - np.interp(s - GRADE_BASE, ps, pz)
    return np.arctan(dz / (2.0 * GRADE_BASE))
