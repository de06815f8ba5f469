"""Vehicle, tire and road parameters with the seed's tables as named presets.

Every field is required and carries its unit. Presets are named after the seed table they
reproduce (Tables 3.1, 3.2, 3.3, 3.5). Values the seed does not give are marked
``# ours`` and explained in ``docs/model.md``.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Literal

import numpy as np

G = 9.81
"""Gravitational acceleration [m/s^2]."""

RHO_AIR_STANDARD = 1.225
"""Density of dry air at 15 deg C and 101.325 kPa (ISO 2533 standard atmosphere) [kg/m^3]."""


@dataclass(frozen=True, slots=True)
class MagicFormula:
    """Pacejka Magic Formula coefficients, eqs (3.9)-(3.10).

    ``D`` is negative in the seed's sign convention: with alpha = atan(...) - delta (3.7),
    a positive slip angle gives a negative (restoring) cornering force.
    """

    B: float  # stiffness factor [1/rad]
    C: float  # shape factor [-]
    D: float  # peak factor [N] (negative, see above)
    E: float  # curvature factor [-]


MF_SEED = MagicFormula(B=8.22, C=1.65, D=-1.7e4, E=-10.0)
"""Table 3.2: the seed's tire, identical front and rear, D independent of load and road."""


SURFACES: dict[str, float] = {
    "good_dry": 1.00,
    "good_wet": 0.90,
    "poor_dry": 0.80,
    "poor_wet": 0.60,
    "ice": 0.25,
}
"""Table 3.3: maximum coefficient of road adhesion mu [-] by pavement condition."""


@dataclass(frozen=True, slots=True)
class VehicleParams:
    """Chassis parameters of the single-track model (Tables 3.1, 3.5) and its limits."""

    m: float  # mass [kg]
    Izz: float  # yaw moment of inertia [kg m^2]
    a: float  # CoG to front axle [m]
    b: float  # CoG to rear axle [m]
    h: float  # CoG height [m] (eq 3.14)
    length: float  # body length, bumper to bumper [m]
    width: float  # body width [m]
    front_overhang: float  # front axle to front bumper [m]
    steer_max: float  # steering angle limit [rad]
    steer_rate_max: float  # steering rate limit [rad/s]
    c_d: float  # aerodynamic drag coefficient, alone in still air [-] (docs/energy.md)
    frontal_area: float  # frontal area A of 0.5 rho c_d A v^2 [m^2] (docs/energy.md)
    color: tuple[int, int, int]  # RGB shown in SUMO
    drive_lag_s: float = 0.0  # first-order lag of the drive/brake demand [s] (0: none, the seed's)
    steer_lag_s: float = 0.0  # first-order lag of the steering actuator [s] (0: none, the seed's)

    @property
    def wheelbase(self) -> float:
        """a + b [m]."""
        return self.a + self.b

    @property
    def cog_to_front_bumper(self) -> float:
        """Distance from the centre of gravity to the front bumper [m]."""
        return self.a + self.front_overhang


PASSENGER_CAR = VehicleParams(
    m=1480.0, Izz=1950.0, a=1.421, b=1.029,  # Table 3.1
    h=0.55,  # section 3.1.4
    length=4.6, width=1.8, front_overhang=0.9,  # ours: a mid-size sedan
    steer_max=np.deg2rad(35.0), steer_rate_max=np.deg2rad(30.0),  # ours, road-wheel angle
    c_d=0.30, frontal_area=2.2,  # ours: a mid-size sedan (docs/energy.md)
    color=(30, 144, 255),
)
"""Table 3.1 passenger car (body size, CoG height and steering limits: see docs/model.md)."""

SMALL_TRUCK = VehicleParams(
    m=7490.0, Izz=4700.0, a=1.7, b=2.55,  # Table 3.5
    h=1.0,  # ours: the seed gives no CoG height for the truck
    length=7.5, width=2.3, front_overhang=1.3,  # ours: a 7.5 t box truck
    steer_max=np.deg2rad(35.0), steer_rate_max=np.deg2rad(20.0),  # ours
    c_d=0.60, frontal_area=6.5,  # ours: a 7.5 t box truck (docs/energy.md)
    color=(255, 140, 0),
)
"""Table 3.5 small truck (CoG height, body size and steering limits: see docs/model.md)."""

VEHICLE_PRESETS: dict[str, VehicleParams] = {
    "passenger_car": PASSENGER_CAR,
    "small_truck": SMALL_TRUCK,
}

TireKind = Literal["seed", "load"]
"""``seed``: Table 3.2 as given (constant D). ``load``: D = -mu * axle load (eq 3.11)."""


@dataclass(frozen=True, slots=True)
class Tires:
    """Front and rear Magic Formula plus how cornering force is evaluated."""

    front: MagicFormula
    rear: MagicFormula
    linear: bool  # True: linearised tire F = B C D alpha (eq 3.12)


def axle_loads(veh: VehicleParams) -> tuple[float, float]:
    """Static front and rear axle loads [N]: m g b / L and m g a / L."""
    w = veh.m * G
    return w * veh.b / veh.wheelbase, w * veh.a / veh.wheelbase


