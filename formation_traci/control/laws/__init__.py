"""The members' control laws, selected by name (scenario ``controller.law``).

A law is a module with

* ``PARAMS``: the names of its per-member parameters (columns of the array ``L``);
* ``pack(cfg) -> (n, len(PARAMS))``: those parameters from a sim/fleet.py FleetConfig (its
  ``law_params``: per member, {law name: {parameter: value}});
* optionally ``SPEC``: a pydantic model of its parameters with their defaults, which the
  scenario's ``[controller.<name>]`` table is validated against (scenario/formation_parts.py
  ControllerSpec ``params(name)``, the same for every law). A built-in law with parameters has
  them, ``SPEC`` and ``DEFAULTS``, in a sibling module without kernels, ``<law>_spec.py``, that
  the law's module imports and the scenario schema reads without compiling or importing numba
  (control/laws/acc_spec.py, cacc_path_spec.py, cacc_ploeg_spec.py), named in its
  :data:`BUILTIN` line;
* ``input_at(fleet, state, i, target, v_cap_i, a_cap_i)``: a ``@kernel`` giving member i's
  model input for its desired point and the safety caps ``v_cap_i`` [m/s], ``a_cap_i``
  [m/s^2]. ``fleet`` (sim/fleet_records.py FleetParams) holds the members' parameters: the
  model ``kind``, the law parameter rows ``L``, the gain rows ``gains`` (control/schedule.py
  SPEED_G_MIN ..), ``pred`` the member ahead of each in the formation's column (-1: none),
  the control period ``dt_c`` [s]; ``state`` (StateRecord) every member's state: the rows
  ``x`` (models/bicycle.py S), ``theta_star`` [rad], ``speed_in`` [m/s] and ``u_last``, every
  member's input u0 of the control period before (a_r [m/s^2] on the dynamic model: what a
  CACC receives of its predecessor, and a dynamic law's own state); ``target``
  (control/formation.py Target) the desired point p [m], p' [m/s], p'' [m/s^2]. It returns
  (u0, u1, v_ref [m/s], omega_ref [rad/s], theta* dot [rad/s], v_ref dot [m/s^2], ex, ey [m],
  heading error [rad]) (control/laws/virtual_structure.py).

Built-in laws are named in :data:`BUILTIN` and dispatched by code in the compiled step
(control/laws/dispatch.py, cached with the other kernels; their ``input_at`` and the platoon
helpers are ``@kernel(inline="always")``: compiled into the step's kernels, the records are
not passed from call to call); :func:`register_law` adds a law
from anywhere at run time (compiled for its fleet when first used, not cached on disk).
The platoon laws (acc, cacc_path, cacc_ploeg: control/laws/platoon.py, docs/platoon_laws.md)
are longitudinal laws on the column's predecessor with the virtual structure's lateral loop.
This module imports no kernels: the scenario schema checks names against it.
"""
from __future__ import annotations

import importlib
from types import ModuleType

DEFAULT_LAW = "virtual_structure"
"""The seed's law: the virtual structure, eqs 2.4-2.11, with the loops 3.32-3.38."""

_LAWS = "formation_traci.control.laws."
BUILTIN: dict[str, tuple[str, int, str]] = {
    "virtual_structure": (_LAWS + "virtual_structure", 0, ""),
    "acc": (_LAWS + "acc", 1, _LAWS + "acc_spec"),
    "cacc_path": (_LAWS + "cacc_path", 2, _LAWS + "cacc_path_spec"),
    "cacc_ploeg": (_LAWS + "cacc_ploeg", 3, _LAWS + "cacc_ploeg_spec"),
}
"""Built-in laws: name -> (module, code of control/laws/dispatch.py, the module without
kernels holding its parameter ``SPEC``, "" for none)."""

PLATOON_LAWS = ("acc", "cacc_path", "cacc_ploeg")
"""Built-in laws that follow the member ahead in a column (FleetConfig.pred)."""

SUMO_LAWS: dict[str, str] = {
    "sumo_cacc": _LAWS + "sumo_cacc",
}
"""Laws SUMO's own car-following model runs (road runs only): name -> module, a light module
without a kernel (control/laws/sumo_cacc.py): its parameter schema ``SPEC``, the members SUMO
drives (``driven(pred)``), the law our fleet runs for the others (``HEAD_LAW``); the SUMO side
is sumo/driven.py."""

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


def law_spec(name: str):
    """The parameter schema (a pydantic model with its defaults) of law ``name``, built in, of
    SUMO or registered at run time, read from the scenario's ``[controller.<name>]``; None when
    it has none (or ``name`` is no law)."""
    if name in BUILTIN:
        spec_module = BUILTIN[name][2]
        return importlib.import_module(spec_module).SPEC if spec_module else None
    if name in SUMO_LAWS:
        return importlib.import_module(SUMO_LAWS[name]).SPEC
    module = _RUNTIME.get(name)
    return getattr(module, "SPEC", None) if module is not None else None


def law_module(name: str) -> ModuleType:
    """The module of law ``name``."""
    if name in _RUNTIME:
        return _RUNTIME[name]
    if name not in BUILTIN:
        raise KeyError(f"unknown control law {name!r}; known: {', '.join(law_names())}")
    return importlib.import_module(BUILTIN[name][0])


def sumo_law(name: str) -> ModuleType:
    """The module of the SUMO law ``name`` (:data:`SUMO_LAWS`)."""
    return importlib.import_module(SUMO_LAWS[name])


def law_code(name: str) -> int:
    """The dispatch code of a built-in law, -1 for one registered at run time."""
    return BUILTIN[name][1] if name in BUILTIN else -1
