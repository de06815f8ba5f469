"""The channel as a transform of the step's Reference (control/reference.py, docs/architecture.md).

:class:`CommChannel` replaces each member's copy of the virtual car, ``ref.vc[j, i]``, by the
member's view: the newest beacon it holds predicted to the present (comm/predict.py), or its
fallback. Per step (sim/loop.py):

1. :meth:`CommChannel.sense` (before the transform runs) hands it what the world sensed and
   the members' state: where they are, for the fallback and its gaps, and where to record
   ``leader_age_s`` and the events;
2. :meth:`CommChannel.__call__` stores the true virtual car of every beacon sent during the step
   (the generator's rows, identical for every member), finds the newest beacon each member
   holds at each control instant and its age (comm/channel.py); a member whose newest state
   is older than ``timeout_s`` at the start of the step is in fallback for the step
   (``comm_timeout`` / ``comm_restored`` events). In fallback it follows a virtual car of its
   own re-anchored at itself (its slot's offset taken off), at the speed it had when it timed
   out, with no acceleration or turning: it holds its lane (free space: its heading) and its
   speed, and keeps the time gap to formation members ahead of it (the caps of the reference;
   SUMO's vehicles ahead are in them already).

On a road a beacon is the virtual car along the reference line (s, v, a = v_dot) and the view
is recomputed from the line at the predicted s; in free space (s is NaN) it is the pose,
predicted with turn rate and acceleration held. With perfect communication every view is the
true row, bit for bit. No kernel changes: the loop records the formation error against the
true virtual car (sim/loop.py).
"""
from __future__ import annotations

import math

import numpy as np

from ..control.governor import member_caps, vehicles_ahead
from ..control.reference import Reference
from ..control.virtual_car import along_line_advance
from ..core.kernels import kernel
from ..road.leader import road_leader_at
from .channel import Channel
from .predict import predict_planar

N_VC = 8  # x, y, theta, v, omega, v_dot, omega_dot, s (control/reference.py VC_FIELDS)


@kernel
def channel_instants(truth, dt_c, c0, send, beacons, nxt, arr_sorted, newest_sorted, ptr, NB,
                     AGE):
    """Control instants c0 .. c0 + n_ctrl - 1 of one step (``truth`` (n_ctrl, 8): the true
    virtual car at each): store every beacon sent (row b of ``beacons``; ``nxt[0]`` the next
    to send), then the newest beacon each member holds (NB (n_ctrl, n)) and its age [s] (AGE).
    ``ptr`` (n,) keeps each member's place in its sorted arrivals (comm/channel.py Channel)."""
    n = ptr.shape[0]
    B = send.shape[0]
    for j in range(truth.shape[0]):
        c = c0 + j
        while nxt[0] < B and send[nxt[0]] <= c:
            for q in range(truth.shape[1]):
                beacons[nxt[0], q] = truth[j, q]
            nxt[0] += 1
        for i in range(n):
            p = ptr[i]
            while p < B and arr_sorted[i, p] <= c:
                p += 1
            ptr[i] = p
            b = newest_sorted[i, p - 1]
            NB[j, i] = b
            AGE[j, i] = (c - send[b]) * dt_c


@kernel
def _view_row(G, src, tau, road, out):
    """The virtual car ``src`` (8,) predicted tau [s] later into out (8,)."""
    if road:
        s, v = along_line_advance(src[7], src[3], src[5], tau)
        if tau == 0.0:
            for q in range(8):
                out[q] = src[q]
            return
        out[0], out[1], out[2], out[3], out[4], out[5], out[6] = road_leader_at(G, s, v, src[5])
        out[7] = s
        return
    out[0], out[1], out[2], out[3] = predict_planar(src[0], src[1], src[2], src[3], src[4],
                                                    src[5], tau)
    for q in range(4, 8):
        out[q] = src[q]


@kernel
def views(G, road, NB, AGE, beacons, fb, fb_rows, dt_c, vc):
    """Every member's view at every period into vc (n_ctrl, n, 8): its newest beacon
    predicted over its age, or in fallback its own virtual car fb_rows[i] moving on."""
    for j in range(NB.shape[0]):
        for i in range(NB.shape[1]):
            if fb[i]:
                _view_row(G, fb_rows[i], j * dt_c, road, vc[j, i])
            else:
                _view_row(G, beacons[NB[j, i]], AGE[j, i], road, vc[j, i])


