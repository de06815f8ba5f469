"""Compiled step for road formations whose slots move (maneuvers): moving road targets.

sim/fast.py's kernels hold every slot fixed over a SUMO step. During a maneuver each slot
(dx, dy) follows the plan of control/maneuvers/transition.py; with sigma = s + dx the slot's
arc length (sigma' = v + dx', sigma'' = v_dot + dx'') the desired point

    p = c(sigma) + dy n(sigma)

has, by the Frenet-Serret formulas per unit arc length (t' = kappa n, n' = -kappa t),

    p'  = sigma' (1 - dy kappa) t + dy' n,
    p'' = [sigma'' (1 - dy kappa) - sigma'^2 dy kappa' - 2 sigma' dy' kappa] t
          + [sigma'^2 (1 - dy kappa) kappa + dy''] n,

which reduce to road/targets.py's when dx' = dy' = 0. The step below is sim/fast.py's
step_periods_nb with these targets evaluated at every control period t + j dt_c; the
controller, the vehicle models and the virtual car are fast.py's own kernels (called, not
copied). Scenarios without maneuvers keep using fast.py unchanged.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from numba import njit

from ..control.maneuvers import transition
from ..control.maneuvers.transition import slot_at
from ..road.fast_line import frame_at
from . import fast
from .fast import N_T, _advance_members, _advance_vc, _control_at, _f64, _signal_rows


@njit(cache=True, error_model="numpy")
def moving_road_target(G, s, v, v_dot, dx, dy, dxd, dyd, dxdd, dydd):
    """Desired point of a moving slot: (px, py, vx, vy, ax, ay) [m, m/s, m/s^2].

    s, v, v_dot: virtual car's arc length [m], speed [m/s], acceleration [m/s^2];
    dx, dy: slot along/across [m]; dxd, dyd [m/s]; dxdd, dydd [m/s^2] their time derivatives.
    """
    sd = v + dxd
    sdd = v_dot + dxdd
    x, y, tx, ty, heading, kappa, kappa_rate = frame_at(G, s + dx)
    nx = -ty
    ny = tx
    stretch = 1.0 - dy * kappa
    vt = sd * stretch
    ct = sdd * stretch - sd * sd * dy * kappa_rate - 2.0 * sd * dyd * kappa
    cn = sd * sd * stretch * kappa + dydd
    return (x + dy * nx, y + dy * ny, vt * tx + dyd * nx, vt * ty + dyd * ny,
            ct * tx + cn * nx, ct * ty + cn * ny)


@njit(cache=True, error_model="numpy")
def moving_targets_nb(G, plan, t, s, v, v_dot):
    """Targets (n, 6) [p | v | a] of every member at time t [s] from its plan row."""
    n = plan.shape[0]
    T = np.empty((n, N_T))
    for i in range(n):
        dx, dy, dxd, dyd, dxdd, dydd = slot_at(plan[i], t)
        T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = moving_road_target(
            G, s, v, v_dot, dx, dy, dxd, dyd, dxdd, dydd)
    return T


@njit(cache=True, error_model="numpy")
def step_moving_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, G, plan, t, s_vc,
                   v_vc, a_vc, v_cap, a_cap, dt_c, n_ctrl, n_sub):
    """One SUMO step from time t [s]: ``n_ctrl`` periods of moving targets -> control ->
    advance -> virtual car. Returns (x, theta_star, speed_in, s_vc, v_vc)."""
    n = x.shape[0]
    theta_star = theta_star.copy()
    speed_in = speed_in.copy()
    U = np.empty((n, 2))
    tsd = np.empty(n)
    for j in range(n_ctrl):
        tc = t + j * dt_c
        for i in range(n):
            dx, dy, dxd, dyd, dxdd, dydd = slot_at(plan[i], tc)
            px, py, tvx, tvy, tax, tay = moving_road_target(G, s_vc, v_vc, a_vc, dx, dy, dxd,
                                                            dyd, dxdd, dydd)
            U[i, 0], U[i, 1], _, _, tsd[i], _, _, _, _, _, _ = _control_at(
                i, x, theta_star, speed_in, model_kind, k, k_theta, C, px, py, tvx, tvy, tax,
                tay, v_cap[i], a_cap[i])
        x = _advance_members(x, theta_star, speed_in, U, tsd, model_kind, P, dt_c, n_sub)
        s_vc, v_vc = _advance_vc(s_vc, v_vc, a_vc, dt_c)
    return x, theta_star, speed_in, s_vc, v_vc


@njit(cache=True, error_model="numpy")
def record_moving_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, G, plan, t, s_vc,
                     v_vc, a_vc, v_cap, a_cap, cols, out):
    """The recorded signals at the start of a step (fast.record_signals_nb with moving targets)."""
    T = moving_targets_nb(G, plan, t, s_vc, v_vc, a_vc)
    vc_theta = frame_at(G, s_vc)[4]
    _signal_rows(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, v_cap, a_cap,
                 vc_theta, cols, out)


def step(ff, state, plan, t, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c, n_ctrl):
    """FastFleet.step with the slot plan: returns (FleetState, s_vc, v_vc)."""
    from .fleet import FleetState
    from .integrate import substeps
    v_cap, a_cap = ff._caps(v_cap, a_cap)
    x, ts, sp, s_vc, v_vc = step_moving_nb(
        _f64(state.x), _f64(state.theta_star), _f64(state.speed_in), ff.model_kind, ff.P, ff.k,
        ff.k_theta, ff.C, ff.line.G, _f64(plan), float(t), float(s_vc), float(v_vc), float(a_vc),
        v_cap, a_cap, float(dt_c), int(n_ctrl), substeps(dt_c, ff.cfg.physics_step))
    return FleetState(x, ts, sp), s_vc, v_vc


def signals(ff, state, plan, t, s_vc, v_vc, a_vc, v_cap=None, a_cap=None, out=None):
    """FastFleet.signals with the slot plan: (n, len(SIGNAL_COLUMNS))."""
    v_cap, a_cap = ff._caps(v_cap, a_cap)
    if out is None:
        out = np.full((ff.cfg.n, len(fast.SIGNAL_COLUMNS)), np.nan)
    record_moving_nb(_f64(state.x), _f64(state.theta_star), _f64(state.speed_in), ff.model_kind,
                     ff.P, ff.k, ff.k_theta, ff.C, ff.line.G, _f64(plan), float(t), float(s_vc),
                     float(v_vc), float(a_vc), v_cap, a_cap, ff.cols, out)
    return out


# numba keys its cache on this file only: drop it when a file whose kernels these call changed
_DEPENDENCIES = (Path(fast.__file__), Path(transition.__file__), Path(__file__))


def _check_dependency_digest() -> None:
    try:
        h = hashlib.sha256()
        for p in _DEPENDENCIES + fast._DEPENDENCIES:
            h.update(p.read_bytes())
        digest = h.hexdigest()
        cache_dir = Path(step_moving_nb._cache.cache_path)
        stamp = cache_dir / "fast_moving.digest"
        if not stamp.exists() or stamp.read_text().strip() != digest:
            for d in (moving_road_target, moving_targets_nb, step_moving_nb, record_moving_nb,
                      transition.quintic, transition.slot_at):
                d._cache.flush()
            cache_dir.mkdir(parents=True, exist_ok=True)
            stamp.write_text(digest)
    except Exception:  # pragma: no cover - read-only tree
        pass


_check_dependency_digest()
