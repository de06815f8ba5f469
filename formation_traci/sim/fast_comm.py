"""Compiled step with a per-member view of the virtual car (the communication channel).

Without a channel every member's targets come from the one true virtual-car state
(sim/fast.py ``step_periods_nb`` / ``step_free_nb``). With one (sim/comm_link.py) member i at
control period j sees its own virtual car: the newest beacon it holds predicted to the present
(comm/predict.py), or its fallback. Views:

* road runs: (s [m], v [m/s], a [m/s^2]) along the reference line, V[j, i, 0:3];
* free space: (x, y [m], theta [rad], v [m/s], omega [rad/s], v_dot [m/s^2], omega_dot
  [rad/s^2]), V[j, i, 0:7].

A beacon carries the true state in the same layout (``truth`` rows, one per control period
of the step). The kernels below are fast.py's step and signal kernels with that one change,
built from fast.py's scalar laws; with every view equal to the true state they give the same
numbers bit for bit. The recorded formation error (ex, ey, e_lon, e_lat, x_des, y_des) is
always measured against the true virtual car; v_ref and omega_ref are what the member
commanded from its view.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from numba import njit

from ..comm.predict import predict_planar
from ..models import bicycle_fast
from ..road import fast_line
from ..road.fast_line import frame_at
from . import fast
from .fast import (N_T, _Q_E_LAT, _Q_E_LON, _Q_EX, _Q_EY, _Q_X_DES, _Q_Y_DES, _advance_members,
                   _advance_vc, _control_at, _free_leader_advance, _profile, _road_leader,
                   _road_target, _rigid_target, _signal_rows, mixed_targets_nb)

ROAD_STATE = 3
"""Width of a road view / beacon: s, v, a."""
FREE_STATE = 7
"""Width of a free-space view / beacon: x, y, theta, v, omega, v_dot, omega_dot."""


# ---------------------------------------------------------------- channel bookkeeping

@njit(cache=True, error_model="numpy")
def channel_instants_nb(truth, dt_c, c0, send, beacons, nxt, arr_sorted, newest_sorted, ptr,
                        NB, AGE):
    """Control instants c0 .. c0 + n_ctrl - 1 of one step (``truth`` (n_ctrl, m): the true
    state at each): store the state of every beacon sent (row b of ``beacons``; ``nxt[0]`` the
    next beacon to send), then the newest beacon each member holds (NB (n_ctrl, n)) and its
    age [s] (AGE). ``ptr`` (n,) keeps each member's place in its sorted arrivals
    (comm/channel.py Channel)."""
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


@njit(cache=True, error_model="numpy")
def road_truth_nb(s, v, a, dt_c, truth):
    """The virtual car along the line at every control period of the step: truth (n_ctrl, 3)."""
    for j in range(truth.shape[0]):
        truth[j, 0] = s
        truth[j, 1] = v
        truth[j, 2] = a
        s, v = _advance_vc(s, v, a, dt_c)


@njit(cache=True, error_model="numpy")
def free_truth_nb(prof, t, pose, dt_c, n_sub_leader, truth):
    """The free virtual car at every control period of the step from t (as fast.step_free_nb
    computes it): truth (n_ctrl + 1, 7); the last row's pose is the next step's."""
    X, Y, th = pose[0], pose[1], pose[2]
    for j in range(truth.shape[0]):
        tc = t + j * dt_c
        v, v_dot = _profile(prof, 0, tc)
        w, w_dot = _profile(prof, 1, tc)
        truth[j, 0], truth[j, 1], truth[j, 2] = X, Y, th
        truth[j, 3], truth[j, 4], truth[j, 5], truth[j, 6] = v, w, v_dot, w_dot
        if j + 1 < truth.shape[0]:
            X, Y, th = _free_leader_advance(prof, tc, X, Y, th, dt_c, n_sub_leader)


@njit(cache=True, error_model="numpy")
def road_views_nb(NB, AGE, beacons, fb, fb_state, dt_c, V):
    """Each member's view (s, v, a) at each period: its newest beacon predicted over its age
    along the line (comm/predict.py), or in fallback fb_state (s, v) moving on at constant
    speed."""
    for j in range(NB.shape[0]):
        for i in range(NB.shape[1]):
            if fb[i]:
                V[j, i, 0], V[j, i, 1] = _advance_vc(fb_state[i, 0], fb_state[i, 1], 0.0, j * dt_c)
                V[j, i, 2] = 0.0
            else:
                b = NB[j, i]
                V[j, i, 0], V[j, i, 1] = _advance_vc(beacons[b, 0], beacons[b, 1], beacons[b, 2],
                                                     AGE[j, i])
                V[j, i, 2] = beacons[b, 2]


@njit(cache=True, error_model="numpy")
def free_views_nb(NB, AGE, beacons, fb, fb_state, dt_c, V):
    """Each member's view (x, y, theta, v, omega, v_dot, omega_dot) at each period: its newest
    beacon predicted over its age with turn rate and acceleration held (predict_planar; v_dot
    and omega_dot as sent), or in fallback fb_state moving straight on at constant speed."""
    for j in range(NB.shape[0]):
        for i in range(NB.shape[1]):
            if fb[i]:
                src = fb_state[i]
                tau = j * dt_c
            else:
                src = beacons[NB[j, i]]
                tau = AGE[j, i]
            V[j, i, 0], V[j, i, 1], V[j, i, 2], V[j, i, 3] = predict_planar(
                src[0], src[1], src[2], src[3], src[4], src[5], tau)
            V[j, i, 4] = src[4]
            V[j, i, 5] = src[5]
            V[j, i, 6] = src[6]


# ------------------------------------------------------------------- step kernels

@njit(cache=True, error_model="numpy")
def _road_view_target(G, view, is_road, slot_x, slot_y, rig_x, rig_y):
    """Desired (p, v, a) of one member from its view (s, v, a) of the virtual car."""
    if is_road:
        return _road_target(G, view[0], view[1], view[2], slot_x, slot_y)
    X, Y, th, vv, om, vd, omd = _road_leader(G, view[0], view[1], view[2])
    return _rigid_target(X, Y, th, vv, om, vd, omd, rig_x, rig_y)


@njit(cache=True, error_model="numpy")
def _free_view_target(view, dx, dy):
    return _rigid_target(view[0], view[1], view[2], view[3], view[4], view[5], view[6], dx, dy)


@njit(cache=True, error_model="numpy")
def _periods(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, v_cap, a_cap, dt_c, n_sub):
    """One control period from the targets T (n, 6): control, then advance (theta_star and
    speed_in in place). Returns the new states."""
    n = x.shape[0]
    U = np.empty((n, 2))
    tsd = np.empty(n)
    for i in range(n):
        U[i, 0], U[i, 1], _, _, tsd[i], _, _, _, _, _, _ = _control_at(
            i, x, theta_star, speed_in, model_kind, k, k_theta, C, T[i, 0], T[i, 1], T[i, 2],
            T[i, 3], T[i, 4], T[i, 5], v_cap[i], a_cap[i])
    return _advance_members(x, theta_star, speed_in, U, tsd, model_kind, P, dt_c, n_sub)


@njit(cache=True, error_model="numpy")
def step_views_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, G, slots, rigid,
                  is_road, V, v_cap, a_cap, dt_c, n_sub):
    """fast.step_periods_nb (a road run's step) with member i's targets at period j from its
    view V[j, i] (s, v, a). Returns (x, theta_star, speed_in)."""
    n = x.shape[0]
    theta_star = theta_star.copy()
    speed_in = speed_in.copy()
    T = np.empty((n, N_T))
    for j in range(V.shape[0]):
        for i in range(n):
            T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _road_view_target(
                G, V[j, i], is_road[i], slots[i, 0], slots[i, 1], rigid[i, 0], rigid[i, 1])
        x = _periods(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, v_cap, a_cap,
                     dt_c, n_sub)
    return x, theta_star, speed_in


@njit(cache=True, error_model="numpy")
def step_free_views_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, offsets, V,
                       v_cap, a_cap, dt_c, n_sub):
    """fast.step_free_nb with member i's rigid targets at period j from its view V[j, i]."""
    n = x.shape[0]
    theta_star = theta_star.copy()
    speed_in = speed_in.copy()
    T = np.empty((n, N_T))
    for j in range(V.shape[0]):
        for i in range(n):
            T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _free_view_target(
                V[j, i], offsets[i, 0], offsets[i, 1])
        x = _periods(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, v_cap, a_cap,
                     dt_c, n_sub)
    return x, theta_star, speed_in


# ----------------------------------------------------------------- recorded signals

@njit(cache=True, error_model="numpy")
def _put(out, i, col, val):
    if col >= 0:
        out[i, col] = val


@njit(cache=True, error_model="numpy")
def _true_errors(x, Tt, vc_theta, cols, out):
    """Overwrite the error columns with the error against the true targets Tt (n, 6)."""
    c = np.cos(vc_theta)
    s = np.sin(vc_theta)
    for i in range(x.shape[0]):
        ex = Tt[i, 0] - x[i, 0]
        ey = Tt[i, 1] - x[i, 1]
        _put(out, i, cols[_Q_EX], ex)
        _put(out, i, cols[_Q_EY], ey)
        _put(out, i, cols[_Q_E_LON], c * ex + s * ey)
        _put(out, i, cols[_Q_E_LAT], -s * ex + c * ey)
        _put(out, i, cols[_Q_X_DES], Tt[i, 0])
        _put(out, i, cols[_Q_Y_DES], Tt[i, 1])


@njit(cache=True, error_model="numpy")
def record_views_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, G, slots, rigid,
                    is_road, truth, V0, v_cap, a_cap, cols, out):
    """fast.record_signals_nb with the control from each member's view V0 (n, 3) and the
    formation error against the true virtual car truth (s, v, a)."""
    n = x.shape[0]
    T = np.empty((n, N_T))
    for i in range(n):
        T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _road_view_target(
            G, V0[i], is_road[i], slots[i, 0], slots[i, 1], rigid[i, 0], rigid[i, 1])
    vc_theta = frame_at(G, truth[0])[4]
    _signal_rows(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, v_cap, a_cap,
                 vc_theta, cols, out)
    Tt = mixed_targets_nb(G, slots, rigid, is_road, truth[0], truth[1], truth[2])
    _true_errors(x, Tt, vc_theta, cols, out)


