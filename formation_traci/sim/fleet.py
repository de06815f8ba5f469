"""The formation members as one closed loop (Figure 3.46), compiled per step.

Per control period of a step, for every member: its desired point from the step's
:class:`~formation_traci.control.reference.Reference` (control/targets.py) -> the formation
controller (2.5-2.10) -> the model input (kinematic: v_ref, omega_ref; dynamic: the
scheduled speed loop 3.32-3.34 capped by the safety layer, the steering-rate loop 3.37) ->
the input held while RK4 integrates the vehicle (models/integrator.py) and Euler theta* (2.11).
The laws live in their home modules; this module only wires them, per member, in one
compiled call per step (:func:`step_members`) and one for the recorded signals
(:func:`member_signals`). Parameters are per-member arrays (a formation may mix vehicles).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..control.formation import initial_theta_star
from ..control.laws import DEFAULT_LAW
from ..control.laws.dispatch import law_input_at
from ..control.reference import Reference, cap_at
from ..control.schedule import GainSchedule
from ..control.reference_records import StepReference
from ..control.targets import desired_point_at, follows_lane, target_at
from ..core.kernels import kernel, maximum, substeps
from ..models import bicycle, kinematic
from ..models.integrator import HELD, rhs_into, rk4_row_from
from ..models.params import _DRAG, _GRADE, BicycleParams, N_PARAMS, pack_params
from ..models.bicycle import S
from ..models.state import DYNAMIC, KINEMATIC, motion_at
from ..record.columns import SIGNAL_COLUMNS
from .fleet_laws import fallback_switches, law_kernels, pack_laws
from .fleet_models import model_kernel, with_variant_params, with_variant_slots
from .fleet_rows import period_table_rows, signal_table_rows
from .record_rows import beyond_limits
from .table_records import NO_SIGNAL_ROWS
from .fleet_records import FleetParams, StateRecord, as_f64 as _f64, state_record
from .fleet_state import FleetState

_KERNEL_SIGNALS = ("x", "y", "heading", "v", "yaw_rate", "a_lon", "a_lat", "ex", "ey",
                   "e_lon", "e_lat", "x_des", "y_des", "v_ref", "omega_ref", "steer",
                   "steer_rate", "beta", "slip_front", "slip_rear", "traction_force",
                   "traction_force_max", "friction_usage", "power", "drag_force", "drag_ratio")
"""The signals :func:`member_signals` computes, in its internal order."""
N_SIGNALS = len(_KERNEL_SIGNALS)


def signal_column_map(columns: tuple[str, ...] = SIGNAL_COLUMNS) -> np.ndarray:
    """Output column of every kernel signal (-1: not recorded)."""
    return np.array([columns.index(n) if n in columns else -1 for n in _KERNEL_SIGNALS],
                    dtype=np.int64)


@dataclass(frozen=True)
class FleetConfig:
    """Static description of the members' closed loop (per-member arrays of length n)."""

    ids: tuple[str, ...]
    model: Literal["dynamic", "kinematic"]
    params: BicycleParams | None  # dynamic model only; fields scalar or (n,)
    k: np.ndarray  # (n,) position gain of (2.7) [m/s]
    k_theta: np.ndarray  # (n,) heading gain of (2.8) [1/s]
    speed_gains: GainSchedule | tuple[GainSchedule, ...]  # one, or one per member
    yaw_gains: GainSchedule | tuple[GainSchedule, ...]  # one, or one per member
    physics_step: float  # [s]
    law: str | tuple[str, ...] = DEFAULT_LAW  # control/laws: the members' law, or one per member
    pred: tuple[int, ...] | None = None  # member ahead of each in the column (-1: none); None: none
    bumpers: tuple[tuple[float, float], ...] | None = None  # CoG to front, to rear bumper [m]
    law_params: tuple | None = None  # per member: {law name: {parameter: value}} (platoon laws)
    variant: str | None = None  # a model variant of ``model`` (models/variants.py) or None
    variant_params: dict | None = None  # the variant's {parameter: value} (its pack(cfg))

    @property
    def n(self) -> int:
        return len(self.ids)


