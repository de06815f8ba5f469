"""A member's desired point (position, velocity, acceleration) from the step's reference.

Dispatches on the slot's frame: the virtual car's frame (eq 2.4 with the slot's rates,
control/formation.py ``rigid_target_at``) or road coordinates (road/targets.py
``road_target_at``), for member i in control period j of a Reference's arrays.
"""
from __future__ import annotations

from ..kernels import kernel
from ..road.targets import road_target_at
from .formation import rigid_target_at
from .reference import FRAME_ROAD


@kernel
def desired_point_at(frame_i, G, vc, slots, j, i):
    """(px, py, vx, vy, ax, ay) of member i in control period j (Reference.vc, .slots)."""
    if frame_i == FRAME_ROAD:
        return road_target_at(G, vc[j, i, 7], vc[j, i, 3], vc[j, i, 5], slots[j, i, 0],
                              slots[j, i, 1], slots[j, i, 2], slots[j, i, 3], slots[j, i, 4],
                              slots[j, i, 5])
    return rigid_target_at(vc[j, i, 0], vc[j, i, 1], vc[j, i, 2], vc[j, i, 3], vc[j, i, 4],
                           vc[j, i, 5], vc[j, i, 6], slots[j, i, 0], slots[j, i, 1],
                           slots[j, i, 2], slots[j, i, 3], slots[j, i, 4], slots[j, i, 5])