@njit(cache=True, error_model="numpy")
def record_free_views_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, offsets, truth,
                         V0, cols, out):
    """fast.record_signals_free_nb with the control from each member's view V0 (n, 7) and the
    formation error against the true virtual car ``truth`` (7,)."""
    n = x.shape[0]
    T = np.empty((n, N_T))
    Tt = np.empty((n, N_T))
    for i in range(n):
        T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _free_view_target(
            V0[i], offsets[i, 0], offsets[i, 1])
        Tt[i, 0], Tt[i, 1], Tt[i, 2], Tt[i, 3], Tt[i, 4], Tt[i, 5] = _free_view_target(
            truth, offsets[i, 0], offsets[i, 1])
    inf = np.full(n, np.inf)
    _signal_rows(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, inf, inf,
                 truth[2], cols, out)
    _true_errors(x, Tt, truth[2], cols, out)


# ------------------------------------------------------------ numba cache maintenance

def _check_digest() -> None:
    """Numba keys this module's cache on this file only: drop it when a file whose compiled
    functions these kernels call changed (as fast.py does for its own kernels)."""
    from ..comm import predict

    try:
        h = hashlib.sha256()
        for p in (Path(fast.__file__), Path(fast_line.__file__), Path(bicycle_fast.__file__),
                  Path(predict.__file__), Path(__file__)):
            h.update(p.read_bytes())
        digest = h.hexdigest()
        cache_dir = Path(step_views_nb._cache.cache_path)
        stamp = cache_dir / "fast_comm_kernels.digest"
        if (stamp.read_text().strip() if stamp.exists() else None) != digest:
            for d in list(globals().values()):
                if hasattr(d, "_cache") and getattr(d, "py_func", None) is not None \
                        and d.py_func.__module__ == __name__:
                    d._cache.flush()
            cache_dir.mkdir(parents=True, exist_ok=True)
            stamp.write_text(digest)
    except Exception:  # pragma: no cover - read-only tree etc.
        pass


_check_digest()
