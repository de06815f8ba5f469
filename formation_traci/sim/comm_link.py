"""The channel as a transformer of the virtual car's state into each member's view.

Built from [comm] (docs/communication.md). Per step:

1. :meth:`update` stores the true state of every beacon the virtual leader sends during the
   step, finds the newest beacon each member holds at each control instant
   (comm/channel.py) and its age; a member whose newest state is older than ``timeout_s`` at
   the start of the step is in fallback for the step (``comm_timeout`` / ``comm_restored``
   events). Views: the newest state predicted to the present (comm/predict.py); in fallback a
   virtual car re-anchored at the member itself (its slot's offset taken off), at the speed it
   had when it timed out, with no acceleration or turning: the member holds its lane (road:
   the slot's lateral offset; free space: its heading) and its speed.
2. :meth:`caps` adds, for members in fallback, the time gap to formation members ahead of
   them (SUMO's vehicles ahead are already in the governor's caps of road runs).
3. :meth:`signals` and :meth:`step` run sim/fast_comm.py's kernels on the views.

:class:`RoadChannel` (SUMO runs: views along the reference line) and :class:`FreeChannel`
(free space: planar views) differ only in the state they carry and predict.
"""
from __future__ import annotations

import math

import numpy as np

from ..comm.channel import Channel, build_channel, link_params
from . import fast_comm as fc
from .fast import FastFleet, _f64
from .fleet import FleetState
from .governor import member_speed_cap, time_gap_accel, vehicles_ahead
from .integrate import substeps


class _ChannelBase:
    width = 0  # state carried by a beacon

    def __init__(self, ff: FastFleet, channel: Channel, member_ids, n_ctrl: int, dt_c: float,
                 timeout_s: float, veh, leader_spec):
        n = len(member_ids)
        self.ff, self.ch, self.ids = ff, channel, list(member_ids)
        self.n_ctrl, self.dt_c, self.timeout = int(n_ctrl), float(dt_c), float(timeout_s)
        self.veh, self.ld = veh, leader_spec
        self.beacons = np.zeros((len(channel.send), self.width))
        self.truth = np.zeros((n_ctrl + 1, self.width))
        self.nxt = np.zeros(1, dtype=np.int64)
        self.ptr = np.zeros(n, dtype=np.int64)
        self.NB = np.zeros((n_ctrl, n), dtype=np.int64)
        self.AGE = np.zeros((n_ctrl, n))
        self.V = np.zeros((n_ctrl, n, self.width))
        self.fb = np.zeros(n, dtype=np.bool_)
        self.fb_state = np.zeros((n, self.width))
        self.v_hold = np.zeros(n)

    @classmethod
    def build(cls, sc, ff: FastFleet, n_ctrl: int, dt_c: float, veh, **kw):
        ids = [m.id for m in sc.members]
        ch = build_channel([link_params(sc.comm, i) for i in ids], sc.run.seed, sc.run.duration,
                           sc.run.control_step, sc.comm.beacon_hz)
        return cls(ff, ch, ids, n_ctrl, dt_c, sc.comm.timeout_s, veh, sc.leader, **kw)

    def _ages(self, k: int, t: float, v_m, active, rec) -> np.ndarray:
        """Beacons of the step and each member's newest; time-outs. Truth rows filled."""
        fc.channel_instants_nb(self.truth[:self.n_ctrl], self.dt_c, k * self.n_ctrl, self.ch.send,
                               self.beacons, self.nxt, self.ch.arrival_sorted,
                               self.ch.newest_sorted, self.ptr, self.NB, self.AGE)
        age = self.AGE[0].copy()
        late = (age > self.timeout) & active
        for i in np.flatnonzero(late & ~self.fb):
            self.v_hold[i] = v_m[i]
            rec.add_event(t, "comm_timeout", self.ids[i], "",
                          f"no virtual-car state for {age[i]:.2f} s (time-out {self.timeout:g} s): "
                          f"holds its lane at {v_m[i]:.1f} m/s")
        for i in np.flatnonzero(~late & self.fb & active):
            rec.add_event(t, "comm_restored", self.ids[i], "", f"virtual-car state {age[i]:.2f} s old")
        self.fb[:] = late
        return age

    def _gap_caps(self, v_cap, a_cap, along, across, heading_ok, v_m, active, decel_emergency):
        """Caps of the fallback members from the members ahead: ``along`` / ``across`` (n, n)
        position of member j in member i's frame [m]."""
        v_cap, a_cap = np.array(v_cap, float), np.array(a_cap, float)
        d_front = self.veh.cog_to_front_bumper
        half_w = np.full(1, self.veh.width / 2)
        for i in np.flatnonzero(self.fb & active):
            o = active & heading_ok[i]
            o[i] = False
            gap, v_lead, _ = vehicles_ahead(np.full(1, d_front), np.zeros(1), half_w,
                                            along[i, o] - (self.veh.length - d_front), across[i, o],
                                            np.full(int(o.sum()), self.veh.width / 2), v_m[o])
            v_cap[i] = min(v_cap[i], member_speed_cap(gap, v_lead, self.ld.time_gap, self.ld.min_gap)[0])
            a_law = time_gap_accel(gap, v_m[i:i + 1], v_lead, self.ld.time_gap, self.ld.min_gap)[0]
            a_cap[i] = min(a_cap[i], max(a_law, -decel_emergency))
        return v_cap, a_cap


