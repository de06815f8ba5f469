"""Compiled (numba) RK4 integration of the dynamic bicycle and the kinematic unicycle.

Drop-in replacements for the per-control-period physics of ``sim.fleet.advance``:

    integrate_bicycle(x, u, P, dt, n_sub)
        == integrate(bicycle.rhs, x, u, p, dt, max_step, bicycle.project)
        with P = pack_params(p, n) and n_sub = integrate.substeps(dt, max_step)
    integrate_unicycle(x, u, dt, n_sub)
        == integrate(kinematic.rhs, x, u, None, dt, max_step)

Both do ``n_sub`` classical RK4 sub-steps of ``dt / n_sub`` with the input held (and, for the
bicycle, ``bicycle.project`` after every sub-step), in scalar code per vehicle: no
temporary arrays per stage, so a call for a handful of vehicles costs about a microsecond
instead of the numpy path's call overhead.

The formulas are those of ``models/bicycle.py``, ``models/tire.py`` and
``models/params.py`` written out per scalar with the same operation order (no fastmath, no
reassociation), so results agree with the numpy reference to rounding level: the only
differences come from numpy's SIMD transcendentals (sin, cos, tan, atan, atan2) versus
libm's, a few ulp per evaluation. Keep this file in step with ``bicycle.rhs``;
``tests/test_bicycle_fast.py`` compares the two.

The kernels compile on first use (cached on disk by numba); :func:`warmup` compiles both
for the argument types used by the fleet (C-contiguous float64 arrays, float dt, int n_sub).
"""
from __future__ import annotations

import hashlib
from dataclasses import fields
from pathlib import Path

import numpy as np
from numba import njit

from .params import G, BicycleParams
from .resistance import road_load