def initial_state(cfg: FleetConfig, pos, heading, speed, yaw_rate, steer, targets) -> FleetState:
    """Members in their initial pose and speed; theta*(0) from eq (2.11)."""
    n = cfg.n
    if cfg.model == "kinematic":
        x = np.zeros((n, kinematic.N_STATES))
        x[:, S.X], x[:, S.Y], x[:, S.PSI] = pos[:, 0], pos[:, 1], heading
    else:
        x = np.zeros((n, bicycle.N_STATES))
        x[:, S.X], x[:, S.Y], x[:, S.PSI] = pos[:, 0], pos[:, 1], heading
        x[:, S.V], x[:, S.R], x[:, S.DELTA] = speed, yaw_rate, steer
        x[:, S.DELTA_C] = steer  # the steering actuator starts at rest
    theta0 = initial_theta_star(targets, pos, heading, cfg.k)
    speed_in = np.asarray(speed, dtype=float) * np.ones(n)
    return FleetState(with_variant_slots(cfg, x), theta0, speed_in, np.zeros(n))


# ---------------------------------------------------------------------------- kernels

@kernel
def step_members(fleet, state, ref, comfort, t0, table, table_ids, at):
    """One step: for each of the ref.vc.shape[0] control periods of ``fleet.dt_c`` [s], every
    member's input from the reference ``ref`` (control/reference_records.py StepReference)
    under its control law (``fleet``: sim/fleet_records.py FleetParams; every law of period
    j reads the members' u0 of period j - 1 as ``u_last``), held over RK4 in ``fleet.n_sub``
    sub-steps (models/integrator.py). ``state`` (StateRecord) is not modified; returns (x,
    theta_star, speed_in, u_last) after the step. When ``comfort`` has a row per period
    ((n_ctrl, n, 3); else pass an empty array), member i's speed [m/s], a_lon and a_lat
    [m/s^2] at the start of period j go to comfort[j, i] (the values :func:`member_signals`
    records for that period); with ``at`` >= 0 too, periods 1 .. n_ctrl - 1 also as comfort
    table rows at columns at, at + 1, ... of ``table`` (t = t0 + j dt_c [s], speed, a_lon,
    a_lat) and ``table_ids`` (code i), period by period. Rows not ``ref.moving`` are left as
    they are (no law, no integration, no comfort values: the caller holds them)."""
    kind, P, dt_c, vc = fleet.kind, fleet.P, fleet.dt_c, ref.vc
    x = state.x.copy()
    n = x.shape[0]
    m = x.shape[1]
    theta_star = state.theta_star.copy()
    speed_in = state.speed_in.copy()
    u_prev = state.u_last.copy()
    now = StateRecord(x, theta_star, speed_in, u_prev)  # the laws' view, updated in place
    U0 = np.empty(n)
    U1 = np.empty(n)
    tsd = np.empty(n)
    w = np.empty((5, m))
    h = dt_c / fleet.n_sub
    for j in range(vc.shape[0]):
        for i in range(n):
            if not ref.moving[i]:
                continue
            res = law_input_at(fleet, now, i, target_at(fleet, now, ref, j, i), ref.v_cap[i],
                               cap_at(ref.a_cap_from[i], ref.a_cap[i], j, vc.shape[0]))
            U0[i] = res[0]
            U1[i] = res[1]
            tsd[i] = res[4]
            if kind == KINEMATIC and comfort.shape[0] == vc.shape[0]:
                _comfort_values(kind, x, i, P, res, comfort, j)
        for i in range(n):
            if not ref.moving[i]:
                continue
            theta_star[i] = theta_star[i] + tsd[i] * dt_c
            k1 = kind != KINEMATIC and comfort.shape[0] == vc.shape[0]
            if k1:  # the period's accelerations from RK4's first stage: its own numbers
                rhs_into(kind, x[i], U0[i], U1[i], P, i, w[0])
                comfort[j, i, 0] = x[i, S.V]
                comfort[j, i, 1], comfort[j, i, 2] = bicycle.body_accelerations(
                    x[i, S.V], x[i, S.BETA], x[i, S.R], w[0, S.V], w[0, S.BETA])
            rk4_row_from(kind, x[i], U0[i], U1[i], P, i, h, fleet.n_sub, w, HELD, k1)
            if kind == KINEMATIC:
                speed_in[i] = maximum(U0[i], 0.0)
            u_prev[i] = U0[i]  # the laws of the next period read it; none runs in this loop
    if at >= 0 and comfort.shape[0] == vc.shape[0]:
        period_table_rows(comfort, t0, dt_c, table, table_ids, at, ref.moving)
    return x, theta_star, speed_in, u_prev


