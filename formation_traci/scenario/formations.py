"""A scenario's formations, each as the scenario it sees.

The run's builders (sim/setup.py, comm/link.py, ...) read one formation from a Scenario's
``leader``, ``members``, ``controller`` and ``comm``; :func:`formation_views` gives, for every
formation of the run, its formation_id and the scenario with those fields its own. The first
is the top-level formation: the scenario itself, so a one-formation run is built exactly as
before.
"""
from __future__ import annotations

from ..record.columns import DEFAULT_FORMATION_ID
from .schema import Scenario


def formation_views(sc: Scenario) -> list[tuple[str, Scenario]]:
    """(formation_id, the scenario as that formation sees it) for every formation."""
    views = [(DEFAULT_FORMATION_ID, sc)]
    for f in sc.formations:
        views.append((f.id, sc.model_copy(update={
            "leader": f.leader, "members": f.members, "controller": f.controller,
            "comm": f.comm, "formations": []})))
    return views


def all_member_ids(sc: Scenario) -> list[str]:
    """Every member of every formation, in formation order (the run's fleet rows)."""
    return [m.id for _, view in formation_views(sc) for m in view.members]
