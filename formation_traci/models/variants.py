"""Model variants: a base model with more state slots, added from anywhere at run time by
:func:`register_model` (scenario ``vehicle.variant``).

A variant is a module with

* ``BASE``: the model it extends, ``"dynamic"`` (models/bicycle.py) or ``"kinematic"``
  (models/kinematic.py); the scenario's ``vehicle.model`` must be it. Everything the
  package reads of a member (the laws' ``motion_at``, the recorded signals, SUMO's
  placement) reads the base's slots, so a variant runs under every law and in every world;
* ``SLOTS``: the names of the slots it adds, columns ``FIRST``, ``FIRST + 1``, ... of a
  member's state row after the base's (``FIRST`` = models/bicycle.py ``N_STATES`` or
  models/kinematic.py ``N_STATES``); they start at 0;
* ``pack(cfg) -> (n, k)``: its k parameters from a sim/fleet.py FleetConfig
  (``cfg.variant_params``: {parameter: value}), columns ``N_PARAMS``, ``N_PARAMS + 1``, ...
  of the parameter rows ``P`` (models/params.py ``N_PARAMS``);
* optionally ``SPEC``: a pydantic model of its parameters with their defaults, which the
  scenario's ``[vehicle.<name>]`` table is validated against (defaults without a table);
* ``rhs_into(s, u0, u1, P, i, out)``: a compiled function (numba ``njit``) writing the
  derivative of the whole state row ``s`` of member i into ``out`` (typically the base's
  ``rhs_into`` and then its own slots'), the input (u0, u1) as the base takes it;
* optionally ``constrain(s, P, i)`` (compiled): the row's constraints after every RK4
  sub-step (default: the base's, models/integrator.py ``constrain``).

The members' step kernel is then compiled for the variant (models/integrator.py
``model_integrator``, sim/fleet_models.py: not cached on disk). This module imports no
kernels: the scenario schema checks names against it.
"""
from __future__ import annotations

from types import ModuleType

BASES = ("dynamic", "kinematic")
"""The models a variant may extend (scenario ``vehicle.model``)."""

_VARIANTS: dict[str, ModuleType] = {}


def register_model(name: str, module: ModuleType) -> None:
    """Make ``module`` (see the module docstring) the model variant ``name``; a base model's
    name is refused."""
    if name in BASES:
        raise ValueError(f"{name!r} is a built-in model")
    for attr in ("BASE", "SLOTS", "pack", "rhs_into"):
        if not hasattr(module, attr):
            raise TypeError(f"model module {module.__name__} has no {attr!r}")
    if module.BASE not in BASES:
        raise ValueError(f"model module {module.__name__}: BASE {module.BASE!r} is not one of {BASES}")
    _VARIANTS[name] = module


def model_names() -> tuple[str, ...]:
    """Every model variant a scenario may name."""
    return tuple(_VARIANTS)


def model_module(name: str) -> ModuleType:
    """The module of model variant ``name``."""
    if name not in _VARIANTS:
        raise KeyError(f"unknown model variant {name!r}; known: {', '.join(model_names()) or 'none'}")
    return _VARIANTS[name]


def model_spec(name: str):
    """The parameter schema (a pydantic model with its defaults) of variant ``name``, None
    when it has none or there is no such variant."""
    module = _VARIANTS.get(name)
    return getattr(module, "SPEC", None) if module is not None else None