class RoadChannel(_ChannelBase):
    """Views (s, v, a) along the reference line (SUMO runs)."""

    width = fc.ROAD_STATE

    def __init__(self, *args, along=None):
        super().__init__(*args)
        self.along = np.asarray(along, float)  # slot (or offset) ahead of the virtual car [m]

    @classmethod
    def for_road(cls, sc, plan, ff: FastFleet, n_ctrl: int, dt_c: float) -> "RoadChannel":
        along = np.where(plan.is_road, plan.slots[:, 0], plan.rigid[:, 0])
        return cls.build(sc, ff, n_ctrl, dt_c, plan.veh, along=along)

    def update(self, k, t, s_vc, v_vc, a_vc, m_s, v_m, active, rec) -> np.ndarray:
        """Step k (time t [s]) with the true virtual car (s_vc [m], v_vc [m/s], a_vc [m/s^2]):
        fills the views; returns each member's leader age at t [s]."""
        fc.road_truth_nb(float(s_vc), float(v_vc), float(a_vc), self.dt_c, self.truth)
        age = self._ages(k, t, v_m, active, rec)
        self.fb_state[:, 0] = m_s - self.along
        self.fb_state[:, 1] = self.v_hold
        fc.road_views_nb(self.NB, self.AGE, self.beacons, self.fb, self.fb_state, self.dt_c, self.V)
        return age

    def caps(self, v_cap, a_cap, m_s, m_d, v_m, active, decel_emergency: float):
        """Members in fallback also keep the time gap to formation members ahead of them."""
        if not self.fb.any():
            return v_cap, a_cap
        along = m_s[None, :] - m_s[:, None]
        across = m_d[None, :] - m_d[:, None]
        ok = np.ones((len(m_s), len(m_s)), dtype=bool)
        return self._gap_caps(v_cap, a_cap, along, across, ok, v_m, active, decel_emergency)

    def signals(self, state, v_cap, a_cap, out: np.ndarray) -> np.ndarray:
        """FastFleet.signals with each member's control from its view at the step's start."""
        ff = self.ff
        v_cap, a_cap = ff._caps(v_cap, a_cap)
        fc.record_views_nb(_f64(state.x), _f64(state.theta_star), _f64(state.speed_in),
                           ff.model_kind, ff.P, ff.k, ff.k_theta, ff.C, ff.line.G, ff.slots,
                           ff.rigid, ff.is_road, self.truth[0], self.V[0], v_cap, a_cap, ff.cols, out)
        return out

    def step(self, state, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c: float, n_ctrl: int):
        """FastFleet.step on the views: (FleetState, s_vc, v_vc) after the step."""
        ff = self.ff
        v_cap, a_cap = ff._caps(v_cap, a_cap)
        x, ts, sp = fc.step_views_nb(
            _f64(state.x), _f64(state.theta_star), _f64(state.speed_in), ff.model_kind, ff.P, ff.k,
            ff.k_theta, ff.C, ff.line.G, ff.slots, ff.rigid, ff.is_road, self.V, v_cap, a_cap,
            float(dt_c), substeps(dt_c, ff.cfg.physics_step))
        return FleetState(x, ts, sp), float(self.truth[n_ctrl, 0]), float(self.truth[n_ctrl, 1])


