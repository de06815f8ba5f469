"""The channel as a transformer of the virtual car's state into each member's view.

Built from [comm] (docs/communication.md) for a SUMO run. Per SUMO step:

1. :meth:`ChannelReference.update` stores the true state of every beacon the virtual leader
   sends during the step, finds the newest beacon each member holds at each control instant
   (comm/channel.py), and its age; a member whose newest state is older than ``timeout_s`` at
   the start of the step is in fallback for the step (``comm_timeout`` / ``comm_restored``
   events). Views: the newest state predicted to the present (comm/predict.py); in fallback a
   virtual car re-anchored at the member's own arc length, at the speed it had when it timed
   out, with no acceleration: the member holds its slot's lane and its speed.
2. :meth:`ChannelReference.caps` adds, for members in fallback, the time gap to formation
   members ahead of them (SUMO's vehicles ahead are already in the governor's caps).
3. :meth:`signals` and :meth:`step` run sim/fast_comm.py's kernels on the views.
"""
from __future__ import annotations

import numpy as np

from ..comm.channel import Channel, build_channel, link_params
from .fast import FastFleet, _f64
from .fleet import FleetState
from .fast_comm import channel_instants_nb, record_views_nb, step_views_nb, views_nb
from .governor import member_speed_cap, time_gap_accel, vehicles_ahead
from .integrate import substeps


class ChannelReference:
    """Each member's view of the virtual car through the channel (see the module docstring)."""

    def __init__(self, ff: FastFleet, channel: Channel, member_ids: list[str], along: np.ndarray,
                 n_ctrl: int, dt_c: float, timeout_s: float, veh, leader_spec):
        n = len(member_ids)
        self.ff, self.ch, self.ids = ff, channel, list(member_ids)
        self.along = np.asarray(along, float)  # slot (or offset) ahead of the virtual car [m]
        self.n_ctrl, self.dt_c, self.timeout = int(n_ctrl), float(dt_c), float(timeout_s)
        self.veh, self.ld = veh, leader_spec
        B = len(channel.send)
        self.bs, self.bv, self.ba = np.zeros(B), np.zeros(B), np.zeros(B)
        self.nxt = np.zeros(1, dtype=np.int64)
        self.ptr = np.zeros(n, dtype=np.int64)
        self.NB = np.zeros((n_ctrl, n), dtype=np.int64)
        self.AGE, self.VS, self.VV, self.VA = (np.zeros((n_ctrl, n)) for _ in range(4))
        self.fb = np.zeros(n, dtype=np.bool_)
        self.fb_s, self.fb_v = np.zeros(n), np.zeros(n)

    @classmethod
    def build(cls, sc, plan, ff: FastFleet, n_ctrl: int, dt_c: float) -> "ChannelReference":
        ids = [m.id for m in sc.members]
        links = [link_params(sc.comm, i) for i in ids]
        ch = build_channel(links, sc.run.seed, sc.run.duration, sc.run.control_step, sc.comm.beacon_hz)
        along = np.where(plan.is_road, plan.slots[:, 0], plan.rigid[:, 0])
        return cls(ff, ch, ids, along, n_ctrl, dt_c, sc.comm.timeout_s, plan.veh, sc.leader)

    def update(self, k: int, t: float, s_vc: float, v_vc: float, a_vc: float, m_s, v_m, active,
               rec) -> np.ndarray:
        """Step k (time t [s]) with the true virtual car (s_vc [m], v_vc [m/s], a_vc [m/s^2]):
        fills the views; returns each member's leader age at t [s]."""
        channel_instants_nb(float(s_vc), float(v_vc), float(a_vc), self.dt_c, self.n_ctrl,
                            k * self.n_ctrl, self.ch.send, self.bs, self.bv, self.ba, self.nxt,
                            self.ch.arrival_sorted, self.ch.newest_sorted, self.ptr, self.NB,
                            self.AGE)
        age = self.AGE[0].copy()
        late = (age > self.timeout) & active
        for i in np.flatnonzero(late & ~self.fb):
            self.fb_v[i] = v_m[i]
            rec.add_event(t, "comm_timeout", self.ids[i], "",
                          f"no virtual-car state for {age[i]:.2f} s (time-out {self.timeout:g} s): "
                          f"holds its lane at {v_m[i]:.1f} m/s")
        for i in np.flatnonzero(~late & self.fb & active):
            rec.add_event(t, "comm_restored", self.ids[i], "", f"virtual-car state {age[i]:.2f} s old")
        self.fb[:] = late
        self.fb_s[late] = m_s[late] - self.along[late]
        views_nb(self.NB, self.AGE, self.bs, self.bv, self.ba, self.fb, self.fb_s, self.fb_v,
                 self.dt_c, self.VS, self.VV, self.VA)
        return age

    def caps(self, v_cap, a_cap, m_s, m_d, v_m, active, decel_emergency: float):
        """Members in fallback also keep the time gap to formation members ahead of them."""
        if not self.fb.any():
            return v_cap, a_cap
        v_cap, a_cap = np.array(v_cap, float), np.array(a_cap, float)
        d_front = self.veh.cog_to_front_bumper
        half_w = np.full(len(m_s), self.veh.width / 2)
        for i in np.flatnonzero(self.fb & active):
            o = active.copy()
            o[i] = False
            gap, v_lead, _ = vehicles_ahead(m_s[i:i + 1] + d_front, m_d[i:i + 1], half_w[i:i + 1],
                                            m_s[o] - (self.veh.length - d_front), m_d[o], half_w[o], v_m[o])
            v_cap[i] = min(v_cap[i], member_speed_cap(gap, v_lead, self.ld.time_gap, self.ld.min_gap)[0])
            a_law = time_gap_accel(gap, v_m[i:i + 1], v_lead, self.ld.time_gap, self.ld.min_gap)[0]
            a_cap[i] = min(a_cap[i], max(a_law, -decel_emergency))
        return v_cap, a_cap

    def signals(self, state, s_vc, v_vc, a_vc, v_cap, a_cap, out: np.ndarray) -> np.ndarray:
        """FastFleet.signals with each member's control from its view at the step's start."""
        ff = self.ff
        v_cap, a_cap = ff._caps(v_cap, a_cap)
        record_views_nb(_f64(state.x), _f64(state.theta_star), _f64(state.speed_in), ff.model_kind,
                        ff.P, ff.k, ff.k_theta, ff.C, ff.line.G, ff.slots, ff.rigid, ff.is_road,
                        float(s_vc), float(v_vc), float(a_vc), self.VS[0], self.VV[0], self.VA[0],
                        v_cap, a_cap, ff.cols, out)
        return out

    def step(self, state, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c: float, n_ctrl: int):
        """FastFleet.step on the views: (FleetState, s_vc, v_vc) after the step."""
        ff = self.ff
        v_cap, a_cap = ff._caps(v_cap, a_cap)
        x, ts, sp, s_vc, v_vc = step_views_nb(
            _f64(state.x), _f64(state.theta_star), _f64(state.speed_in), ff.model_kind, ff.P, ff.k,
            ff.k_theta, ff.C, ff.line.G, ff.slots, ff.rigid, ff.is_road, float(s_vc), float(v_vc),
            float(a_vc), self.VS, self.VV, self.VA, v_cap, a_cap, float(dt_c), int(n_ctrl),
            substeps(dt_c, ff.cfg.physics_step))
        return FleetState(x, ts, sp), s_vc, v_vc
