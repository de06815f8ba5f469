"""A scenario's formations, each as the scenario it sees.

The run's builders (sim/setup.py, comm/link.py, ...) read one formation from a Scenario's
``leader``, ``members``, ``controller`` and ``comm``; :func:`formation_views` gives, for every
formation of the run, its formation_id and the scenario with those fields its own. The first
is the top-level formation: the scenario itself, so a one-formation run is built exactly as
before (a scenario without top-level members has none: its [[formations]] are the run's).
"""
from __future__ import annotations

from dataclasses import dataclass

from run_contract.columns import DEFAULT_FORMATION_ID

from .schema import Scenario


def formation_views(sc: Scenario) -> list[tuple[str, Scenario]]:
    """(formation_id, the scenario as that formation sees it) for every formation: its own
    leader, members, controller, comm, maneuvers and (on a road) ``road.start``."""
    views = [(DEFAULT_FORMATION_ID, sc)] if sc.members else []
    for f in sc.formations:
        update = {"leader": f.leader, "members": f.members, "controller": f.controller,
                  "comm": f.comm, "maneuvers": f.maneuvers, "formations": []}
        if sc.road is not None and f.start is not None:
            update["road"] = sc.road.model_copy(update={"start": f.start})
        views.append((f.id, sc.model_copy(update=update)))
    return views


@dataclass(frozen=True)
class FormationSetup:
    """One formation of a road run as prepared: its id, the scenario it sees
    (:func:`formation_views`), its departure time [s] and how many lanes left of the
    reference lane (``road.lane``) its slots' ``lanes`` count from."""

    id: str
    view: Scenario
    depart: float = 0.0
    lane_shift: int = 0
    field: str = ""  # its fields' path in the scenario file ('' or 'formations.<j>.')
    flow: str = ""  # the [[formation_flows]] id that inserts it ('' : none; it waits for room)


def formation_setups(sc: Scenario, flow_of: dict | None = None) -> list[FormationSetup]:
    """:class:`FormationSetup` of every formation, the top-level one first; ``flow_of``:
    formation id -> the flow that inserts it (sumo/formation_flows.py)."""
    flow_of = flow_of or {}
    out = []
    top = 1 if sc.members else 0  # the top-level formation comes first when it has members
    for j, (fid, view) in enumerate(formation_views(sc)):
        f = sc.formations[j - top] if j >= top else None
        lane = None if f is None or f.lane is None or sc.road is None else f.lane - sc.road.lane
        flow = flow_of.get(fid, "")
        out.append(FormationSetup(fid, view, float(sc.depart if f is None else f.depart), lane or 0,
                                  "" if f is None else (f"formation_flows.{flow}.formation." if flow
                                                        else f"formations.{j - top}."), flow))
    return out


def all_member_ids(sc: Scenario) -> list[str]:
    """Every member of every formation, in formation order (the run's fleet rows)."""
    return [m.id for _, view in formation_views(sc) for m in view.members]