class FreeChannel(_ChannelBase):
    """Planar views (x, y, theta, v, omega, v_dot, omega_dot) in free space."""

    width = fc.FREE_STATE

    def update(self, k, t, pose, pos, heading, v_m, rec) -> np.ndarray:
        """Step k from time t [s] with the leader's pose (x, y, theta); members at ``pos``
        (n, 2) [m] with ``heading`` (n,) [rad] and speed v_m [m/s]. Returns the leader ages [s]."""
        ff = self.ff
        fc.free_truth_nb(ff.profiles, float(t), _f64(pose), self.dt_c,
                         substeps(self.dt_c, ff.leader_max_step), self.truth)
        active = np.ones(len(self.ids), dtype=bool)
        age = self._ages(k, t, v_m, active, rec)
        c, s = np.cos(heading), np.sin(heading)
        dx, dy = ff.rigid[:, 0], ff.rigid[:, 1]
        st = self.fb_state
        st[:, 0] = pos[:, 0] - (dx * c - dy * s)
        st[:, 1] = pos[:, 1] - (dx * s + dy * c)
        st[:, 2] = heading
        st[:, 3] = self.v_hold
        st[:, 4:] = 0.0
        fc.free_views_nb(self.NB, self.AGE, self.beacons, self.fb, st, self.dt_c, self.V)
        return age

    def caps(self, pos, heading, v_m, decel_emergency: float):
        """(v_cap, a_cap): members in fallback keep the time gap to members ahead along their
        heading (+inf otherwise, as free space has no other caps)."""
        n = len(self.ids)
        inf = np.full(n, np.inf)
        if not self.fb.any():
            return inf, inf
        rel = pos[None, :, :] - pos[:, None, :]  # [i, j]: j seen from i
        c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
        along = rel[..., 0] * c + rel[..., 1] * s
        across = -rel[..., 0] * s + rel[..., 1] * c
        same_way = np.cos(heading[None, :] - heading[:, None]) > math.cos(math.radians(45.0))
        return self._gap_caps(inf, inf, along, across, same_way, v_m, np.ones(n, bool),
                              decel_emergency)

    def signals(self, state, out: np.ndarray) -> np.ndarray:
        ff = self.ff
        fc.record_free_views_nb(_f64(state.x), _f64(state.theta_star), _f64(state.speed_in),
                                ff.model_kind, ff.P, ff.k, ff.k_theta, ff.C, ff.rigid,
                                self.truth[0], self.V[0], ff.cols, out)
        return out

    def step(self, state, v_cap, a_cap, dt_c: float, n_ctrl: int):
        """One free-space step on the views: (FleetState, pose after the step)."""
        ff = self.ff
        x, ts, sp = fc.step_free_views_nb(
            _f64(state.x), _f64(state.theta_star), _f64(state.speed_in), ff.model_kind, ff.P, ff.k,
            ff.k_theta, ff.C, ff.rigid, self.V, _f64(v_cap), _f64(a_cap), float(dt_c),
            substeps(dt_c, ff.cfg.physics_step))
        last = self.truth[n_ctrl]
        return FleetState(x, ts, sp), (float(last[0]), float(last[1]), float(last[2]))