@kernel
def _comfort_values(kind, x, i, P, res, out, j):
    """Speed [m/s], a_lon and a_lat [m/s^2] of member i on the kinematic model into out[j, i]
    (as :func:`_signal_values` computes them from the same inputs; the dynamic model's come
    from RK4's first stage in :func:`step_members`, which :func:`_signal_values`' outputs_of
    computes alike)."""
    vk = maximum(res[0], 0.0)
    out[j, i, 0] = vk
    out[j, i, 1] = res[5]
    out[j, i, 2] = vk * res[1]


@kernel
def _slot_error(x, i, px, py, c, s, vals):
    """ex, ey, e_lon, e_lat [m] and x_des, y_des of member i against the slot point (px, py)
    into vals (_KERNEL_SIGNALS order); (c, s): the virtual car's heading."""
    _errors_into(px - x[i, S.X], py - x[i, S.Y], px, py, c, s, vals)


@kernel
def _errors_into(ex, ey, px, py, c, s, vals):
    """ex, ey [m], their components along and across the heading (c, s) = (cos, sin), e_lon and
    e_lat [m], and the desired point x_des, y_des [m] into vals (_KERNEL_SIGNALS order)."""
    vals[7] = ex
    vals[8] = ey
    vals[9] = c * ex + s * ey
    vals[10] = -s * ex + c * ey
    vals[11] = px
    vals[12] = py


@kernel
def _signal_values(kind, x, i, P, u0, u1, res, px, py, c, s, vals):
    """The recorded signals of member i (vals, _KERNEL_SIGNALS order; NaN where the
    kinematic model has no value)."""
    vals[0] = x[i, S.X]
    vals[1] = x[i, S.Y]
    vals[2] = x[i, S.PSI]
    _errors_into(res[6], res[7], px, py, c, s, vals)
    vals[13] = res[2]
    vals[14] = res[3]
    if kind == KINEMATIC:
        vk = maximum(u0, 0.0)
        vals[3] = vk
        vals[4] = u1
        vals[5] = res[5]
        vals[6] = vk * u1
        for q in range(15, N_SIGNALS):
            vals[q] = np.nan
        return
    a_lon, a_lat, sf, sr, f_lf, f_max, usage, rate, power, drag, ratio = bicycle.outputs_of(
        x[i], u0, u1, P, i)
    vals[3] = x[i, S.V]
    vals[4] = x[i, S.R]
    vals[5] = a_lon
    vals[6] = a_lat
    vals[15] = x[i, S.DELTA]
    vals[16] = rate
    vals[17] = x[i, S.BETA]
    vals[18] = sf
    vals[19] = sr
    vals[20] = f_lf
    vals[21] = f_max
    vals[22] = usage
    vals[23] = power
    vals[24] = drag
    vals[25] = ratio


@kernel
def member_signals(fleet, state, ref, cols, out, t, rows):
    """The recorded signals at the start of a step (the first control period's reference
    ``ref``) into out[i, cols[q]]; e_lon / e_lat in the frame of the member's virtual car.

    With ``rows.at`` >= 0 (``rows``: sim/table_records.py SignalRows), also the members'
    table rows at time t [s] unless a |signal| exceeds ``rows.limits`` (one per column of
    out): member i's row is column at + i of ``rows.traj`` (one row per table column: t, then
    out's columns) and of ``rows.traj_ids`` (its code, i), and column c_at + i of
    ``rows.comfort`` (t, then out's columns ``comfort_cols``) and ``rows.comfort_ids``.
    Returns True when it wrote the rows (sim/recorder.py signal_rows)."""
    kind, x, vc = fleet.kind, state.x, ref.vc
    vals = np.empty(N_SIGNALS)
    n = x.shape[0]
    for i in range(n):
        tg = target_at(fleet, state, ref, 0, i)
        res = law_input_at(fleet, state, i, tg, ref.v_cap[i],
                           cap_at(ref.a_cap_from[i], ref.a_cap[i], 0, vc.shape[0]))
        th = vc[0, i, 2]
        _signal_values(kind, x, i, fleet.P, res[0], res[1], res, tg.px, tg.py, np.cos(th),
                       np.sin(th), vals)
        frame_i = ref.frame[i]
        if follows_lane(fleet.law[i], fleet.pred[i], frame_i):  # the error to the slot itself
            sx, sy, _, _, _, _ = desired_point_at(frame_i, ref.G, vc, ref.slots, 0, i)
            _slot_error(x, i, sx, sy, np.cos(th), np.sin(th), vals)
        for q in range(N_SIGNALS):
            if cols[q] >= 0:
                out[i, cols[q]] = vals[q]
    if rows.at < 0 or beyond_limits(out, rows.limits):
        return False  # out of range: the caller records the rows (and the event)
    signal_table_rows(out, t, rows.traj, rows.traj_ids, rows.at, rows.comfort, rows.comfort_ids,
                      rows.c_at, rows.comfort_cols, np.ones(n, dtype=np.bool_))
    return True


