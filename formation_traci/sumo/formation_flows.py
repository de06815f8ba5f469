"""Formations inserted by a flow ([[formation_flows]], docs/scenarios.md "Formation flows").

Before the run each flow becomes the formations it asks for over the run: formation ``k`` of
flow ``F`` is ``F.k`` (members ``F.k.<member>``), due at ``begin + k T``, with T from the
flow's rule: ``period_s``; ``veh_per_hour`` formation vehicles (T = n 3600 / veh_per_hour for
n members); or ``penetration`` p of traffic flow ``of_flow`` of Q veh/h (T = n 3600 / (p Q),
and that flow keeps (1 - p) Q: the demand stays Q, a share p of it formation vehicles; several
penetration flows of one traffic flow (e.g. one per lane) take their shares from it together). At
run time a due formation waits until its members' insertion zones are free (sim/loop.py,
SumoWorld.has_room; one formation of a flow per step, in order) and then enters; run.json
``formation_flows.<id>`` counts the formations requested (due within the run) and inserted.
A run whose flows ask for no formation (a penetration of 0) and that has no other formation
keeps its first flow's formation ``F.0``, due after the run: it never enters, and the run is
SUMO's traffic alone, recorded and measured as any other.
"""
from __future__ import annotations

import math

from ..scenario.load import ScenarioError
from ..scenario.schema import FormationSpec, Scenario
from .traffic import flow_vehicles_per_hour

MAX_FLOW_FORMATIONS = 1000
"""A flow asks for at most this many formations over a run (each is rows of the fleet)."""


def flow_period(sc: Scenario, flow, lanes_of: dict) -> float:
    """Time between the formations of ``flow`` [s] (inf: none); ``lanes_of``: traffic flow id
    -> lanes of its first edge."""
    n = len(flow.formation.members)
    if flow.period_s is not None:
        return float(flow.period_s)
    if flow.veh_per_hour is not None:
        return n * 3600.0 / flow.veh_per_hour
    if flow.penetration == 0.0:
        return math.inf
    spec = next(f for f in sc.traffic.flows if f.id == flow.of_flow)
    return n * 3600.0 / (flow.penetration * flow_vehicles_per_hour(spec, lanes_of[spec.id]))


def expand_flows(sc: Scenario, lanes_of: dict, source=None):
    """(the scenario with every flow's formations as [[formations]] entries and no flows,
    formation id -> its flow's id, traffic flow id -> the share of its demand it keeps,
    formation flow id -> the traffic flow it is a share of, or '')."""
    if not sc.formation_flows:
        return sc, {}, {}, {}
    out, flow_of, keep = list(sc.formations), {}, {}
    for j, fl in enumerate(sc.formation_flows):
        period = flow_period(sc, fl, lanes_of)
        if fl.penetration is not None:
            keep[fl.of_flow] = keep.get(fl.of_flow, 1.0) - fl.penetration
            if keep[fl.of_flow] <= 0.0:
                raise ScenarioError(source or "<scenario>", [(f"formation_flows.{j}.penetration", (
                    f"the penetrations of flow {fl.of_flow!r} add up to 1 or more: expected a sum below 1"))])
        end = min(sc.run.duration if fl.end is None else fl.end, sc.run.duration)
        count = 0 if not math.isfinite(period) or fl.begin >= end else math.ceil((end - fl.begin) / period)
        if count > MAX_FLOW_FORMATIONS:
            raise ScenarioError(source or "<scenario>", [(f"formation_flows.{j}", (
                f"asks for {count} formations over the run (one every {period:.2f} s); at most "
                f"{MAX_FLOW_FORMATIONS}: a longer period or a shorter run"))])
        for k in range(count):
            out.append(_instance(fl, k, fl.begin + k * period))
            flow_of[out[-1].id] = fl.id
    if not out and not sc.members:  # no formation at all: traffic alone (see the module docstring)
        fl = sc.formation_flows[0]
        out.append(_instance(fl, 0, never_due(sc)))
        flow_of[out[-1].id] = fl.id
    share_of = {fl.id: fl.of_flow or "" for fl in sc.formation_flows}
    return sc.model_copy(update={"formations": out, "formation_flows": []}), flow_of, keep, share_of


def never_due(sc: Scenario) -> float:
    """A departure time after the run's end [s]: a formation due then never enters."""
    return 2.0 * float(sc.run.duration) + 1.0


def _instance(fl, k: int, t: float) -> FormationSpec:
    """Formation k of flow ``fl``, due at run time t [s]."""
    fid = f"{fl.id}.{k}"
    tpl = fl.formation
    comm = tpl.comm
    if comm is not None and comm.links:
        comm = comm.model_copy(update={"links": {f"{fid}.{m}": v for m, v in comm.links.items()}})
    members = [m.model_copy(update={"id": f"{fid}.{m.id}"}) for m in tpl.members]
    return FormationSpec(id=fid, leader=tpl.leader, members=members, controller=tpl.controller,
                         comm=comm, start=fl.start, depart=t,
                         lane=fl.lane[k % len(fl.lane)] if isinstance(fl.lane, list) else fl.lane)