class CommChannel:
    """The [comm] channel of a run as a Reference transform (see the module docstring)."""

    error_against_truth = True  # the loop records ex .. y_des against the true virtual car

    def __init__(self, channel: Channel, member_ids, n_ctrl: int, timeout_s: float, veh, ld,
                 law_fallback: bool = True):
        n = len(member_ids)
        self.law_fallback = bool(law_fallback)  # CACC members fall back to ACC (sim/loop.py)
        self.ch, self.ids = channel, list(member_ids)
        self.n_ctrl, self.timeout = int(n_ctrl), float(timeout_s)
        self.veh, self.ld = veh, ld
        self.beacons = np.zeros((len(channel.send), N_VC))
        self.nxt = np.zeros(1, dtype=np.int64)
        self.ptr = np.zeros(n, dtype=np.int64)
        self.NB = np.zeros((n_ctrl, n), dtype=np.int64)
        self.AGE = np.zeros((n_ctrl, n))
        self.fb = np.zeros(n, dtype=np.bool_)
        self.fb_rows = np.zeros((n, N_VC))
        self.v_hold = np.zeros(n)
        self._seen = None

    def sense(self, k: int, t: float, sensed, kin, rec) -> None:
        """What the world sensed at step k (time t [s]); ``kin`` the members' (pos (n, 2) [m],
        velocity (n, 2) [m/s], heading (n,) [rad]); ``rec`` the run's Recorder."""
        self._seen = (k, t, sensed, kin, rec)

    def __call__(self, ref: Reference) -> Reference:
        k, t, sensed, (pos, vel, heading), rec = self._seen
        v_m = np.hypot(vel[:, 0], vel[:, 1])
        truth = np.ascontiguousarray(ref.vc[:, 0, :])
        channel_instants(truth, ref.dt, k * self.n_ctrl, self.ch.send, self.beacons, self.nxt,
                         self.ch.arrival_sorted, self.ch.newest_sorted, self.ptr, self.NB, self.AGE)
        age = self.AGE[0].copy()
        self._timeouts(t, age, v_m, ref.active, rec)
        road = bool(np.isfinite(truth[0, 7]))
        self._anchor(ref, road, sensed, pos, heading)
        vc = np.empty_like(ref.vc)
        views(ref.line, road, self.NB, self.AGE, self.beacons, self.fb, self.fb_rows, ref.dt, vc)
        sensed.extra["leader_age_s"] = age
        v_cap, a_cap, cap_from = ref.v_cap, ref.a_cap, ref.a_cap_from
        if self.fb.any():
            v_cap, a_cap = self._gap_caps(ref, road, sensed, pos, heading, v_m)
            if cap_from is not None:  # a cap tightened here holds from the step's start
                cap_from = np.minimum(cap_from, a_cap)
        return ref.with_(vc=vc, v_cap=v_cap, a_cap=a_cap, a_cap_from=cap_from)

    def timed_out(self) -> np.ndarray:
        """(n,) bools: the members whose newest state is older than ``timeout_s`` this step."""
        return self.fb

    def _timeouts(self, t, age, v_m, active, rec) -> None:
        late = (age > self.timeout) & active
        for i in np.flatnonzero(late & ~self.fb):
            self.v_hold[i] = v_m[i]
            rec.add_event(t, "comm_timeout", self.ids[i], "",
                          f"no virtual-car state for {age[i]:.2f} s (time-out {self.timeout:g} s): "
                          f"holds its lane at {v_m[i]:.1f} m/s")
        for i in np.flatnonzero(~late & self.fb & active):
            rec.add_event(t, "comm_restored", self.ids[i], "", f"virtual-car state {age[i]:.2f} s old")
        self.fb[:] = late

    def _anchor(self, ref, road, sensed, pos, heading) -> None:
        """Fallback rows: a virtual car at the member minus its slot's offset, at the held
        speed, not accelerating or turning."""
        rows = self.fb_rows
        for i in np.flatnonzero(self.fb):
            dx, dy = ref.slots[0, i, 0], ref.slots[0, i, 1]
            if road:
                rows[i] = [0.0, 0.0, 0.0, self.v_hold[i], 0.0, 0.0, 0.0, sensed.m_s[i] - dx]
            else:
                c, s = math.cos(heading[i]), math.sin(heading[i])
                rows[i] = [pos[i, 0] - (dx * c - dy * s), pos[i, 1] - (dx * s + dy * c),
                           heading[i], self.v_hold[i], 0.0, 0.0, 0.0, np.nan]

    def _gap_caps(self, ref, road, sensed, pos, heading, v_m):
        """Caps of the fallback members from the formation members ahead of them."""
        if road:
            along = sensed.m_s[None, :] - sensed.m_s[:, None]
            across = sensed.m_d[None, :] - sensed.m_d[:, None]
            same_way = np.ones(along.shape, dtype=bool)
        else:
            rel = pos[None, :, :] - pos[:, None, :]  # [i, j]: j seen from i
            c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
            along = rel[..., 0] * c + rel[..., 1] * s
            across = -rel[..., 0] * s + rel[..., 1] * c
            same_way = np.cos(heading[None, :] - heading[:, None]) > math.cos(math.radians(45.0))
        v_cap, a_cap = np.array(ref.v_cap, float), np.array(ref.a_cap, float)
        veh, ld = self.veh, self.ld
        d_front = veh.cog_to_front_bumper
        for i in np.flatnonzero(self.fb & ref.active):
            o = ref.active & same_way[i]
            o[i] = False
            gap, v_lead, _ = vehicles_ahead(np.full(1, d_front), np.zeros(1), np.full(1, veh.width / 2),
                                            along[i, o] - (veh.length - d_front), across[i, o],
                                            np.full(int(o.sum()), veh.width / 2), v_m[o])
            vc_i, ac_i = member_caps(float(gap[0]), float(v_lead[0]), float(v_m[i]), float(ld.time_gap),
                                     float(ld.min_gap), float(ld.decel_emergency))
            v_cap[i], a_cap[i] = min(v_cap[i], vc_i), min(a_cap[i], ac_i)
        return v_cap, a_cap


def warm_kernels() -> None:
    """Compile (or load) this module's kernels for the argument types a [comm] run passes,
    on zero members (sim/warm.py: one compilation covers every scenario kind)."""
    i1, f2 = np.zeros(1, dtype=np.int64), np.zeros((0, N_VC))
    i2 = np.zeros((1, 0), dtype=np.int64)
    channel_instants(np.zeros((1, N_VC)), 0.01, 0, np.zeros(0, dtype=np.int64), f2, i1, i2, i2,
                     np.zeros(0, dtype=np.int64), i2, np.zeros((1, 0)))
    views(np.zeros(1), False, i2, np.zeros((1, 0)), f2, np.zeros(0, dtype=np.bool_), f2, 0.01,
          np.zeros((1, 0, N_VC)))