def make_tires(veh: VehicleParams, mu: float, kind: TireKind = "load",
               linear: bool = False, base: MagicFormula = MF_SEED) -> Tires:
    """Build the tire pair for a vehicle on a road of adhesion ``mu``.

    ``kind="seed"`` returns Table 3.2 on both axles (D = -1.7e4 N whatever the load and road).
    ``kind="load"`` keeps B, C, E of ``base`` and sets D = -mu * axle load per axle
    (eq 3.11 applied to the static axle load), so the peak force scales with the road.
    """
    if kind == "seed":
        return Tires(base, base, linear)
    if kind == "load":
        fz_f, fz_r = axle_loads(veh)
        return Tires(replace(base, D=-mu * fz_f), replace(base, D=-mu * fz_r), linear)
    raise ValueError(f"tire kind must be 'seed' or 'load', got {kind!r}")


@dataclass(frozen=True, slots=True)
class LowSpeedBlend:
    """Blend from the dynamic to the kinematic single-track model at low speed.

    Below ``v_low`` the kinematic bicycle is used alone, above ``v_high`` the dynamic
    model alone, in between a smoothstep of v. ``tau`` is the relaxation time with which
    side slip and yaw rate are pulled to their kinematic values. Braking deceleration is
    capped at v / ``tau_stop`` so that the car comes to rest exponentially and never
    reverses (an RK4 step cannot overshoot through v = 0).
    """

    v_low: float  # [m/s]
    v_high: float  # [m/s]
    tau: float  # [s]
    tau_stop: float  # [s]


LOW_SPEED_DEFAULT = LowSpeedBlend(v_low=1.0, v_high=3.0, tau=0.05, tau_stop=0.05)


@dataclass(frozen=True, slots=True)
class BicycleParams:
    """Everything the dynamic bicycle right-hand side needs.

    Fields are floats for one vehicle, or arrays of shape (n,) for a mixed fleet
    (see :func:`stack`); all formulas broadcast.
    """

    m: float | np.ndarray  # [kg]
    Izz: float | np.ndarray  # [kg m^2]
    a: float | np.ndarray  # [m]
    b: float | np.ndarray  # [m]
    h: float | np.ndarray  # [m]
    mu: float | np.ndarray  # road adhesion [-]
    Bf: float | np.ndarray  # front MF B [1/rad]
    Cf: float | np.ndarray  # front MF C [-]
    Df: float | np.ndarray  # front MF D [N]
    Ef: float | np.ndarray  # front MF E [-]
    Br: float | np.ndarray  # rear MF B [1/rad]
    Cr: float | np.ndarray  # rear MF C [-]
    Dr: float | np.ndarray  # rear MF D [N]
    Er: float | np.ndarray  # rear MF E [-]
    linear_tire: bool  # eq 3.12 instead of 3.9-3.10
    steer_max: float | np.ndarray  # [rad]
    steer_rate_max: float | np.ndarray  # [rad/s]
    v_low: float  # [m/s] see LowSpeedBlend
    v_high: float  # [m/s]
    tau: float  # [s]
    tau_stop: float  # [s]
    resistances: bool  # rolling, aerodynamic and grade resistance on (False: the seed's model)
    c_d: float | np.ndarray  # drag coefficient alone [-]
    frontal_area: float | np.ndarray  # [m^2]
    rho_air: float | np.ndarray  # air density [kg/m^3]
    drag_ratio: float | np.ndarray  # c_d multiplier from the vehicles around [-] (1 alone)
    grade: float | np.ndarray  # road grade under the vehicle [rad], positive uphill
    drive_lag_s: float | np.ndarray = 0.0  # drive/brake actuator time constant [s] (docs/model.md)
    steer_lag_s: float | np.ndarray = 0.0  # steering actuator time constant [s] (docs/model.md)


def bicycle_params(veh: VehicleParams, mu: float, tires: Tires,
                   blend: LowSpeedBlend = LOW_SPEED_DEFAULT, resistances: bool = False,
                   rho_air: float = RHO_AIR_STANDARD) -> BicycleParams:
    """Flatten chassis, road, tires and low-speed blend into one :class:`BicycleParams`.

    ``resistances=False`` (default) is the seed's model: the traction force of (3.13) moves
    the car against no resistance. ``True`` adds rolling (3.15), aerodynamic and grade
    resistance (models/resistance.py); drag_ratio starts at 1 (alone) and grade at 0.
    """
    f, r = tires.front, tires.rear
    return BicycleParams(
        m=veh.m, Izz=veh.Izz, a=veh.a, b=veh.b, h=veh.h, mu=mu,
        Bf=f.B, Cf=f.C, Df=f.D, Ef=f.E, Br=r.B, Cr=r.C, Dr=r.D, Er=r.E,
        linear_tire=tires.linear,
        steer_max=veh.steer_max, steer_rate_max=veh.steer_rate_max,
        v_low=blend.v_low, v_high=blend.v_high, tau=blend.tau, tau_stop=blend.tau_stop,
        resistances=bool(resistances), c_d=veh.c_d, frontal_area=veh.frontal_area,
        rho_air=rho_air, drag_ratio=1.0, grade=0.0,
        drive_lag_s=veh.drive_lag_s, steer_lag_s=veh.steer_lag_s,
    )


