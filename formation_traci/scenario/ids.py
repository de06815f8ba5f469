"""Ids unique over the whole run, with the formation flows expanded: formations, members, virtual
cars and SUMO's background vehicles.

A formation flow ``F`` inserts formations ``F.<k>`` with members ``F.<k>.<member>``
(sumo/formation_flows.py); SUMO names the vehicles of traffic flow ``T`` ``T.<n>``; the virtual
car is ``vc`` (``vc:<formation>`` with several formations). ``k`` and ``n`` run over every
integer, so a clash is found from the scenario alone, before the run and whatever the demand.
"""
from __future__ import annotations

import re

from run_contract.columns import VIRTUAL_CAR_ID


def _members(sc) -> list[tuple[str, str]]:
    """(field of the id, member id) of every member given by id (top level and [[formations]])."""
    out = [(f"members.{i}.id", m.id) for i, m in enumerate(sc.members or [])]
    for j, f in enumerate(sc.formations):
        out += [(f"formations.{j}.members.{i}.id", m.id) for i, m in enumerate(f.members)]
    return out


def _flow_member(flow, j: int, member_id: str) -> tuple[str, str] | None:
    """(field, template member) of formation flow ``flow`` (entry j) whose generated id
    ``flow.<k>.<member>`` can be ``member_id``, or None."""
    for i, m in enumerate(flow.formation.members):
        if re.fullmatch(rf"{re.escape(flow.id)}\.\d+\.{re.escape(m.id)}", member_id):
            return f"formation_flows.{j}.formation.members.{i}.id", m.id
    return None


def _background(sc, member_id: str) -> str | None:
    """The field of the traffic flow whose SUMO vehicles ``T.<n>`` (and, with ``populate``,
    ``T.p<n>``) can be named ``member_id``."""
    for t, fl in enumerate(sc.traffic.flows):
        if re.fullmatch(rf"{re.escape(fl.id)}\.p?\d+", member_id):
            return f"traffic.flows.{t}.id"
    return None


def _generated_background(sc, flow, j: int) -> list[tuple[str, str]]:
    """Clashes of formation flow ``flow``'s generated member ids with background vehicles."""
    out = []
    for i, m in enumerate(flow.formation.members):
        head, _, last = m.id.rpartition(".")
        if not last.isdigit():
            continue  # 'T.<n>' ends in digits
        pattern = rf"{re.escape(flow.id)}\.\d+" + (rf"\.{re.escape(head)}" if head else "")
        for t, fl in enumerate(sc.traffic.flows):
            if re.fullmatch(pattern, fl.id):
                out.append((f"formation_flows.{j}.formation.members.{i}.id",
                            f"{m.id!r} gives members '{flow.id}.<k>.{m.id}', the names SUMO gives the "
                            f"vehicles of traffic flow {fl.id!r} (traffic.flows.{t}.id): rename one"))
    return out


def id_clashes(sc) -> list[tuple[str, str]]:
    """Every clash of ids in scenario ``sc`` (a Scenario): (dotted field, message naming the
    other side); [] if none.

    Parameters
    ----------
    sc : Scenario
        The validated scenario, its formation flows not yet expanded.

    Returns
    -------
    list of (str, str)
        One entry per clash.
    """
    out = []
    for j, fl in enumerate(sc.formation_flows):
        for k, f in enumerate(sc.formations):
            if re.fullmatch(rf"{re.escape(fl.id)}\.\d+", f.id):
                out.append((f"formations.{k}.id", f"{f.id!r} is also the id of a formation that formation flow "
                                                  f"{fl.id!r} (formation_flows.{j}) inserts ('{fl.id}.<k>'): rename one"))
        ids = [m.id for m in fl.formation.members]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            out.append((f"formation_flows.{j}.formation.members", f"ids must be unique, repeated: {dup}"))
        out += _generated_background(sc, fl, j)
    for field, mid in _members(sc):
        if mid == VIRTUAL_CAR_ID and field.startswith("formations."):  # top level: schema.py
            out.append((field, f"member id {VIRTUAL_CAR_ID!r} is reserved for the virtual car"))
        for j, fl in enumerate(sc.formation_flows):
            hit = _flow_member(fl, j, mid)
            if hit:
                out.append((field, f"{mid!r} is also the id of a member that formation flow {fl.id!r} "
                                   f"inserts ({hit[0]} {hit[1]!r} gives '{fl.id}.<k>.{hit[1]}'): rename one"))
        flow_field = _background(sc, mid)
        if flow_field:
            out.append((field, f"{mid!r} is also the name SUMO gives a vehicle of traffic flow "
                               f"{mid.rpartition('.')[0]!r} ({flow_field}: '<id>.<n>'): rename one"))
    return out
