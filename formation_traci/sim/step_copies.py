"""The compiled steps (sim/free_step.py ``free_step``, sumo/fused_step.py ``fused_step``) for a
fleet whose step and signal kernels are not the package's own (a law registered at run time, a
model variant: sim/fleet.py ``Fleet.kernels``)."""
from __future__ import annotations

from ..core.kernels import rebind
from .fleet import member_signals, step_members

_STEP_COPIES: dict = {}


def with_fleet_kernels(whole, record, kernels):
    """A compiled step ``whole`` (sim/free_step.py free_step, sumo/fused_step.py fused_step)
    that calls :func:`~.fleet.step_members` itself and :func:`~.fleet.member_signals` through
    its kernel ``record``, for a fleet whose (step, signal) kernels are ``kernels``: ``whole``
    itself for the package's own, else a compiled copy calling those given (a law registered
    at run time, a model variant), made once per triple (compiled on first call, not cached
    on disk)."""
    step, signals = kernels
    if step is step_members and signals is member_signals:
        return whole
    key = (id(whole), id(step), id(signals))
    got = _STEP_COPIES.get(key)
    if got is None or got[0] is not step or got[1] is not signals:
        copy = rebind(whole, step_members=step, _record=rebind(record, member_signals=signals))
        got = _STEP_COPIES[key] = (step, signals, copy)
    return got[2]