PARAM_NAMES: tuple[str, ...] = (
    "m", "Izz", "a", "b", "h", "mu",
    "Bf", "Cf", "Df", "Ef", "Br", "Cr", "Dr", "Er",
    "linear_tire", "steer_max", "steer_rate_max",
    "v_low", "v_high", "tau", "tau_stop",
    "resistances", "c_d", "frontal_area", "rho_air", "drag_ratio", "grade",
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

_G = float(G)

N_STATES_BICYCLE = 7  # X, Y, PSI, V, BETA, R, DELTA (bicycle.S)
N_INPUTS_BICYCLE = 2  # A_REF, STEER_RATE (bicycle.U)
N_STATES_UNICYCLE = 3  # X, Y, PSI (kinematic.KS)
N_INPUTS_UNICYCLE = 2  # V, OMEGA (kinematic.KU)


def pack_params(p: BicycleParams, n: int) -> np.ndarray:
    """Pack ``p`` into a C-contiguous float64 array of shape (n, N_PARAMS), columns PARAM_NAMES.

    Scalar fields are broadcast to all n rows; (n,) array fields (a mixed fleet from
    ``params.stack``) are copied per row; ``linear_tire`` and ``resistances`` become 0.0 / 1.0.
    Pack once per fleet and reuse: the array does not change while the parameters do not
    (``drag_ratio`` and ``grade`` are the exception: the loops write those two columns).
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


# --- scalar helpers with numpy's semantics (NaN propagates like np.maximum / np.minimum) ---

@njit(cache=True, error_model="numpy")
def _maximum(a, b):
    if a >= b or a != a:
        return a
    return b


@njit(cache=True, error_model="numpy")
def _minimum(a, b):
    if a <= b or a != a:
        return a
    return b


@njit(cache=True, error_model="numpy")
def _clip(x, lo, hi):
    """np.clip(x, lo, hi) == minimum(maximum(x, lo), hi)."""
    return _minimum(_maximum(x, lo), hi)


@njit(cache=True, error_model="numpy")
def _bicycle_rhs(psi, v, beta, r, delta, a_ref, rate_in, P, i):
    """bicycle.rhs for vehicle row i, as scalars; returns the 7 state derivatives.

    X and Y do not enter the right-hand side, so they are not arguments.
    """
    m = P[i, _M]
    Izz = P[i, _IZZ]
    a = P[i, _A]
    b = P[i, _B]
    h = P[i, _H]
    mu = P[i, _MU]
    v_low = P[i, _VLOW]
    v_high = P[i, _VHIGH]
    tau = P[i, _TAU]
    steer_max = P[i, _SMAX]
    steer_rate_max = P[i, _SRMAX]

    sb = np.sin(beta)
    cb = np.cos(beta)
    sd = np.sin(delta)
    cd = np.cos(delta)

    # slip_angles (3.7)-(3.8), speed floored at v_low
    vs = _maximum(v, v_low)
    vx = vs * cb
    vy = vs * sb
    alpha_f = np.arctan2(vy + a * r, vx) - delta
    alpha_r = np.arctan2(vy - b * r, vx)

    # tire_forces: cornering_force (3.9)-(3.10) or linear (3.12)
    if P[i, _LIN] != 0.0:
        fcf = P[i, _BF] * P[i, _CF] * P[i, _DF] * alpha_f
        fcr = P[i, _BR] * P[i, _CR] * P[i, _DR] * alpha_r
    else:
        ba = P[i, _BF] * alpha_f
        fcf = P[i, _DF] * np.sin(P[i, _CF] * np.arctan(ba - P[i, _EF] * (ba - np.arctan(ba))))
        ba = P[i, _BR] * alpha_r
        fcr = P[i, _DR] * np.sin(P[i, _CR] * np.arctan(ba - P[i, _ER] * (ba - np.arctan(ba))))

    # traction_force_max (3.14)-(3.15), on the unfloored v
    L = a + b
    w_weight = m * _G
    f_rl = 0.01 * (1.0 + v / 40.8)
    f_max = mu * w_weight * (b + f_rl * h) / L / (1.0 + mu * h / L)
    f_brake = mu * m * _G  # braking_force_max

    # driving resistance (models/resistance.py); off: the seed's model, unchanged
    res_on = P[i, _RES] != 0.0
    f_res = 0.0
    if res_on:
        f_res = road_load(v, m, P[i, _CD], P[i, _AREA], P[i, _RHO], P[i, _DRAG], P[i, _GRADE])

    # traction_from_acceleration (3.13), clipped
    num = m * a_ref - fcf * (cd * sb - sd * cb) - fcr * sb
    if res_on:
        num = num + f_res
    den = cd * cb + sd * sb
    f_lf = _clip(num / den, -f_brake, f_max)

    fx = f_lf * cd - fcf * sd
    fy = f_lf * sd + fcf * cd + fcr

    v_dot_dyn = (fx * cb + fy * sb) / m
    if res_on:
        v_dot_dyn = v_dot_dyn - f_res / m
    beta_dot_dyn = (fy * cb - fx * sb) / (m * vs) - r
    r_dot_dyn = ((f_lf * sd + fcf * cd) * a - fcr * b) / Izz

    # steering_rate: rate limit, zero when pushing past the angle limit
    rate = _clip(rate_in, -steer_rate_max, steer_rate_max)
    if (delta >= steer_max and rate > 0.0) or (delta <= -steer_max and rate < 0.0):
        ddelta = 0.0
    else:
        ddelta = rate

    # kinematic bicycle
    td = np.tan(delta)
    sec2 = 1.0 + td * td
    k = b * td / L
    beta_k = np.arctan(k)
    dbeta_k = (b / L) * sec2 / (1.0 + k * k)
    if res_on:
        v_dot_kin = _clip(a_ref + f_res / m, -f_brake / m, f_max / m) - f_res / m
    else:
        v_dot_kin = _clip(a_ref, -f_brake / m, f_max / m)
    cbk = np.cos(beta_k)
    sbk = np.sin(beta_k)
    r_k = v * cbk * td / L
    dr_k_dv = cbk * td / L
    dr_k_dd = v / L * (cbk * sec2 - sbk * dbeta_k * td)
    beta_dot_kin = (beta_k - beta) / tau + dbeta_k * ddelta
    r_dot_kin = (r_k - r) / tau + dr_k_dv * v_dot_kin + dr_k_dd * ddelta

    # _blend_weight: smoothstep between v_low and v_high
    s = _clip((v - v_low) / (v_high - v_low), 0.0, 1.0)
    w = s * s * (3.0 - 2.0 * s)
    v_dot = w * v_dot_dyn + (1.0 - w) * v_dot_kin
    v_dot = _maximum(v_dot, -_maximum(v, 0.0) / P[i, _TAUSTOP])

    course = psi + beta
    return (v * np.cos(course),
            v * np.sin(course),
            r,
            v_dot,
            w * beta_dot_dyn + (1.0 - w) * beta_dot_kin,
            w * r_dot_dyn + (1.0 - w) * r_dot_kin,
            ddelta)


@njit(cache=True, error_model="numpy")
def integrate_bicycle(x, u, P, dt, n_sub):
    """``integrate(bicycle.rhs, x, u, p, dt, max_step, bicycle.project)`` in compiled code.

    x : (n, 7) float64 state (bicycle.S order); not modified.
    u : (n, 2) float64 input (bicycle.U order), held over dt.
    P : (n, N_PARAMS) float64 from :func:`pack_params`.
    dt : step [s]; n_sub : number of equal RK4 sub-steps (``integrate.substeps(dt, max_step)``).
    Returns the new (n, 7) state.
    """
    n = x.shape[0]
    if x.shape[1] != N_STATES_BICYCLE:
        raise ValueError("x must have shape (n, 7)")
    if u.shape[0] != n or u.shape[1] != N_INPUTS_BICYCLE:
        raise ValueError("u must have shape (n, 2)")
    if P.shape[0] != n or P.shape[1] != N_PARAMS:
        raise ValueError("P must have shape (n, N_PARAMS), see pack_params")
    if n_sub < 1:
        raise ValueError("n_sub must be >= 1")
    h = dt / n_sub
    hh = 0.5 * h
    h6 = h / 6.0
    out = np.empty((n, N_STATES_BICYCLE))
    for i in range(n):
        X = x[i, 0]
        Y = x[i, 1]
        psi = x[i, 2]
        v = x[i, 3]
        beta = x[i, 4]
        r = x[i, 5]
        delta = x[i, 6]
        a_ref = u[i, 0]
        rate = u[i, 1]
        steer_max = P[i, _SMAX]
        for _ in range(n_sub):
            k1 = _bicycle_rhs(psi, v, beta, r, delta, a_ref, rate, P, i)
            k2 = _bicycle_rhs(psi + hh * k1[2], v + hh * k1[3], beta + hh * k1[4],
                              r + hh * k1[5], delta + hh * k1[6], a_ref, rate, P, i)
            k3 = _bicycle_rhs(psi + hh * k2[2], v + hh * k2[3], beta + hh * k2[4],
                              r + hh * k2[5], delta + hh * k2[6], a_ref, rate, P, i)
            k4 = _bicycle_rhs(psi + h * k3[2], v + h * k3[3], beta + h * k3[4],
                              r + h * k3[5], delta + h * k3[6], a_ref, rate, P, i)
            X = X + h6 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            Y = Y + h6 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            psi = psi + h6 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
            v = v + h6 * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
            beta = beta + h6 * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
            r = r + h6 * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])
            delta = delta + h6 * (k1[6] + 2.0 * k2[6] + 2.0 * k3[6] + k4[6])
            # bicycle.project
            v = _maximum(v, 0.0)
            delta = _clip(delta, -steer_max, steer_max)
        out[i, 0] = X
        out[i, 1] = Y
        out[i, 2] = psi
        out[i, 3] = v
        out[i, 4] = beta
        out[i, 5] = r
        out[i, 6] = delta
    return out


@njit(cache=True, error_model="numpy")
def integrate_unicycle(x, u, dt, n_sub):
    """``integrate(kinematic.rhs, x, u, None, dt, max_step)`` in compiled code.

    x : (n, 3) float64 state (kinematic.KS order); not modified.
    u : (n, 2) float64 input (kinematic.KU order: v, omega), held; v is floored at 0.
    Returns the new (n, 3) state.
    """
    n = x.shape[0]
    if x.shape[1] != N_STATES_UNICYCLE:
        raise ValueError("x must have shape (n, 3)")
    if u.shape[0] != n or u.shape[1] != N_INPUTS_UNICYCLE:
        raise ValueError("u must have shape (n, 2)")
    if n_sub < 1:
        raise ValueError("n_sub must be >= 1")
    h = dt / n_sub
    hh = 0.5 * h
    h6 = h / 6.0
    out = np.empty((n, N_STATES_UNICYCLE))
    for i in range(n):
        X = x[i, 0]
        Y = x[i, 1]
        psi = x[i, 2]
        v = _maximum(u[i, 0], 0.0)
        om = u[i, 1]
        for _ in range(n_sub):
            p2 = psi + hh * om
            p3 = psi + hh * om
            p4 = psi + h * om
            c1, s1 = v * np.cos(psi), v * np.sin(psi)
            c2, s2 = v * np.cos(p2), v * np.sin(p2)
            c3, s3 = v * np.cos(p3), v * np.sin(p3)
            c4, s4 = v * np.cos(p4), v * np.sin(p4)
            X = X + h6 * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
            Y = Y + h6 * (s1 + 2.0 * s2 + 2.0 * s3 + s4)
            psi = psi + h6 * (om + 2.0 * om + 2.0 * om + om)
        out[i, 0] = X
        out[i, 1] = Y
        out[i, 2] = psi
    return out


def _drop_stale_cache() -> None:
    """Numba keys its on-disk cache on this file only: drop it when the law module it calls
    (models/resistance.py) changed since the cache was written."""
    from . import resistance
    try:
        digest = hashlib.sha256(Path(resistance.__file__).read_bytes()
                                + Path(__file__).read_bytes()).hexdigest()
        stamp = Path(integrate_bicycle._cache.cache_path) / "bicycle_fast_deps.digest"
        if (stamp.read_text().strip() if stamp.exists() else None) != digest:
            for d in (_bicycle_rhs, integrate_bicycle):
                d._cache.flush()
            stamp.parent.mkdir(parents=True, exist_ok=True)
            stamp.write_text(digest)
    except Exception:  # pragma: no cover - read-only tree: the tests compare with bicycle.rhs
        pass


_drop_stale_cache()


def warmup() -> None:
    """Compile (or load from numba's cache) both kernels for the fleet's argument types."""
    from .params import PASSENGER_CAR, bicycle_params, make_tires

    p = bicycle_params(PASSENGER_CAR, 1.0, make_tires(PASSENGER_CAR, 1.0))
    x = np.zeros((1, N_STATES_BICYCLE))
    u = np.zeros((1, N_INPUTS_BICYCLE))
    integrate_bicycle(x, u, pack_params(p, 1), 0.01, 1)
    integrate_unicycle(np.zeros((1, N_STATES_UNICYCLE)), u, 0.01, 1)
