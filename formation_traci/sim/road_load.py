"""Per-step inputs of the members' driving resistance: the formation-aware drag ratio.

Called once per outer step by the loops (runner.free_space_steps, sumo_loop.sumo_steps)
before the step's signals are recorded; the ratio is held over the step's control periods
(FastFleet.set_road_load). The law itself is models/drag_interaction.py. Road grade stays
0: none of the networks we read carries elevation (docs/energy.md).
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
