"""A formation as a unit at run time, and a run's formations as one fleet.

A run holds a list of :class:`Formation`: each has its id, its members' rows in the run's
arrays (a slice), its reference generator (free space: control/reference_free.py; road:
control/reference_road.py), its transforms (maneuver slots, the radio) and its virtual car's
id in the tables. The members of all formations are one :class:`~.fleet.Fleet` (one compiled
call per step for every member, whatever formation it is in; per-member parameters and laws);
each step the formations' references are joined into the fleet's (:func:`join_references`).
With one formation nothing is joined: the run is the one-formation run, bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..control.reference import Reference, SensingTransform
from ..record.columns import VIRTUAL_CAR_ID
from .fleet import FleetConfig, FleetState
from .world import Sensed


@dataclass
class Formation:
    """One formation of a run (see the module docstring)."""

    id: str
    members: slice  # its members' rows in the run's fleet arrays
    generator: object  # a reference generator: reference(t, sensed), commit(), stop_reason(t)
    transforms: list = field(default_factory=list)  # Reference -> Reference, in order
    vc_id: str = VIRTUAL_CAR_ID  # the virtual car's vehicle_id in the tables

    @property
    def sensing(self) -> list:
        """Its transforms that are told what the world sensed first (comm/link.py)."""
        return [tr for tr in self.transforms if isinstance(tr, SensingTransform)]

    @property
    def true_error(self) -> bool:
        """A transform has the formation error recorded against the true virtual car."""
        return any(getattr(tr, "error_against_truth", False) for tr in self.transforms)


def virtual_car_id(formation_id: str, n_formations: int) -> str:
    """The virtual car's vehicle_id: 'vc' in a one-formation run, 'vc:<id>' with several (a
    member id cannot hold ':')."""
    return VIRTUAL_CAR_ID if n_formations == 1 else f"{VIRTUAL_CAR_ID}:{formation_id}"


def join_configs(cfgs: list[FleetConfig]) -> FleetConfig:
    """The formations' fleet configurations as one fleet (members in formation order)."""
    if len(cfgs) == 1:
        return cfgs[0]
    first = cfgs[0]
    if any(c.model != first.model or c.physics_step != first.physics_step for c in cfgs):
        raise ValueError("the formations of a run share vehicle.model and run.physics_step")
    n = [c.n for c in cfgs]
    offsets = np.cumsum([0] + n[:-1])
    pred = [p + o if p >= 0 else -1
            for c, o in zip(cfgs, offsets) for p in (c.pred if c.pred is not None else (-1,) * c.n)]
    laws = tuple(law for c in cfgs for law in _per_member(c.law, c.n))
    return replace(
        first, ids=tuple(i for c in cfgs for i in c.ids),
        params=None if first.params is None else _join_params([c.params for c in cfgs], n),
        k=np.concatenate([np.broadcast_to(c.k, (c.n,)) for c in cfgs]),
        k_theta=np.concatenate([np.broadcast_to(c.k_theta, (c.n,)) for c in cfgs]),
        speed_gains=tuple(g for c in cfgs for g in _per_member(c.speed_gains, c.n)),
        yaw_gains=tuple(g for c in cfgs for g in _per_member(c.yaw_gains, c.n)),
        law=laws if len(set(laws)) > 1 else laws[0], pred=tuple(pred),
        bumpers=None if any(c.bumpers is None for c in cfgs)
        else tuple(b for c in cfgs for b in c.bumpers),
        law_params=tuple(q for c in cfgs for q in (c.law_params or ({},) * c.n)))


def _per_member(value, n: int) -> tuple:
    return tuple(value) if isinstance(value, (tuple, list)) else (value,) * n


def _join_params(params: list, n: list[int]):
    """BicycleParams of several fleets as one: every field per member."""
    fields = {}
    for name in params[0].__dataclass_fields__:
        vals = [getattr(p, name) for p in params]
        if all(np.ndim(v) == 0 for v in vals) and all(v == vals[0] for v in vals):
            fields[name] = vals[0]
        else:
            fields[name] = np.concatenate([np.broadcast_to(np.asarray(v, dtype=float), (k,))
                                           for v, k in zip(vals, n)])
    return replace(params[0], **fields)


def join_states(states: list[FleetState]) -> FleetState:
    if len(states) == 1:
        return states[0]
    return FleetState(np.concatenate([s.x for s in states]),
                      np.concatenate([s.theta_star for s in states]),
                      np.concatenate([s.speed_in for s in states]),
                      np.concatenate([s.u_last if s.u_last is not None else np.zeros(len(s.x))
                                      for s in states]))


def sensed_of(sensed: Sensed, sl: slice) -> Sensed:
    """What the world sensed, as formation ``sl`` sees it: its members' rows (views), every
    neighbour. Its transforms' recorded columns go back into ``sensed`` with
    :func:`merge_extra`."""
    n = len(sensed.active)
    pick = (lambda a: a[sl] if isinstance(a, np.ndarray) and a.shape[:1] == (n,) else a)
    return replace(sensed, active=sensed.active[sl],
                   extra={k: pick(v) for k, v in sensed.extra.items()},
                   v_m=pick(sensed.v_m), m_s=pick(sensed.m_s), m_d=pick(sensed.m_d))


def merge_extra(sensed: Sensed, part: Sensed, sl: slice) -> None:
    """The recorded columns ``part`` (a formation's :func:`sensed_of`) holds into
    ``sensed``'s rows ``sl``."""
    n = len(sensed.active)
    for name, val in part.extra.items():
        full = sensed.extra.get(name)
        if not (isinstance(full, np.ndarray) and full.shape == (n,)):
            full = sensed.extra[name] = np.full(n, np.nan)
        full[sl] = val


def join_references(refs: list[Reference]) -> Reference:
    """The formations' references of one step as the fleet's: members' rows in formation
    order; ``truth`` (k, 8), one row per formation's virtual car."""
    if len(refs) == 1:
        return refs[0]
    first = refs[0]
    if any(r.line is not first.line for r in refs):
        raise ValueError("the formations of a run share one reference line")
    info = {}
    for r in refs:
        info.update(r.info)
    return Reference(
        first.t, first.dt, np.concatenate([r.vc for r in refs], axis=1),
        np.concatenate([r.slots for r in refs], axis=1),
        np.concatenate([r.frame for r in refs]), np.concatenate([r.active for r in refs]),
        np.concatenate([r.v_cap for r in refs]), np.concatenate([r.a_cap for r in refs]),
        line=first.line, truth=np.stack([r.truth for r in refs]), info=info,
        a_cap_from=(None if all(r.a_cap_from is None for r in refs) else np.concatenate(
            [r.a_cap if r.a_cap_from is None else r.a_cap_from for r in refs])))
