"""Compiled step with a per-member view of the virtual car (the communication channel).

Without a channel every member's targets come from the one true virtual-car state
(sim/fast.py ``step_periods_nb``). With one (sim/comm_link.py), member i at control period j
sees its own state (VS[j, i] [m], VV[j, i] [m/s], VA[j, i] [m/s^2]) along the reference line:
the newest beacon it holds, predicted to the present (comm/predict.py), or its fallback. The
kernels below are ``step_periods_nb`` / ``record_signals_nb`` with that one change; they
reuse fast.py's scalar laws. With every view equal to the true state they give the same
numbers bit for bit. The recorded formation error (ex, ey, e_lon, e_lat, x_des, y_des) is
always measured against the true virtual car; v_ref and omega_ref are what the member
commanded from its view.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from numba import njit

from ..models import bicycle_fast
from ..road import fast_line
from ..road.fast_line import frame_at
from . import fast
from .fast import (N_T, _Q_E_LAT, _Q_E_LON, _Q_EX, _Q_EY, _Q_X_DES, _Q_Y_DES, _advance_members,
                   _advance_vc, _control_at, _road_leader, _road_target, _rigid_target,
                   _signal_rows, mixed_targets_nb)


@njit(cache=True, error_model="numpy")
def _view_target(G, s, v, a, is_road, slot_x, slot_y, rig_x, rig_y):
    """Desired (p, v, a) of one member from its view (s, v, a) of the virtual car."""
    if is_road:
        return _road_target(G, s, v, a, slot_x, slot_y)
    X, Y, th, vv, om, vd, omd = _road_leader(G, s, v, a)
    return _rigid_target(X, Y, th, vv, om, vd, omd, rig_x, rig_y)


@njit(cache=True, error_model="numpy")
def channel_instants_nb(s0, v0, a, dt_c, n_ctrl, c0, send, bs, bv, ba, nxt, arr_sorted,
                        newest_sorted, ptr, NB, AGE):
    """Control instants c0 .. c0 + n_ctrl - 1 of one step: store the true state (s, v, a) of
    every beacon sent (bs, bv, ba at its index; ``nxt[0]`` the next beacon to send), then the
    newest beacon each member holds (NB (n_ctrl, n)) and its age [s] (AGE). ``ptr`` (n,) keeps
    each member's place in its sorted arrivals (comm/channel.py Channel)."""
    n = ptr.shape[0]
    B = send.shape[0]
    s = s0
    v = v0
    for j in range(n_ctrl):
        c = c0 + j
        while nxt[0] < B and send[nxt[0]] <= c:
            b = nxt[0]
            bs[b] = s
            bv[b] = v
            ba[b] = a
            nxt[0] = b + 1
        for i in range(n):
            p = ptr[i]
            while p < B and arr_sorted[i, p] <= c:
                p += 1
            ptr[i] = p
            b = newest_sorted[i, p - 1]
            NB[j, i] = b
            AGE[j, i] = (c - send[b]) * dt_c
        s, v = _advance_vc(s, v, a, dt_c)


@njit(cache=True, error_model="numpy")
def views_nb(NB, AGE, bs, bv, ba, fb, fb_s, fb_v, dt_c, VS, VV, VA):
    """Each member's view at each period: its newest beacon predicted over its age
    (comm/predict.py), or, in fallback, (fb_s, fb_v) moving on at constant speed."""
    for j in range(NB.shape[0]):
        for i in range(NB.shape[1]):
            if fb[i]:
                VS[j, i], VV[j, i] = _advance_vc(fb_s[i], fb_v[i], 0.0, j * dt_c)
                VA[j, i] = 0.0
            else:
                b = NB[j, i]
                VS[j, i], VV[j, i] = _advance_vc(bs[b], bv[b], ba[b], AGE[j, i])
                VA[j, i] = ba[b]


