"""A member's desired point (position, velocity, acceleration) from the step's reference.

Dispatches on the slot's frame: the virtual car's frame (eq 2.4 with the slot's rates,
control/formation.py ``rigid_target_at``) or road coordinates (road/targets.py
``road_target_at``), for member i in control period j of a Reference's arrays.
"""
from __future__ import annotations

import numpy as np

from ..core.kernels import kernel
from ..models.bicycle import S
from ..models.state import motion_at
from ..road.fast_line import to_frenet_one
from ..road.targets import road_target_at
from .formation import V_EPS, Target, rigid_target_at
from .laws.dispatch import ACC, CACC_PLOEG
from .reference import FRAME_ROAD



@kernel
def desired_point_at(frame_i, G, vc, slots, j, i):
    """(px, py, vx, vy, ax, ay) of member i in control period j (Reference.vc, .slots)."""
    if frame_i == FRAME_ROAD:
        return road_target_at(G, vc[j, i, 7], vc[j, i, 3], vc[j, i, 5], slots[j, i, 0],
                              slots[j, i, 1], slots[j, i, 2], slots[j, i, 3], slots[j, i, 4],
                              slots[j, i, 5])
    return rigid_target_at(vc[j, i], slots[j, i])


@kernel
def lane_point_at(G, vc, slots, j, i, xi, yi, vi, px, py, tvx, tvy):
    """The desired point (px, py, vx, vy, ax, ay) of member i's road-frame slot moved along
    the road to the member's own along-position: the point of its slot's lane (the slot's
    lateral offset and its rates) abeam the member's centre of gravity (xi, yi) [m], with the
    slot's speed and tangential acceleration along the road (a CACC's leader terms) and the
    normal acceleration of a point that moves along the lane at the member's own speed vi
    [m/s] (the curvature's yaw-rate feed-forward kappa vi, not kappa times the virtual car's
    speed, which over-steers a member slower than its slot). ``px`` .. ``tvy``: the slot's
    own point and velocity (their along-distance to the member seeds the projection). A member
    that follows the member ahead keeps its lane about this point whatever its along-error;
    moved along the slot's tangent instead, the point leaves the lane on a curve by about
    kappa e^2 / 2."""
    sp = np.hypot(tvx, tvy)
    e_lon = 0.0
    if sp > V_EPS:
        e_lon = ((px - xi) * tvx + (py - yi) * tvy) / sp
    s_i, _ = to_frenet_one(G, xi, yi, vc[j, i, 7] + slots[j, i, 0] - e_lon)
    qx, qy, qvx, qvy, qax, qay = road_target_at(G, s_i, vc[j, i, 3], vc[j, i, 5], 0.0,
                                                slots[j, i, 1], slots[j, i, 2], slots[j, i, 3],
                                                slots[j, i, 4], slots[j, i, 5])
    q = np.hypot(qvx, qvy)
    if q <= V_EPS:
        return qx, qy, qvx, qvy, qax, qay
    ux = qvx / q
    uy = qvy / q
    a_t = qax * ux + qay * uy
    a_n = (-qax * uy + qay * ux) * max(vi, 0.0) / q  # q^2 kappa -> q kappa vi
    return qx, qy, qvx, qvy, a_t * ux - a_n * uy, a_t * uy + a_n * ux


@kernel
def follows_lane(law_i, pred_i, frame_i):
    """Does the member follow the member ahead on a road slot under a platoon law of ours?
    Its lateral loop then holds its slot's lane abeam itself (:func:`lane_point_at`)."""
    return ACC <= law_i <= CACC_PLOEG and pred_i >= 0 and frame_i == FRAME_ROAD


@kernel
def law_point_at(law_i, pred_i, frame_i, G, vc, slots, j, i, x, kind, speed_in_i):
    """The desired point member i's law steers about in control period j: its slot's
    (:func:`desired_point_at`), moved along the road to the member's own
    along-position for a member that follows the member ahead on a road slot
    (:func:`follows_lane`; ``kind``, ``speed_in_i``: its model and speed input)."""
    px, py, tvx, tvy, tax, tay = desired_point_at(frame_i, G, vc, slots, j, i)
    if not follows_lane(law_i, pred_i, frame_i):
        return px, py, tvx, tvy, tax, tay
    v, _, _ = motion_at(kind, x, i, speed_in_i)
    return lane_point_at(G, vc, slots, j, i, x[i, S.X], x[i, S.Y], v, px, py, tvx, tvy)


@kernel
def target_at(fleet, state, ref, j, i):
    """Member i's desired point in control period j (:func:`law_point_at`) as a
    :class:`Target`; ``fleet``, ``state``, ``ref``: the kernels' records of the members'
    parameters and state and of the step's reference (sim/fleet_records.py,
    control/reference_records.py StepReference)."""
    px, py, tvx, tvy, tax, tay = law_point_at(fleet.law[i], fleet.pred[i], ref.frame[i], ref.G,
                                              ref.vc, ref.slots, j, i, state.x, fleet.kind,
                                              state.speed_in[i])
    return Target(px, py, tvx, tvy, tax, tay)