_SHARED = ("linear_tire", "v_low", "v_high", "tau", "tau_stop", "resistances")


def stack(params: list[BicycleParams]) -> BicycleParams:
    """Stack per-vehicle parameters into one set with (n,) arrays, for a mixed fleet.

    The tire law and the low-speed blend must be the same for all vehicles.
    """
    first = params[0]
    for p in params[1:]:
        for name in _SHARED:
            if getattr(p, name) != getattr(first, name):
                raise ValueError(f"all members must share {name}")
    values = {}
    for f in fields(BicycleParams):
        if f.name in _SHARED:
            values[f.name] = getattr(first, f.name)
        else:
            values[f.name] = np.array([getattr(p, f.name) for p in params], dtype=float)
    return BicycleParams(**values)


# ------------------------------------------------ per-member parameter arrays (kernels)

PARAM_NAMES: tuple[str, ...] = (
    "m", "Izz", "a", "b", "h", "mu",
    "Bf", "Cf", "Df", "Ef", "Br", "Cr", "Dr", "Er",
    "linear_tire", "steer_max", "steer_rate_max",
    "v_low", "v_high", "tau", "tau_stop",
    "resistances", "c_d", "frontal_area", "rho_air", "drag_ratio", "grade",
    "drive_lag_s", "steer_lag_s",
)
"""Column order of the packed parameter array ``P`` (one column per BicycleParams field)."""

N_PARAMS = len(PARAM_NAMES)

# column indices (module-level ints: numba freezes them as compile-time constants)
_M = PARAM_NAMES.index("m")
_IZZ = PARAM_NAMES.index("Izz")
_A = PARAM_NAMES.index("a")
_B = PARAM_NAMES.index("b")
_H = PARAM_NAMES.index("h")
_MU = PARAM_NAMES.index("mu")
_BF = PARAM_NAMES.index("Bf")
_CF = PARAM_NAMES.index("Cf")
_DF = PARAM_NAMES.index("Df")
_EF = PARAM_NAMES.index("Ef")
_BR = PARAM_NAMES.index("Br")
_CR = PARAM_NAMES.index("Cr")
_DR = PARAM_NAMES.index("Dr")
_ER = PARAM_NAMES.index("Er")
_LIN = PARAM_NAMES.index("linear_tire")
_SMAX = PARAM_NAMES.index("steer_max")
_SRMAX = PARAM_NAMES.index("steer_rate_max")
_VLOW = PARAM_NAMES.index("v_low")
_VHIGH = PARAM_NAMES.index("v_high")
_TAU = PARAM_NAMES.index("tau")
_TAUSTOP = PARAM_NAMES.index("tau_stop")
_RES = PARAM_NAMES.index("resistances")
_CD = PARAM_NAMES.index("c_d")
_AREA = PARAM_NAMES.index("frontal_area")
_RHO = PARAM_NAMES.index("rho_air")
_DRAG = PARAM_NAMES.index("drag_ratio")
_GRADE = PARAM_NAMES.index("grade")
_DLAG = PARAM_NAMES.index("drive_lag_s")
_SLAG = PARAM_NAMES.index("steer_lag_s")


def pack_params(p: BicycleParams, n: int) -> np.ndarray:
    """Pack ``p`` into a C-contiguous float64 array of shape (n, N_PARAMS), columns PARAM_NAMES.

    Scalar fields are broadcast to all n rows; (n,) array fields (a mixed fleet from
    ``params.stack``) are copied per row; ``linear_tire`` and ``resistances`` become 0.0 / 1.0.
    Pack once per fleet and reuse: the array does not change while the parameters do not
    (``drag_ratio`` and ``grade`` are the exception: sim/fleet.py ``Fleet.set_road_load``
    writes those two columns every step).
    """
    names = tuple(f.name for f in fields(BicycleParams))
    if set(names) != set(PARAM_NAMES):
        raise ValueError(f"BicycleParams fields {names} do not match the kernel's {PARAM_NAMES}")
    n = int(n)
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    P = np.empty((n, N_PARAMS), dtype=np.float64)
    for j, name in enumerate(PARAM_NAMES):
        value = getattr(p, name)
        if name in ("linear_tire", "resistances"):
            col = np.asarray(value)
            if col.ndim != 0:
                raise ValueError(f"{name} must be one bool shared by the whole fleet")
            P[:, j] = 1.0 if bool(col) else 0.0
            continue
        col = np.asarray(value, dtype=np.float64)
        if col.ndim == 0 or col.shape == (n,):
            P[:, j] = col
        else:
            raise ValueError(f"parameter {name!r} has shape {col.shape}, expected () or ({n},)")
    return P