@njit(cache=True, error_model="numpy")
def step_views_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, G, slots, rigid,
                  is_road, s_vc, v_vc, a_vc, VS, VV, VA, v_cap, a_cap, dt_c, n_ctrl, n_sub):
    """fast.step_periods_nb with member i's targets at period j from (VS, VV, VA)[j, i].
    Returns (x, theta_star, speed_in, s_vc, v_vc) after the step (true virtual car)."""
    n = x.shape[0]
    theta_star = theta_star.copy()
    speed_in = speed_in.copy()
    U = np.empty((n, 2))
    tsd = np.empty(n)
    for j in range(n_ctrl):
        for i in range(n):
            px, py, tvx, tvy, tax, tay = _view_target(G, VS[j, i], VV[j, i], VA[j, i], is_road[i],
                                                      slots[i, 0], slots[i, 1], rigid[i, 0],
                                                      rigid[i, 1])
            U[i, 0], U[i, 1], _, _, tsd[i], _, _, _, _, _, _ = _control_at(
                i, x, theta_star, speed_in, model_kind, k, k_theta, C, px, py, tvx, tvy, tax,
                tay, v_cap[i], a_cap[i])
        x = _advance_members(x, theta_star, speed_in, U, tsd, model_kind, P, dt_c, n_sub)
        s_vc, v_vc = _advance_vc(s_vc, v_vc, a_vc, dt_c)
    return x, theta_star, speed_in, s_vc, v_vc


@njit(cache=True, error_model="numpy")
def record_views_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, G, slots, rigid,
                    is_road, s_vc, v_vc, a_vc, vs, vv, va, v_cap, a_cap, cols, out):
    """fast.record_signals_nb with the control from each member's view (vs, vv, va) (n,) and
    the formation error against the true virtual car (s_vc, v_vc, a_vc)."""
    n = x.shape[0]
    T = np.empty((n, N_T))
    for i in range(n):
        T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _view_target(
            G, vs[i], vv[i], va[i], is_road[i], slots[i, 0], slots[i, 1], rigid[i, 0], rigid[i, 1])
    vc_theta = frame_at(G, s_vc)[4]
    _signal_rows(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, v_cap, a_cap,
                 vc_theta, cols, out)
    Tt = mixed_targets_nb(G, slots, rigid, is_road, s_vc, v_vc, a_vc)
    c = np.cos(vc_theta)
    s = np.sin(vc_theta)
    for i in range(n):
        ex = Tt[i, 0] - x[i, 0]
        ey = Tt[i, 1] - x[i, 1]
        _put(out, i, cols[_Q_EX], ex)
        _put(out, i, cols[_Q_EY], ey)
        _put(out, i, cols[_Q_E_LON], c * ex + s * ey)
        _put(out, i, cols[_Q_E_LAT], -s * ex + c * ey)
        _put(out, i, cols[_Q_X_DES], Tt[i, 0])
        _put(out, i, cols[_Q_Y_DES], Tt[i, 1])


@njit(cache=True, error_model="numpy")
def _put(out, i, col, val):
    if col >= 0:
        out[i, col] = val


# ------------------------------------------------------------ numba cache maintenance

def _check_digest() -> None:
    """Numba keys this module's cache on this file only: drop it when a file whose compiled
    functions these kernels call changed (as fast.py does for its own kernels)."""
    try:
        h = hashlib.sha256()
        for p in (Path(fast.__file__), Path(fast_line.__file__), Path(bicycle_fast.__file__),
                  Path(__file__)):
            h.update(p.read_bytes())
        digest = h.hexdigest()
        cache_dir = Path(step_views_nb._cache.cache_path)
        stamp = cache_dir / "fast_comm_kernels.digest"
        if (stamp.read_text().strip() if stamp.exists() else None) != digest:
            for d in (_view_target, _put, channel_instants_nb, views_nb, step_views_nb, record_views_nb):
                d._cache.flush()
            cache_dir.mkdir(parents=True, exist_ok=True)
            stamp.write_text(digest)
    except Exception:  # pragma: no cover - read-only tree etc.
        pass


_check_digest()
