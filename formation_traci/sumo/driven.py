"""SUMO's own CACC as the followers' law, SUMO's side: ``controller.law = "sumo_cacc"``
(docs/platoon_laws.md, "SUMO's CACC twin"; the law itself, its parameters and the members it
drives: control/laws/sumo_cacc.py).

What drives what. The column's head (the law's HEAD_LAW, ours) is placed with moveToXY on its
slot of the virtual car (which follows ``leader.speed`` through the governor), its true speed
and acceleration told to SUMO after every step. Every follower (the law's ``driven``) is
inserted at the pose and speed our column would start from (same lane, same spacing), of a vType
with SUMO's ``CACC`` car-following model (``controller.sumo_cacc``; written to
``sumo/sumo_cacc.add.xml``, copied per member preset with the member's chassis length and
width), and from then on SUMO drives it: the safe-speed checks without the right of way at
junctions (sumo/types.py SPEED_MODE_DRIVEN), no lane changes, no moveToXY.

Recording. At every sense the followers' SUMO state (front bumper, angle, speed,
acceleration) is read back and written into their rows of the fleet state (CoG frame), so the
loop records them in the same tables as our members: x, y, v from SUMO, heading the direction
of the road's smooth reference line where the follower is (SUMO's angle is its lane polyline's
segment direction and jumps at the polyline's corners: SumoDrivenWorld._lane_heading), the
CoG from SUMO's front bumper along that heading, yaw_rate the heading's rate over the step,
a_lon SUMO's acceleration, a_lat v times yaw_rate, the formation
error (ex .. y_des) against their slots on the virtual car as for any member, ``sumo_gap`` ~ 0
(their state is SUMO's); the model's own columns (v_ref, omega_ref, steer .. drag_ratio) are
NaN. Their comfort rows at the control rate hold the step's values (SUMO changes a speed once
per step). The fleet still steps their rows with the head's law (thrown away at the next read).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..control.laws import sumo_cacc
from ..models.bicycle import S
from ..models.state import KINEMATIC
from ..record.columns import SIGNAL_COLUMNS
from ..road.fast_line import frame_many, to_frenet_many
from ..sim.fleet import Fleet
from .types import sumo_to_cog
from .world import SumoWorld

CACC_BASE_TYPE = "sumo_cacc"
"""The CACC vType of the additional file; every member type is a copy of it."""

LANE_CHANGE_PARAMS = {"lcOvertakeRight": "1", "lcCooperativeSpeed": "0", "lcStrategic": "-1"}
"""The followers' lane-change model parameters. SUMO's default lane-change model (LC2013)
changes their speed for reasons of lanes, not of the column, even with lane changes off
(lane-change mode 0), while our head, placed by moveToXY, does neither: it forbids overtaking
on the right (a vehicle slows to the speed of slower traffic in the lane to its left: 25 m/s
behind a 28 m/s head on LuST), it slows a vehicle to let one that wants to change into its lane
in ahead of it, and where its strategy wants a lane change it cannot make it slows the vehicle
as if the change were urgent (1.9 m/s^2 on LuST's off-ramp edge after the
junction at s = 1,437 m, whose lane continues on the route); the followers fell back from the
head they follow, to gaps of 60-76 m. ``lcOvertakeRight = 1``, ``lcCooperativeSpeed = 0`` and
``lcStrategic = -1`` (no strategic changes) keep them with their column's head: their speed is
their CACC's (and SUMO's safe speed); they never change lanes (lane-change mode 0), as under
our laws."""

_COL = {c: SIGNAL_COLUMNS.index(c) for c in ("v", "yaw_rate", "a_lon", "a_lat")}
_MODEL_ONLY = [SIGNAL_COLUMNS.index(c) for c in (
    "v_ref", "omega_ref", "steer", "steer_rate", "beta", "slip_front", "slip_rear",
    "traction_force", "traction_force_max", "friction_usage", "power", "drag_force",
    "drag_ratio") if c in SIGNAL_COLUMNS]
"""Signal columns of our vehicle model and controller: NaN for a member SUMO drives."""


def world_and_fleet(sc, cfg, baseline: bool):
    """(fleet, World class) of a road run: SUMO drives the followers under ``sumo_cacc``
    (a baseline twin has no formation: the ordinary ones)."""
    if sc.controller.law != sumo_cacc.NAME or baseline:
        return Fleet(cfg), SumoWorld
    return DrivenFleet(cfg), SumoDrivenWorld


class DrivenFleet(Fleet):
    """A Fleet whose followers (``driven``: pred >= 0) SUMO drives: their recorded signals
    are SUMO's motion (:attr:`sumo`, written by :class:`SumoDrivenWorld` at every sense)."""

    def __init__(self, cfg):
        super().__init__(cfg)
        self.driven = sumo_cacc.driven(self.pred)
        self.sumo = np.zeros((cfg.n, 3))  # v [m/s], a_lon [m/s^2], yaw rate [rad/s] as read

    def _patch(self, out: np.ndarray) -> None:
        d, s = self.driven, self.sumo
        out[d, _COL["v"]] = s[d, 0]
        out[d, _COL["yaw_rate"]] = s[d, 2]
        out[d, _COL["a_lon"]] = s[d, 1]
        out[d, _COL["a_lat"]] = s[d, 0] * s[d, 2]
        for c in _MODEL_ONLY:
            out[d, c] = np.nan

    def signals_into(self, state, ref, out, t: float = 0.0, rows=None) -> bool:
        """:meth:`Fleet.signals_into` with the followers' columns SUMO's; never writes the
        table rows itself (returns False: the recorder writes ``out``)."""
        super().signals_into(state, ref, out, t, None)
        self._patch(out)
        return False

    def step(self, state, ref, comfort=None, rows=None):
        """:meth:`Fleet.step`; the followers' comfort values of every period (and their table
        rows, when written: sim/recorder.py period_rows' layout, row at + (j - 1) n + i) are
        their SUMO values at the step's start, held."""
        new = super().step(state, ref, comfort, rows)
        if comfort is None or not self.driven.any():
            return new
        d, s = np.flatnonzero(self.driven), self.sumo
        held = np.stack([s[d, 0], s[d, 1], s[d, 0] * s[d, 2]], axis=1)  # (len(d), 3)
        comfort[:, d, :] = held
        if rows is not None:
            table, _, at = rows
            n = self.cfg.n
            for j in range(1, comfort.shape[0]):
                table[1:4, at + (j - 1) * n + d] = held.T
        return new


