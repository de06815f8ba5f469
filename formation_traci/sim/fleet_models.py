"""A fleet's model variant (models/variants.py, scenario ``vehicle.variant``) for the Fleet
(sim/fleet.py): its slots in the members' state rows, its parameter columns in their
parameter rows and the step kernel compiled to integrate it."""
from __future__ import annotations

import numpy as np

from ..core.kernels import rebind
from ..models.integrator import model_integrator
from ..models.variants import model_module, model_spec

_VARIANT_KERNELS: dict = {}


def model_kernel(variant: str | None, step):
    """``step`` (sim/fleet.py step_members) for a fleet of a base model, else a compiled copy
    that integrates the variant's rows (its ``rhs_into`` and ``constrain``, RK4 of
    models/integrator.py): made once per variant, not cached on disk."""
    if variant is None:
        return step
    mod = model_module(variant)
    got = _VARIANT_KERNELS.get(variant)
    if got is None or got[0] is not mod or got[1] is not step:
        rhs, steps = model_integrator(mod, base_constraints=True)
        got = _VARIANT_KERNELS[variant] = (mod, step, rebind(step, rhs_into=rhs, rk4_row_from=steps))
    return got[2]


def variant_params(variant: str, given: dict | None) -> dict:
    """The parameters of ``variant``: ``given`` (its scenario table, validated) over its SPEC's
    defaults ({} without a SPEC)."""
    spec = model_spec(variant)
    table = dict(given or {})
    return table if spec is None else spec.model_validate(table).model_dump()


def with_variant_params(cfg, P: np.ndarray) -> np.ndarray:
    """The parameter rows ``P`` (n, N_PARAMS) with the variant's columns after them (its
    ``pack(cfg)``); ``P`` itself without a variant."""
    if cfg.variant is None:
        return P
    own = np.asarray(model_module(cfg.variant).pack(cfg), dtype=float).reshape(cfg.n, -1)
    return np.ascontiguousarray(np.hstack([P, own]))


def with_variant_slots(cfg, x: np.ndarray) -> np.ndarray:
    """The state rows ``x`` (n, the base's slots) with the variant's slots after them, at 0;
    ``x`` itself without a variant."""
    if cfg.variant is None:
        return x
    return np.hstack([x, np.zeros((len(x), len(model_module(cfg.variant).SLOTS)))])
