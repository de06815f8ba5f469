"""The members' control laws, selected by name (scenario ``controller.law``).

A law is a module with

* ``PARAMS``: the names of its per-member parameters (columns of the array ``L``);
* ``pack(cfg) -> (n, len(PARAMS))``: those parameters from a sim/fleet.py FleetConfig;
* ``input_at(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx, tvy, tax, tay,
  v_cap_i, a_cap_i, pred_i)``: a ``@kernel`` giving member i's model input for its desired
  point (p, p', p'') and the safety caps; ``pred_i`` is the member ahead of i in the
  formation's column (-1: none), whose state row a platoon law reads in ``x``. It returns
  (u0, u1, v_ref [m/s], omega_ref [rad/s], theta* dot [rad/s], v_ref dot [m/s^2], ex, ey [m],
  heading error [rad]) (control/laws/virtual_structure.py).

Built-in laws are named in :data:`BUILTIN` and dispatched by code in the compiled step
(control/laws/dispatch.py, cached with the other kernels); :func:`register_law` adds a law
from anywhere at run time (compiled for its fleet when first used, not cached on disk).
This module imports no kernels: the scenario schema checks names against it.
"""
from __future__ import annotations

import importlib
from types import ModuleType

import numpy as np

DEFAULT_LAW = "virtual_structure"
"""The seed's law: the virtual structure, eqs 2.4-2.11, with the loops 3.32-3.38."""

BUILTIN: dict[str, tuple[str, int]] = {
    "virtual_structure": ("formation_traci.control.laws.virtual_structure", 0),
}
"""Built-in laws: name -> (module, code of control/laws/dispatch.py)."""

_RUNTIME: dict[str, ModuleType] = {}


def law_names() -> tuple[str, ...]:
    """Every law a scenario may name."""
    return (*BUILTIN, *_RUNTIME)


def register_law(name: str, module: ModuleType) -> None:
    """Make ``module`` (see the module docstring) the law ``name``; a built-in name is
    refused."""
    if name in BUILTIN:
        raise ValueError(f"{name!r} is a built-in law")
    for attr in ("PARAMS", "pack", "input_at"):
        if not hasattr(module, attr):
            raise TypeError(f"law module {module.__name__} has no {attr!r}")
    _RUNTIME[name] = module


def law_module(name: str) -> ModuleType:
    """The module of law ``name``."""
    if name in _RUNTIME:
        return _RUNTIME[name]
    if name not in BUILTIN:
        raise KeyError(f"unknown control law {name!r}; known: {', '.join(law_names())}")
    return importlib.import_module(BUILTIN[name][0])


def law_code(name: str) -> int:
    """The dispatch code of a built-in law, -1 for one registered at run time."""
    return BUILTIN[name][1] if name in BUILTIN else -1


def pack_laws(cfg):
    """Every member's law code (n,), the law parameters (n, most PARAMS of its laws) and the
    one law registered at run time among them (or None), for a sim/fleet.py FleetConfig
    (``law``: one name, or one per member)."""
    laws = cfg.law if isinstance(cfg.law, (tuple, list)) else (cfg.law,) * cfg.n
    codes = np.array([law_code(name) for name in laws], dtype=np.int64)
    runtime = sorted({name for name, c in zip(laws, codes) if c < 0})
    if len(runtime) > 1:
        raise ValueError(f"one fleet runs at most one law registered at run time, not {runtime}")
    packs = {name: np.asarray(law_module(name).pack(cfg), dtype=float) for name in set(laws)}
    L = np.zeros((cfg.n, max(p.shape[1] for p in packs.values())))
    for i, name in enumerate(laws):
        L[i, :packs[name].shape[1]] = packs[name][i]
    return codes, L, (runtime[0] if runtime else None)
