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

from run_contract.columns import VIRTUAL_CAR_ID

from ..control.reference import Reference, SensingTransform
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
    depart: float = 0.0  # run time its members enter the world [s]; its generator's time starts then
    parked: object = None  # t -> Reference while it waits or after it ended (no member in the run)
    held: FleetState | None = None  # its members' rows while it is parked (their state is held)
    status: str = "running"  # waiting (to depart) | running | done (retired at the end of its route)
    flow: str = ""  # the formation flow that inserts it: it enters only where there is room
    left: float | None = None  # run time it was retired at the end of its route [s]

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
    if any(c.model != first.model or c.physics_step != first.physics_step
           or c.variant != first.variant or c.variant_params != first.variant_params for c in cfgs):
        raise ValueError("the formations of a run share vehicle.model, vehicle.variant (and its "
                         "parameters) and run.physics_step")
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


def merge_extra(sensed: Sensed, part: Sensed, sl: slice) -> None:
    """The recorded columns ``part`` (a formation's :func:`sensed_of`) holds into
    ``sensed``'s rows ``sl``."""
    n = len(sensed.active)
    for name, val in part.extra.items():
        full = sensed.extra.get(name)
        if not (isinstance(full, np.ndarray) and full.shape == (n,)):
            full = sensed.extra[name] = np.full(n, np.nan)
        full[sl] = val


def join_references(refs: list[Reference], n_nb: int | None = None) -> Reference:
    """The formations' references of one step as the fleet's: members' rows in formation
    order; ``truth`` (k, 8), one row per formation's virtual car; ``info``: :func:`join_info`."""
    if len(refs) == 1:
        return refs[0]
    first = refs[0]
    if any(r.line is not first.line for r in refs):
        raise ValueError("the formations of a run share one reference line")
    info = join_info(refs, n_nb)
    return Reference(
        first.t, first.dt, np.concatenate([r.vc for r in refs], axis=1),
        np.concatenate([r.slots for r in refs], axis=1),
        np.concatenate([r.frame for r in refs]), np.concatenate([r.active for r in refs]),
        np.concatenate([r.v_cap for r in refs]), np.concatenate([r.a_cap for r in refs]),
        line=first.line, truth=np.stack([r.truth for r in refs]), info=info,
        a_cap_from=(None if all(r.a_cap_from is None for r in refs) else np.concatenate(
            [r.a_cap if r.a_cap_from is None else r.a_cap_from for r in refs])))


def join_info(refs: list[Reference], n_nb: int | None = None) -> dict:
    """The generators' diagnostics of several formations as one: per-member arrays joined in
    formation order, per-formation values as one array (one per virtual car). ``n_nb``: how
    many neighbours the world itself sensed; a lead vehicle index at or beyond it is another
    formation's member (sumo/peers.py), given as -1 (no vehicle of the traffic)."""
    info = {}
    for key in dict.fromkeys(k for r in refs for k in r.info):
        vals = [r.info.get(key) for r in refs]
        if all(isinstance(v, np.ndarray) and v.shape == r.active.shape for v, r in zip(vals, refs)):
            info[key] = np.concatenate(vals)
        elif all(v is not None and np.ndim(v) == 0 for v in vals):
            info[key] = np.array(vals)
        else:
            info[key] = vals
    if n_nb is not None and "lead_idx" in info:
        info["lead_idx"] = np.where(info["lead_idx"] >= n_nb, -1, info["lead_idx"])
    return info


def depart_due(f: Formation, world, t: float, state: FleetState, blocked: set) -> None:
    """Formation ``f`` is due at t [s]: its members enter the world (its generator's time
    starts now). One of a formation flow enters only where there is room, one per flow and
    step, in order (``blocked``: the flows whose due formation is still waiting)."""
    if not enters(f, world, t, state, blocked):
        return
    world.spawn(t, np.arange(f.members.start, f.members.stop))
    f.status, f.depart = "running", t


def enters(f: Formation, world, t: float, state: FleetState, blocked: set) -> bool:
    """Does formation ``f``, due at t [s], enter now (:func:`depart_due`'s rule; nothing
    changes but ``blocked``, which gets its flow)? One of a flow needs room and is the first
    due of its flow this step."""
    if f.flow and (f.flow in blocked or not world.has_room(t, f.members, state)):
        blocked.add(f.flow)
        return False
    if f.flow:
        blocked.add(f.flow)
    return True


def retire_formation(f: Formation, world, t: float, state: FleetState, rec, stop,
                     active: np.ndarray | None = None) -> None:
    """Formation ``f`` ends (its generator's ``stop`` = (event kind, detail, why): the end of
    its route): the event for its virtual car, its members out of the world (member_retired),
    their state held from now on. ``active``: the step's reference's members in the run,
    cleared for ``f``'s members (no comfort row of theirs after t)."""
    kind, detail, why = stop
    if kind:
        rec.add_event(t, kind, f.vc_id, "", detail)
    world.retire(t, np.arange(f.members.start, f.members.stop), f"formation {f.id}: {why}")
    f.status, f.held, f.left = "done", state.rows(f.members), t
    if active is not None:
        active[f.members] = False


FORMATION_STATUS = {"waiting": "it never entered the road", "on_road": "on the road at the run's end",
                    "done": "retired at the end of its route", "retired": "every member out of the run "
                    "before the end of its route (removed, dropped, handed over)"}
"""run.json ``formations.<id>.status`` values and their meaning."""


def formations_meta(forms: list, active: np.ndarray | None = None) -> dict:
    """run.json ``formations`` of a run of several formations (or one that departs later): per
    formation when it entered the road and left it [s] (None: never / not before the end) and
    its status at the end (:data:`FORMATION_STATUS`; ``active``: the fleet rows still in the
    run, telling ``on_road`` from ``retired``)."""
    def status(f) -> str:
        if f.status != "running":
            return f.status
        gone = active is not None and not np.asarray(active)[f.members].any()
        return "retired" if gone else "on_road"

    return {f.id: {"entered_s": None if f.status == "waiting" else float(f.depart),
                   "left_s": f.left, "status": status(f), "flow": f.flow or None} for f in forms}
