"""The formation members as one vectorised closed loop (Figure 3.46).

Per control period: the formation controller (2.4-2.11) gives v_ref, omega_ref; the
kinematic unicycle applies them directly (2.2), the dynamic bicycle tracks them with the
scheduled speed (3.32-3.34) and steering-rate (3.35-3.38) loops; the input is held
(zero-order hold) while RK4 integrates the vehicles over the period.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from ..control.formation import FormationOutput, Targets, formation_control, initial_theta_star
from ..control.schedule import GainSchedule
from ..control.speed import desired_acceleration
from ..control.yaw import steering_rate
from ..models import bicycle, bicycle_fast, kinematic
from ..models.bicycle import S, U
from ..models.kinematic import KS, KU
from ..models.params import BicycleParams
from .integrate import substeps


@dataclass(frozen=True)
class FleetConfig:
    """Static description of the members' closed loop."""

    ids: tuple[str, ...]
    model: Literal["dynamic", "kinematic"]
    params: BicycleParams | None  # dynamic model only
    k: np.ndarray  # (n,) position gain of (2.7) [m/s]
    k_theta: np.ndarray  # (n,) heading gain of (2.8) [1/s]
    speed_gains: GainSchedule
    yaw_gains: GainSchedule
    physics_step: float  # [s]

    @property
    def n(self) -> int:
        return len(self.ids)

    @property
    def packed(self) -> np.ndarray:
        """Parameters packed for the compiled model (bicycle_fast.pack_params), built once."""
        p = self.__dict__.get("_packed")
        if p is None:
            p = bicycle_fast.pack_params(self.params, self.n)
            object.__setattr__(self, "_packed", p)
        return p


@dataclass
class FleetState:
    """Dynamic state of the members: vehicle states and the controller's theta* (2.11)."""

    x: np.ndarray  # (n, n_states)
    theta_star: np.ndarray  # (n,) [rad]
    speed_in: np.ndarray  # (n,) unicycle only: speed input applied last [m/s]


def kinematics(cfg: FleetConfig, state: FleetState):
    """Position (n, 2) [m], velocity (n, 2) [m/s], heading (n,) [rad] of the members."""
    x = state.x
    if cfg.model == "kinematic":
        psi, v = x[:, KS.PSI], state.speed_in
        vel = np.stack([v * np.cos(psi), v * np.sin(psi)], axis=1)
        return x[:, [KS.X, KS.Y]], vel, psi
    pos = x[:, [S.X, S.Y]]
    course = x[:, S.PSI] + x[:, S.BETA]
    v = x[:, S.V]
    vel = np.stack([v * np.cos(course), v * np.sin(course)], axis=1)
    return pos, vel, x[:, S.PSI]


def initial_state(cfg: FleetConfig, pos, heading, speed, yaw_rate, steer, targets: Targets) -> FleetState:
    """Members at rest in their initial pose; theta*(0) from eq (2.11)."""
    n = cfg.n
    if cfg.model == "kinematic":
        x = np.zeros((n, kinematic.N_STATES))
        x[:, KS.X], x[:, KS.Y], x[:, KS.PSI] = pos[:, 0], pos[:, 1], heading
    else:
        x = np.zeros((n, bicycle.N_STATES))
        x[:, S.X], x[:, S.Y], x[:, S.PSI] = pos[:, 0], pos[:, 1], heading
        x[:, S.V], x[:, S.R], x[:, S.DELTA] = speed, yaw_rate, steer
    theta0 = initial_theta_star(targets, pos, heading, cfg.k)
    return FleetState(x, theta0, np.asarray(speed, dtype=float) * np.ones(n))


