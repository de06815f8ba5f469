"""Jerk-limited longitudinal references in traffic (the governor's output made smooth).

The governor (control/governor.py) turns what SUMO reports every step into an *requested*
acceleration of the virtual car and, per member with a vehicle ahead, a speed cap and an
acceleration cap. SUMO's vehicles dawdle (Krauss), so these requests carry step-to-step
noise; fed straight to the virtual car and to the members' speed loop (gain up to 8 1/s,
Table 3.4) the noise became +-1.5 m/s^2 chatter in the members' acceleration.

Here every longitudinal request passes a planner with bounded jerk:

* the acceleration approaches the request as a first-order lag of time constant ``tau``
  [s] with its rate of change bounded by ``jerk_max`` [m/s^3] (comfort, ISO 15622's
  2.5 m/s^3 over 1 s with margin), and braking that grows towards a request below
  ``-brake_firm`` from a vehicle ahead (braking firmly; not the virtual car's own speed
  profile) by ``jerk_brake`` (within ISO 15622's bound);
* a request below ``-decel_comfort`` [m/s^2] (more than comfortable braking: a cut-in, a
  vehicle braking hard) is an *emergency*: the lag is skipped and the jerk bound is
  ``jerk_emergency``; the caller records the emergency as an event;
* a member's speed cap becomes an acceleration request ``(v_cap - v) / tau_speed_cap``
  (a hard cap on the speed reference would stop an accelerating member within a couple of
  steps: the speed loop's gain is 8 1/s), joins its acceleration cap, and passes the same
  planner, starting from the member's acceleration when a cap appears; the speed reference
  itself is then left uncapped;
* a cap that lifts (no constraint any more: the vehicle ahead changed lanes) while it still
  binds the member is eased out, not dropped: it rises at ``jerk_max`` (the planner's step
  towards an unbounded request) until it is ``lift_margin`` above the member's acceleration,
  i.e. the member's own law no longer reaches it, and only then goes. The member's requested
  acceleration min(law, cap) so never jumps from the cap to the law; a cap that does not bind
  when it lifts goes at once.

Pure functions of (state, input, params); :class:`LongitudinalPlanner` holds the state of
one run (the virtual car and every member) for the road reference generator
(control/reference_road.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.kernels import kernel


@dataclass(frozen=True)
class PlannerParams:
    """Planner settings (defaults: docs/model.md, 'Smooth longitudinal references')."""

    tau: float = 0.5
    """Time constant of the lag from request to acceleration (and on speed caps) [s]."""
    jerk_max: float = 0.8
    """Largest jerk of the reference outside emergencies [m/s^3]."""
    tau_speed_cap: float = 1.0
    """Time in which a member's speed cap asks to remove its excess speed [s]."""
    jerk_emergency: float = 20.0
    """Largest jerk while braking harder than comfortable [m/s^3]."""
    decel_comfort: float = 3.0
    """A request below minus this is an emergency [m/s^2]."""
    lift_margin: float = 0.3
    """A lifted cap this far above the member's acceleration no longer binds: it goes [m/s^2]
    (above the speed loop's lag behind a cap rising at jerk_max, ~0.1 m/s^2)."""
    jerk_release: float = 20.0
    """Rate at which braking harder than ``decel_comfort`` is released once the emergency is
    over [m/s^3] (up to -decel_comfort, then the lag and jerk_max again; released at
    jerk_max, a member braked at 8 m/s^2 for a car 15 m ahead went on braking to a standstill).
    0: released at jerk_max like any change (``leader.emergency_release = false``)."""
    jerk_brake: float = 2.0
    """Largest jerk while braking grows towards a request below ``-brake_firm`` [m/s^3] (a
    vehicle ahead that brakes firmly: followed at 0.8 m/s^3, the formation's braking falls
    behind what the closing gap asks until the request passes ``decel_comfort``, an emergency
    brake; docs/model.md, "Smooth longitudinal references"). At most ISO 15622's 2.5."""
    brake_firm: float = 2.0
    """A request below minus this [m/s^2] is firm braking, which sets in at ``jerk_brake`` (the
    longitudinal comfort reference: more braking than that is what a vehicle ahead must not be
    left to ask for long)."""

    def packed(self) -> np.ndarray:
        """(tau, jerk_max, jerk_emergency, decel_comfort, tau_speed_cap, lift_margin,
        jerk_release, jerk_brake, brake_firm) for :func:`plan_step`."""
        return np.array([self.tau, self.jerk_max, self.jerk_emergency, self.decel_comfort,
                         self.tau_speed_cap, self.lift_margin, self.jerk_release,
                         self.jerk_brake, self.brake_firm])


(TAU, JERK_MAX, JERK_EMERGENCY, DECEL_COMFORT, TAU_SPEED_CAP, LIFT_MARGIN, JERK_RELEASE,
 JERK_BRAKE, BRAKE_FIRM) = range(9)
"""Slots of :meth:`PlannerParams.packed`."""