class SumoDrivenWorld(SumoWorld):
    """SumoWorld whose followers SUMO's CACC drives (see the module docstring)."""

    def __init__(self, sc, plan, fleet: DrivenFleet, rec, out_dir: Path, meta: dict,
                 baseline: bool = False, step_hook=None):
        super().__init__(sc, plan, fleet, rec, out_dir, meta, baseline, step_hook)
        spec = sc.controller.params("sumo_cacc")
        self.moved = ~fleet.driven
        self.mtypes = [replace(mt, id=f"{mt.id}_cacc", base=CACC_BASE_TYPE, min_gap=spec.min_gap_m,
                               accel=spec.accel_mps2, decel=spec.decel_mps2,
                               emergency_decel=spec.emergency_decel_mps2) for mt in self.mtypes]
        self._psi = np.full(len(self.ids), np.nan)  # followers' heading at the last read [rad]
        meta["sumo_cacc"] = {
            "moved": [m for m, d in zip(self.ids, fleet.driven) if not d],
            "driven_by_sumo": [m for m, d in zip(self.ids, fleet.driven) if d],
            "vtype": {"carFollowModel": "CACC", **spec.vtype_attributes()},
            "desired_gap_m": f"{spec.min_gap_m:g} + {spec.tau_s:g} v (bumper to bumper)"}

    def start(self) -> None:
        self.sumo_dir.mkdir(exist_ok=True)
        path = self.sumo_dir / "sumo_cacc.add.xml"
        write_cacc_type(path, self.sc.controller.params("sumo_cacc").vtype_attributes())
        self.adds = [str(path)]
        super().start()

    def insert_members(self, t_next, rows, pos, heading, v_after) -> None:
        super().insert_members(t_next, rows, pos, heading, v_after)
        for i in rows:
            if self.fleet.driven[i]:
                self.adapter.drive_with_sumo(self.sumo_ids[i])

    def actuate(self, t_next: float, state, v_before) -> None:
        super().actuate(t_next, state, v_before)
        if self.true_v is not None:  # FCD in the formation frame: SUMO's speed is their truth
            self.true_v[int(round(t_next / self.sc.run.step))][self.fleet.driven] = np.nan

    def sense(self, k: int, t: float, state):
        if self.inserted:
            self._read_driven(state)
        else:  # before SUMO has them: the initial state (speed, no acceleration, its yaw rate)
            sumo = self.fleet.sumo
            sumo[:, 0], sumo[:, 1] = self.fleet.speed(state), 0.0
            sumo[:, 2] = 0.0 if self.fleet.kind == KINEMATIC else state.x[:, S.R]
        return super().sense(k, t, state)

    def _read_driven(self, state) -> None:
        """The followers' SUMO state into their fleet-state rows (CoG frame) and the fleet's
        :attr:`DrivenFleet.sumo` (speed, acceleration, heading rate over the step)."""
        rows = np.flatnonzero(self.fleet.driven & self.active & self.in_sumo)
        if not len(rows):
            return
        front, ang, v, a = self.adapter.driven_states([self.sumo_ids[i] for i in rows])
        here = np.isfinite(v)
        rows, front, ang, v, a = rows[here], front[here], ang[here], v[here], a[here]
        psi = self._lane_heading(front, ang, rows)
        x, y, psi = sumo_to_cog(front[:, 0], front[:, 1], 90.0 - np.degrees(psi), self.d_front[rows])
        last = self._psi[rows]
        dpsi = np.angle(np.exp(1j * (psi - last)))
        r = np.where(np.isfinite(last), dpsi / self.sc.run.step, 0.0)
        self._psi[rows] = psi
        sx = state.x
        sx[rows, S.X], sx[rows, S.Y], sx[rows, S.PSI] = x, y, psi
        if self.fleet.kind == KINEMATIC:
            state.speed_in[rows] = v
        else:
            sx[rows, S.V], sx[rows, S.R], sx[rows, S.BETA] = v, r, 0.0
            if sx.shape[1] > S.A_D:
                sx[rows, S.A_D] = a
        sumo = self.fleet.sumo
        sumo[rows, 0], sumo[rows, 1], sumo[rows, 2] = v, a, r
        self._kin = None  # the state changed in place


    def _lane_heading(self, front, ang, rows) -> np.ndarray:
        """The followers' heading [rad CCW from +x]: the direction of the road's smooth
        reference line at the arc length of their centre of gravity (SUMO drives a follower
        along its lane, whose direction that is). SUMO's own angle is the direction of its
        lane shape's polyline segment (or of the junction's): it jumps where two segments meet
        (by a degree or more on a real net: a yaw rate of 0.3-0.6 rad/s over one step, 10-15
        m/s^2 of lateral acceleration at 28 m/s that no car feels); it only seeds the
        projection and picks the branch of the angle."""
        x0, y0, psi0 = sumo_to_cog(front[:, 0], front[:, 1], ang, self.d_front[rows])
        s, _ = to_frenet_many(self.line.G, np.column_stack([x0, y0]), self.m_s[rows])
        line = frame_many(self.line.G, s)[:, 4]
        return psi0 + np.angle(np.exp(1j * (line - psi0)))


def write_cacc_type(path: Path, attributes: dict[str, str]) -> None:
    """The SUMO additional file with the CACC vType :data:`CACC_BASE_TYPE` (``attributes``:
    SUMO attribute -> value)."""
    attrs = " ".join(f'{k}="{v}"' for k, v in {**attributes, **LANE_CHANGE_PARAMS}.items())
    path.write_text(f'<additional>\n    <vType id="{CACC_BASE_TYPE}" carFollowModel="CACC" '
                    f"{attrs}/>\n</additional>\n")