def control(cfg: FleetConfig, state: FleetState, targets: Targets, v_cap=None, a_cap=None):
    """Controller evaluation at one sampling instant.

    Returns the input to hold, shape (n, 2), and the formation controller's output.
    Traffic safety layer (not in the seed, docs/model.md): ``v_cap`` (n,) [m/s] caps the
    speed reference and ``a_cap`` (n,) [m/s^2] the desired acceleration a_r of (3.32), so
    a member keeps its time gap to a vehicle ahead even where the scheduled gain (3.34)
    would brake too gently.
    """
    pos, vel, heading = kinematics(cfg, state)
    fo = formation_control(targets, pos, vel, heading, state.theta_star, cfg.k, cfg.k_theta)
    if v_cap is not None:
        fo = replace(fo, v_ref=np.minimum(fo.v_ref, v_cap))
    u = np.empty((cfg.n, 2))
    if cfg.model == "kinematic":
        u[:, KU.V] = fo.v_ref
        u[:, KU.OMEGA] = fo.omega_ref
    else:
        u[:, U.A_REF] = desired_acceleration(fo.v_ref, state.x[:, S.V], cfg.speed_gains)
        if a_cap is not None:
            u[:, U.A_REF] = np.minimum(u[:, U.A_REF], a_cap)
        u[:, U.STEER_RATE] = steering_rate(fo.omega_ref, state.x[:, S.R], cfg.yaw_gains)
    return u, fo


def advance(cfg: FleetConfig, state: FleetState, u: np.ndarray, fo: FormationOutput, dt: float) -> FleetState:
    """Hold u for dt [s]: RK4 on the vehicles, forward Euler on theta* (2.11).

    The compiled kernels of models/bicycle_fast.py compute exactly what
    ``integrate(bicycle.rhs, ...)`` / ``integrate(kinematic.rhs, ...)`` compute (tests pin it
    to 1e-11), about 100x faster for a few vehicles.
    """
    theta_star = state.theta_star + fo.theta_star_dot * dt
    n_sub = substeps(dt, cfg.physics_step)
    if cfg.model == "kinematic":
        x = bicycle_fast.integrate_unicycle(state.x, u, dt, n_sub)
        return FleetState(x, theta_star, np.maximum(u[:, KU.V], 0.0))
    x = bicycle_fast.integrate_bicycle(state.x, u, cfg.packed, dt, n_sub)
    return FleetState(x, theta_star, state.speed_in)


def member_signals(cfg: FleetConfig, state: FleetState, u: np.ndarray, fo: FormationOutput,
                   targets: Targets, vc_theta: float) -> dict[str, np.ndarray]:
    """The recorded columns of every member at one instant (record/columns.py)."""
    x = state.x
    nan = np.full(cfg.n, np.nan)
    c, s = np.cos(vc_theta), np.sin(vc_theta)
    out = {
        "x": x[:, 0].copy(), "y": x[:, 1].copy(), "heading": x[:, 2].copy(),
        "ex": fo.ex, "ey": fo.ey,
        "e_lon": c * fo.ex + s * fo.ey, "e_lat": -s * fo.ex + c * fo.ey,
        "x_des": targets.p[:, 0].copy(), "y_des": targets.p[:, 1].copy(),
        "v_ref": fo.v_ref, "omega_ref": fo.omega_ref,
    }
    if cfg.model == "kinematic":
        v = np.maximum(u[:, KU.V], 0.0)
        out.update(v=v, yaw_rate=u[:, KU.OMEGA].copy(), a_lon=fo.v_ref_dot,
                   a_lat=v * u[:, KU.OMEGA], steer=nan, steer_rate=nan, beta=nan,
                   slip_front=nan, slip_rear=nan, traction_force=nan,
                   traction_force_max=nan, friction_usage=nan, power=nan, drag_force=nan,
                   drag_ratio=nan)
        return out
    sig = bicycle.outputs(x, u, cfg.params)
    out.update(v=x[:, S.V].copy(), yaw_rate=x[:, S.R].copy(), steer=x[:, S.DELTA].copy(),
               beta=x[:, S.BETA].copy(), **sig)
    return out