@kernel
def plan_accel(a_prev, a_request, dt, pp, firm):
    """Next acceleration [m/s^2] from ``a_prev`` towards ``a_request`` over ``dt`` [s] (``pp``:
    the :class:`PlannerParams` as :meth:`PlannerParams.packed`; ``firm``: the request is
    traffic's, a vehicle's or a maneuver's room, not the virtual car's own speed profile).

    Returns ``(a, emergency)``. Outside emergencies the change is the first-order lag
    ``(a_request - a_prev) (1 - exp(-dt / tau))`` bounded by ``jerk_max dt``, and with
    ``firm`` a fall towards a request below ``-brake_firm`` by ``max(jerk_max, jerk_brake)
    dt``; in an emergency (``a_request < -decel_comfort``) the change is the whole difference
    bounded by ``jerk_emergency dt``. An infinite request (no constraint) leaves ``a_prev``
    unchanged. With ``jerk_release`` > 0, braking harder than ``decel_comfort`` that the
    request no longer asks is released at that rate up to -decel_comfort (the end of an
    emergency).
    """
    if not math.isfinite(a_request):
        return a_prev, False
    decel_comfort, jerk_release = pp[DECEL_COMFORT], pp[JERK_RELEASE]
    emergency = a_request < -decel_comfort
    if jerk_release > 0.0 and not emergency and a_prev < -decel_comfort:
        return a_prev + min(-decel_comfort - a_prev, jerk_release * dt), False
    if emergency:
        da, lim = a_request - a_prev, pp[JERK_EMERGENCY] * dt
    else:
        da, lim = (a_request - a_prev) * (1.0 - math.exp(-dt / pp[TAU])), pp[JERK_MAX] * dt
    fall = lim
    if not emergency and firm and a_request < -pp[BRAKE_FIRM] and pp[JERK_BRAKE] > pp[JERK_MAX]:
        fall = pp[JERK_BRAKE] * dt  # firm braking sets in faster
    return a_prev + min(max(da, -fall), lim), emergency


@kernel
def plan_caps(a_cap_prev, v_cap, a_cap, v_member, a_member, dt, pp, a_out, emergency):
    """Smoothed acceleration caps [m/s^2] of every member, in place (``pp``: the
    :class:`PlannerParams` as :meth:`PlannerParams.packed`, slots :data:`TAU` ..).

    The request is ``min(a_cap, (v_cap - v_member) / tau_speed_cap)`` (inf: no cap), always
    traffic's (:func:`plan_accel`'s ``firm``). A cap that appears (previous value inf) starts
    from the member's acceleration ``a_member`` (or the request if that is higher);
    ``emergency[i]`` is set where the request asks for more than ``decel_comfort`` of braking.
    A cap whose request lifts rises by ``jerk_max dt`` per step while it is less than
    ``lift_margin`` above ``a_member`` (it still binds), and is dropped (inf) after that."""
    jerk_max, decel_comfort, jerk_release = pp[JERK_MAX], pp[DECEL_COMFORT], pp[JERK_RELEASE]
    tau_speed_cap, lift_margin = pp[TAU_SPEED_CAP], pp[LIFT_MARGIN]
    for i in range(v_cap.shape[0]):
        req = min(a_cap[i], (v_cap[i] - v_member[i]) / tau_speed_cap)
        if not math.isfinite(req):
            prev = a_cap_prev[i]
            binds = math.isfinite(prev) and prev < a_member[i] + lift_margin
            rise = prev + jerk_max * dt
            if jerk_release > 0.0 and prev < -decel_comfort:  # the end of an emergency
                rise = prev + min(-decel_comfort - prev, jerk_release * dt)
            a_out[i], emergency[i] = rise if binds else np.inf, False
        else:
            start = a_cap_prev[i] if math.isfinite(a_cap_prev[i]) else max(req, a_member[i])
            a_out[i], emergency[i] = plan_accel(start, req, dt, pp, True)


@kernel
def plan_step(a_vc_prev, a_request, a_profile, a_cap_prev, v_cap, a_cap, v_member, a_member, dt,
              pp, a_out, emergency):
    """One step of the whole planner: the virtual car's acceleration (:func:`plan_accel`,
    returned with its emergency flag) and the members' caps (:func:`plan_caps` into ``a_out``
    and ``emergency``). ``pp``: the :class:`PlannerParams` as :meth:`PlannerParams.packed`.
    ``a_profile`` [m/s^2]: what the virtual car's set speed alone asks (the governor's free-road
    law); the virtual car's request is firm (:func:`plan_accel`) only where a vehicle (or a
    maneuver's room) asks more than that, ``a_request < a_profile``: braking the speed profile
    asks is the profile's own, at ``jerk_max``."""
    a_vc, emergency_vc = plan_accel(a_vc_prev, a_request, dt, pp, a_request < a_profile)
    plan_caps(a_cap_prev, v_cap, a_cap, v_member, a_member, dt, pp, a_out, emergency)
    return a_vc, emergency_vc


class LongitudinalPlanner:
    """State of the planner over one run: the virtual car's acceleration and the members' caps."""

    def __init__(self, n: int, params: PlannerParams, a0: float = 0.0):
        self.p = params
        self.pp = params.packed()
        self.a_vc = float(a0)
        self.emergency_vc = False
        self.v_cap = np.full(n, np.inf)  # never set: speed caps act through a_cap
        self.a_cap = np.full(n, np.inf)
        self.emergency = np.zeros(n, dtype=np.bool_)

    def step(self, a_request: float, v_cap, a_cap, v_member, a_member, dt: float,
             a_profile: float = math.inf):
        """One SUMO step (:func:`plan_step`): returns (a_vc, v_cap, a_cap), the smoothed
        references (the speed caps are folded into the acceleration caps, so v_cap is all inf).
        The road reference (control/reference_road.py) runs the same kernel inside its step.
        ``a_profile``: the set speed's own request [m/s^2] (inf: the request is traffic's)."""
        a_out = np.empty_like(self.a_cap)
        self.a_vc, self.emergency_vc = plan_step(
            self.a_vc, float(a_request), float(a_profile), self.a_cap, np.asarray(v_cap, np.float64),
            np.asarray(a_cap, np.float64), np.asarray(v_member, np.float64),
            np.asarray(a_member, np.float64), float(dt), self.pp, a_out, self.emergency)
        self.a_cap = a_out
        return self.a_vc, self.v_cap, a_out
