"""Open-loop runs: members driven by input profiles or by one loop alone (seed 3.1.6-3.2.2).

Every control period (``run.control_step``) each member gets
* a desired acceleration a_r: the ``accel`` profile, or the speed loop a_r = K e (3.32-3.33)
  with the member's plain P gain or the schedule K(e) (3.34);
* a steering input: the wheel angle set to the ``steer_deg`` profile (clipped to the
  steering limit), the ``steer_rate_deg_s`` profile (3.38), or the yaw-rate loop on
  omega_ref - psi dot with the schedule, as a rate (3.37) or an angle (3.35),
and the dynamic bicycle model is integrated with the one compiled RK4 of the closed loop
(models/integrator.py ``integrate``, the laws of models/bicycle.py; the speed and yaw loops are
control/schedule.py's law). With ``linear_speed`` the linear model (3.30, models/linear.py) linearised there runs
beside each member on the same steering angle and a_r (v dot = a_r, 3.26).

Recorded: the members in ``trajectories.parquet`` (every ``run.step``) and, per step, the
inputs and the linear model in ``open_loop.parquet``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from run_contract.columns import Column

from ..control.schedule import apply as p_law
from ..models import bicycle
from ..models.bicycle import S, traction_from_acceleration_at
from ..models.linear import lateral_ab, linear_params
from ..models.params import make_tires, pack_params
from ..record.columns import SIGNAL_COLUMNS
from ..record.writer import ChunkedTable
from ..scenario.schema import Scenario
from ..models.integrator import DYNAMIC, LINEAR, integrate
from .recorder import Recorder
from .setup import build_fleet, gain_schedule, profile, road_mu, vehicle_params

OPEN_LOOP_COLUMNS = (
    Column("t", "float64", "s", "simulated time"),
    Column("vehicle_id", "string", "-", "member id"),
    Column("a_ref", "float64", "m/s^2", "desired acceleration a_r applied"),
    Column("traction_force_request", "float64", "N", "F_lf that a_r asks for, eq 3.13, before the limits"),
    Column("steer_cmd", "float64", "rad", "steering angle commanded (angle inputs), else NaN"),
    Column("steer_rate_cmd", "float64", "rad/s", "steering rate commanded (rate inputs), else NaN"),
    Column("x_lin", "float64", "m", "linear model (3.30): x"),
    Column("y_lin", "float64", "m", "linear model: y"),
    Column("v_lin", "float64", "m/s", "linear model: speed"),
    Column("beta_lin", "float64", "rad", "linear model: side-slip angle"),
    Column("yaw_rate_lin", "float64", "rad/s", "linear model: yaw rate"),
)
"""Columns of ``open_loop.parquet``."""

_DEG = np.pi / 180.0


def _commands(sc: Scenario, x, t, p_gain, angle_loop, sg, yg, prof):
    """(a_r, steer angle or NaN, steer rate or NaN) of every member at time t [s]."""
    ol = sc.open_loop
    v, r = x[:, S.V], x[:, S.R]
    if ol.accel is not None:
        a_r = np.full(len(v), prof["accel"](t)[0])
    else:
        v_ref = prof["speed_ref"](t)[0]
        a_r = np.where(np.isfinite(p_gain), p_gain * (v_ref - v), p_law(v_ref, v, sg))
    n = len(v)
    angle, rate = np.full(n, np.nan), np.full(n, np.nan)
    if ol.steer_deg is not None:
        angle[:] = prof["steer_deg"](t)[0]
    elif ol.steer_rate_deg_s is not None:
        rate[:] = prof["steer_rate_deg_s"](t)[0]
    else:
        out = p_law(prof["yaw_rate_ref_deg_s"](t)[0], r, yg)  # 3.35 (angle) or 3.37 (rate)
        angle = np.where(angle_loop, out, np.nan)
        rate = np.where(angle_loop, np.nan, out)
    return a_r, angle, rate


def open_loop_steps(sc: Scenario, rec: Recorder, out_dir: Path) -> Iterator[tuple[int, float]]:
    """Simulate ``sc`` open loop; yields (step index, time [s]) after recording each step."""
    run, ol = sc.run, sc.open_loop
    n_steps = int(round(run.duration / run.step))
    n_ctrl = int(round(run.step / run.control_step))
    dt_c = run.step / n_ctrl
    cfg = build_fleet(sc)
    p = cfg.params
    P = pack_params(p, len(sc.members))
    ids = [m.id for m in sc.members]
    n = len(ids)
    ld = sc.leader
    x = np.zeros((n, 7))
    for i, m in enumerate(sc.members):
        x[i, [S.X, S.Y]] = m.position if m.position is not None else (ld.x, ld.y)
        x[i, S.PSI] = (m.heading_deg if m.heading_deg is not None else ld.heading_deg) * _DEG
        x[i, S.V] = m.speed if m.speed is not None else profile(ld.speed)(0.0)[0]
        x[i, S.R] = m.yaw_rate_deg_s * _DEG
        x[i, S.DELTA] = m.steer_deg * _DEG
    scale = {"accel": 1.0, "speed_ref": 1.0, "steer_deg": _DEG, "steer_rate_deg_s": _DEG,
             "yaw_rate_ref_deg_s": _DEG}
    prof = {k: profile(getattr(ol, k), f) for k, f in scale.items() if getattr(ol, k) is not None}
    p_gain = np.array([ol.speed_p_gain.get(i, np.nan) for i in ids])
    angle_loop = np.array([ol.yaw_input.get(i, "steer_rate") == "steer_angle" for i in ids])
    sg, yg = gain_schedule(sc.controller.speed_gains), gain_schedule(sc.controller.yaw_gains)
    ab = z = None
    if ol.linear_speed is not None:
        veh = vehicle_params(sc)
        tires = make_tires(veh, road_mu(sc), sc.vehicle.tire, linear=sc.vehicle.tire_law == "linear")
        ab = linear_params(lateral_ab(ol.linear_speed, veh, tires), n)
        z = np.column_stack([x[:, S.X], x[:, S.Y], x[:, S.PSI], x[:, S.V], x[:, S.BETA], x[:, S.R]])
    table = ChunkedTable(out_dir / "open_loop.parquet", OPEN_LOOP_COLUMNS, chunk_rows=n * 2000,
                         labels=ids)
    sig = np.full((n, len(SIGNAL_COLUMNS)), np.nan)
    col = {c: SIGNAL_COLUMNS.index(c) for c in SIGNAL_COLUMNS}
    try:
        for k in range(n_steps + 1):
            t = k * run.step
            for j in range(n_ctrl if k < n_steps else 1):
                tj = t + j * dt_c
                a_r, angle, rate = _commands(sc, x, tj, p_gain, angle_loop, sg, yg, prof)
                fixed = np.isfinite(angle)  # an angle input sets the wheel (3.35)
                x[:, S.DELTA] = np.where(fixed, np.clip(angle, -p.steer_max, p.steer_max), x[:, S.DELTA])
                u = np.column_stack([a_r, np.where(fixed, 0.0, rate)])
                if j == 0:
                    _record(rec, table, t, x, u, p, a_r, angle, rate, z, sig, col)
                    if k == n_steps:
                        break
                x = integrate(DYNAMIC, x, u, P, dt_c, run.physics_step)
                if z is not None:
                    z = integrate(LINEAR, z, np.column_stack([x[:, S.DELTA], a_r]), ab, dt_c,
                                  run.physics_step)
            yield k, t
    finally:
        table.close()


def _record(rec, table, t, x, u, p, a_r, angle, rate, z, sig, col):
    out = bicycle.outputs(x, u, p)
    sig[:] = np.nan
    for name, j in (("x", S.X), ("y", S.Y), ("heading", S.PSI), ("v", S.V), ("yaw_rate", S.R),
                    ("steer", S.DELTA), ("beta", S.BETA)):
        sig[:, col[name]] = x[:, j]
    for name in ("a_lon", "a_lat", "slip_front", "slip_rear", "traction_force",
                 "traction_force_max", "friction_usage", "steer_rate"):
        sig[:, col[name]] = out[name]
    rec.add_signal_rows(t, sig, {})
    rec.add_comfort_rows(t, sig)
    _, _, fcf, fcr, _, _ = bicycle.forces(x, u, p)
    m = np.broadcast_to(np.asarray(p.m, dtype=float), a_r.shape)
    packed = pack_params(p, len(x))  # for the resistance (0 with resistances off, the seed's)
    request = np.array([traction_from_acceleration_at(a_r[i], x[i, S.BETA], x[i, S.DELTA], fcf[i],
                                                      fcr[i], m[i],
                                                      bicycle.resistance_at(x[i, S.V], packed, i))
                        for i in range(len(a_r))])
    zz = z if z is not None else np.full((len(a_r), 6), np.nan)
    table.append({"t": t, "vehicle_id": np.arange(len(a_r), dtype=np.int32), "a_ref": a_r,
                  "traction_force_request": request, "steer_cmd": angle, "steer_rate_cmd": rate,
                  "x_lin": zz[:, 0], "y_lin": zz[:, 1], "v_lin": zz[:, 3], "beta_lin": zz[:, 4],
                  "yaw_rate_lin": zz[:, 5]}, len(a_r))