@kernel
def kinematics_rows(x, speed_in, kind):
    """Position (n, 2) [m], velocity (n, 2) [m/s], heading (n,) [rad] of the members."""
    n = x.shape[0]
    pos = np.empty((n, 2))
    vel = np.empty((n, 2))
    hd = np.empty(n)
    for i in range(n):
        v, r, course = motion_at(kind, x, i, speed_in[i])
        pos[i, 0] = x[i, S.X]
        pos[i, 1] = x[i, S.Y]
        vel[i, 0] = v * np.cos(course)
        vel[i, 1] = v * np.sin(course)
        hd[i] = x[i, S.PSI]
    return pos, vel, hd


# ------------------------------------------------------------------------ the wrapper

_NO_COMFORT = np.empty((0, 0, 3))
_NO_PERIOD_ROWS = (np.empty((0, 0)), np.empty(0, dtype=np.int32), -1)
"""step_members' table-row arguments when no rows are written."""

def _cap_from(ref: Reference) -> np.ndarray:
    """The members' caps at the start of the step [m/s^2] (period 0's: cap_at)."""
    return _f64(ref.a_cap if ref.a_cap_from is None else ref.a_cap_from)


class Fleet:
    """A FleetConfig packed once into the kernels' per-member arrays.

        fleet = Fleet(cfg)
        state = fleet.step(state, ref)               # ref: control.reference.Reference
        sig = fleet.signals(state, ref)              # (n, len(SIGNAL_COLUMNS))
    """

    def __init__(self, cfg: FleetConfig):
        n = cfg.n
        self.cfg = cfg
        if cfg.model == "dynamic":
            self.kind, self.P = DYNAMIC, pack_params(cfg.params, n)
        elif cfg.model == "kinematic":
            self.kind, self.P = KINEMATIC, np.zeros((n, N_PARAMS))
        else:
            raise ValueError(f"unknown model {cfg.model!r}")
        self.P = with_variant_params(cfg, self.P)  # a variant's columns after the model's
        self.k = _f64(np.broadcast_to(np.asarray(cfg.k, dtype=float), (n,)))  # eq 2.7, theta*(0)
        self.law, self.L, runtime = pack_laws(cfg)
        self.base_law = self.law.copy()  # the scenario's laws (self.law: the ones in force)
        self.pred = np.array(cfg.pred if cfg.pred is not None else (-1,) * n, dtype=np.int64)
        self._step, self._signals = law_kernels(runtime, model_kernel(cfg.variant, step_members),
                                                member_signals)
        sg, yg = (g if isinstance(g, (tuple, list)) else (g,) * n
                  for g in (cfg.speed_gains, cfg.yaw_gains))
        self.gains = _f64([[a.g_min, a.g_max, a.k_min, b.g_min, b.g_max, b.k_min]
                           for a, b in zip(sg, yg, strict=True)])
        self.cols = signal_column_map()
        self._params = None

    @property
    def resistances(self) -> bool:
        """True when the members drive against rolling, aerodynamic and grade resistance."""
        return self.kind == DYNAMIC and bool(self.cfg.params.resistances)

    def set_road_load(self, drag_ratio, grade=None) -> None:
        """Hold the members' drag ratio [-] (models/drag_interaction.py) and road grade [rad]
        for the next step and its signals (arrays (n,) or scalars; None: unchanged). No-op
        without resistances (sim/road_load.py computes them, docs/energy.md)."""
        if not self.resistances:
            return
        if drag_ratio is not None:
            self.P[:, _DRAG] = drag_ratio
        if grade is not None:
            self.P[:, _GRADE] = grade

    def fall_back(self, rows, lost) -> list[tuple[int, bool]]:
        """Put the CACC members of ``rows`` (indices) whose radio is ``lost`` (bools) on their
        ACC fallback and the others back on their own law; returns the members switched,
        (index, True: fell back / False: recovered) (sim/fleet_laws.py)."""
        return fallback_switches(self.law, self.base_law, self.pred, rows, lost)

    def n_sub(self, dt_c: float) -> int:
        return substeps(dt_c, self.cfg.physics_step)

    def step(self, state: FleetState, ref: Reference, comfort: np.ndarray | None = None,
             rows: tuple | None = None) -> FleetState:
        """The members over one step of ``ref.n_ctrl`` control periods of ``ref.dt``;
        ``comfort`` (n_ctrl, n, 3), if given, receives every period's speed [m/s], a_lon and
        a_lat [m/s^2] at its start (:func:`step_members`), and with ``rows``
        (sim/recorder.py Recorder.period_rows) periods 1 .. n_ctrl - 1 go into the comfort
        table's buffers too, in the same compiled call."""
        x, ts, sp, ul = self._step(
            self.params(ref.dt), state_record(state), self.reference(ref),
            _NO_COMFORT if comfort is None else comfort, float(ref.t),
            *(_NO_PERIOD_ROWS if rows is None else rows))
        return FleetState(x, ts, sp, ul)

    def params(self, dt_c: float) -> FleetParams:
        """The members' parameters as the kernels take them at control period dt_c [s] (the
        same record while the arrays are the same ones)."""
        got = self._params
        if (got is None or got.dt_c != dt_c or got.P is not self.P or got.law is not self.law
                or got.L is not self.L or got.gains is not self.gains or got.pred is not self.pred):
            got = self._params = FleetParams(self.kind, self.P, self.law, self.L, self.gains,
                                             self.pred, self.n_sub(dt_c), float(dt_c))
        return got

    @property
    def kernels(self):
        """(step kernel, signal kernel) of the fleet: :func:`step_members` and
        :func:`member_signals`, or their compiled copies that also dispatch to a law
        registered at run time (sim/fleet_laws.py law_kernels) or integrate a model variant
        (sim/fleet_models.py model_kernel)."""
        return self._step, self._signals

    def signals(self, state: FleetState, ref: Reference, out: np.ndarray | None = None):
        """The recorded member columns at the start of the step (SIGNAL_COLUMNS order)."""
        if out is None:
            out = np.full((self.cfg.n, len(SIGNAL_COLUMNS)), np.nan)
        self.signals_into(state, ref, out)
        return out

    def signals_into(self, state: FleetState, ref: Reference, out: np.ndarray, t: float = 0.0,
                     rows: tuple | None = None) -> bool:
        """:meth:`signals` into ``out`` (n, len(SIGNAL_COLUMNS)); with ``rows`` (sim/recorder.py
        Recorder.signal_rows) also written as the step's table rows at t [s], in the same
        compiled call: returns True when they were (False: out of range, or no ``rows``)."""
        return self._signals(self.params(ref.dt), state_record(state), self.reference(ref),
                             self.cols, out, float(t), NO_SIGNAL_ROWS if rows is None else rows)

    @staticmethod
    def reference(ref: Reference) -> StepReference:
        """The step's reference as the kernels take it."""
        return StepReference(ref.line, ref.frame, ref.vc, ref.slots, _f64(ref.v_cap),
                             _f64(ref.a_cap), _cap_from(ref), np.ones(len(ref.frame), dtype=np.bool_))

    def kinematics(self, state: FleetState):
        """Position (n, 2) [m], velocity (n, 2) [m/s], heading (n,) [rad]."""
        return kinematics_rows(_f64(state.x), _f64(state.speed_in), self.kind)

    def speed(self, state: FleetState) -> np.ndarray:
        """Speed of every member [m/s] (the unicycle's applied speed input)."""
        return state.x[:, S.V].copy() if self.kind == DYNAMIC else state.speed_in.copy()
