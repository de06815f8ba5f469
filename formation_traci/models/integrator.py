"""The one integrator: fixed-step classical Runge-Kutta (RK4) over a model's state row.

A model (models/bicycle.py, models/kinematic.py, models/linear.py) exposes its right-hand side
over a state row indexed by its named slots, ``rhs_into(s, u0, u1, P, i, out)``, and the
bicycle its state constraints ``constrain(s, P, i)`` (applied after every sub-step). Every
integration of the package goes through :func:`rk4_row`: the members (sim/fleet.py), the free
virtual car of eq (2.3) (control/virtual_car.py: the unicycle with the profiles' inputs at the
stage times) and the open-loop linear model (sim/open_loop.py). A model with another state
slot (a drivetrain lag, say) changes only its module and its parameter record; a model defined
outside the package is integrated by :func:`rk4_for` (tests/test_law_seam.py), and a model
variant's step kernel by :func:`model_integrator`'s (models/variants.py,
tests/test_model_variant.py).
"""
from __future__ import annotations

import numpy as np

from ..core.kernels import kernel, rebind, substeps
from . import bicycle, kinematic, linear
from .state import DYNAMIC, KINEMATIC, LINEAR  # noqa: F401 (the kinds, re-exported)

MAX_PHYSICS_STEP = 0.01
"""Largest internal step [s]: the car's lateral dynamics need it at low speed (docs/model.md)."""

HELD = np.empty((0, 3, 2))
"""``stages`` of :func:`rk4_row` for an input held over the step."""


@kernel
def rhs_into(kind, s, u0, u1, P, i, out):
    """The right-hand side of model ``kind`` at state row s into out."""
    if kind == DYNAMIC:
        bicycle.rhs_into(s, u0, u1, P, i, out)
    elif kind == KINEMATIC:
        kinematic.rhs_into(s, u0, u1, P, i, out)
    else:
        linear.rhs_into(s, u0, u1, P, i, out)


@kernel
def constrain(kind, s, P, i):
    """The state constraints of model ``kind`` on row s (the bicycle's v >= 0, |delta|)."""
    if kind == DYNAMIC:
        bicycle.constrain(s, P, i)


@kernel
def rk4_row(kind, s, u0, u1, P, i, h, n_sub, w, stages):
    """``n_sub`` RK4 sub-steps of length h [s] of state row ``s`` (in place) of vehicle i.

    The input is (u0, u1) held, or with ``stages`` of shape (n_sub, 3, 2) the input at the
    stage times t0, t0 + h/2, t0 + h of each sub-step (a time-varying input); ``w`` is
    scratch of shape (5, len(s))."""
    rk4_row_from(kind, s, u0, u1, P, i, h, n_sub, w, stages, False)


@kernel
def rk4_row_from(kind, s, u0, u1, P, i, h, n_sub, w, stages, k1_given):
    """:func:`rk4_row`; with ``k1_given`` the first sub-step's first stage, the right-hand
    side at ``s`` under the input at t0, is already in ``w[0]`` (sim/fleet.py step_members
    computes it first for the comfort table's accelerations: the same numbers, once)."""
    m = s.shape[0]
    hh = 0.5 * h
    h6 = h / 6.0
    k1 = w[0]
    k2 = w[1]
    k3 = w[2]
    k4 = w[3]
    y = w[4]
    a0, a1, b0, b1, c0, c1 = u0, u1, u0, u1, u0, u1
    for q in range(n_sub):
        if stages.shape[0] > 0:
            a0, a1 = stages[q, 0, 0], stages[q, 0, 1]
            b0, b1 = stages[q, 1, 0], stages[q, 1, 1]
            c0, c1 = stages[q, 2, 0], stages[q, 2, 1]
        if not (k1_given and q == 0):
            rhs_into(kind, s, a0, a1, P, i, k1)
        for a in range(m):
            y[a] = s[a] + hh * k1[a]
        rhs_into(kind, y, b0, b1, P, i, k2)
        for a in range(m):
            y[a] = s[a] + hh * k2[a]
        rhs_into(kind, y, b0, b1, P, i, k3)
        for a in range(m):
            y[a] = s[a] + h * k3[a]
        rhs_into(kind, y, c0, c1, P, i, k4)
        for a in range(m):
            s[a] = s[a] + h6 * (k1[a] + 2.0 * k2[a] + 2.0 * k3[a] + k4[a])
        constrain(kind, s, P, i)


@kernel
def integrate_rows(kind, x, u, P, dt, n_sub):
    """Every row of x (n, m) advanced by dt [s] in n_sub RK4 sub-steps; x unchanged."""
    n, m = x.shape
    out = x.copy()
    w = np.empty((5, m))
    h = dt / n_sub
    for i in range(n):
        rk4_row(kind, out[i], u[i, 0], u[i, 1], P, i, h, n_sub, w, HELD)
    return out


def integrate(kind: int, x, u, P, dt: float, max_step: float = MAX_PHYSICS_STEP) -> np.ndarray:
    """Advance states x by dt [s] in equal RK4 sub-steps of at most ``max_step`` [s].

    ``kind``: :data:`DYNAMIC` (x (n, 7), u (n, 2), P from models.params.pack_params),
    :data:`KINEMATIC` (x (n, 3); P unused, may be None) or :data:`LINEAR` (x (n, 6), u (n, 2)
    = (delta, a_r), P from models.linear.linear_params)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    u = np.ascontiguousarray(np.broadcast_to(u, (len(x), 2)), dtype=np.float64)
    P = np.zeros((len(x), 1)) if P is None else np.ascontiguousarray(P, dtype=np.float64)
    return integrate_rows(kind, x, u, P, float(dt), substeps(dt, max_step))


def model_integrator(model, base_constraints: bool = False):
    """(:func:`rhs_into`, :func:`rk4_row_from`), same arguments, for a model module defined
    anywhere that has ``rhs_into(s, u0, u1, P, i, out)`` and optionally ``constrain(s, P, i)``
    (``kind`` is ignored but for the constraints of a module without its own: those of model
    ``kind`` with ``base_constraints``, else none): compiled for it (not cached on disk). A
    model variant's step kernel (models/variants.py, sim/fleet_models.py) is compiled with
    them in place of the package's."""
    def _rhs(kind, s, u0, u1, P, i, out):
        model_rhs(s, u0, u1, P, i, out)  # noqa: F821 (bound by rebind)

    def _constrain(kind, s, P, i):
        model_constrain(s, P, i)  # noqa: F821 (bound by rebind)

    def _none(kind, s, P, i):
        pass

    own = getattr(model, "constrain", None)
    if own is not None:
        con = rebind(_constrain, model_constrain=own)
    else:
        con = constrain if base_constraints else rebind(_none)
    rhs = rebind(_rhs, model_rhs=model.rhs_into)
    return rhs, rebind(rk4_row_from, rhs_into=rhs, constrain=con)


def rk4_for(model):
    """:func:`rk4_row` (same arguments, ``kind`` ignored) for a model module defined
    anywhere that has ``rhs_into(s, u0, u1, P, i, out)`` and optionally ``constrain(s, P,
    i)``: compiled for it (not cached on disk)."""
    return rebind(rk4_row, rk4_row_from=model_integrator(model)[1])
