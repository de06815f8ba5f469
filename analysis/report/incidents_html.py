"""The run report's incident table (its first screen): who, when, where, from run.json
``incidents.events`` (formation_traci/sim/incident_log.py)."""
from __future__ import annotations

INCIDENT_ROWS = 10
"""Incidents listed on the report's first screen (all of run.json's in incidents.events)."""


def incidents_html(meta: dict, table) -> str:
    """The run's incidents on the first screen: who, when, where (run.json incidents.events);
    ``table(header, rows, left=...)``: the report's table writer."""
    inc = meta.get("incidents") or {}
    events = inc.get("events") or []
    if not events:
        return ""
    total = int(inc.get("events_total") or len(events))
    cols = ["t", "kind", "formation_id", "vehicle_id", "other_id", "edge", "lane", "s", "value"]
    rows = [[ev.get(c) for c in cols] for ev in events[:INCIDENT_ROWS]]
    more = total - len(rows)
    return ('<h2 class="bad">Incidents</h2><p>value: a collision\'s body clearance [m] '
            "(negative: overlap), an emergency brake's braking request [m/s^2], a stranded "
            "member's speed [m/s]; s [m] along the formation's road.</p>"
            + table(["t [s]", *cols[1:7], "s [m]", "value"], rows, left=6)
            + (f"<p>and {more} more (run.json incidents.events holds the first "
               f"{len(events)}; events.parquet all)</p>" if more > 0 else ""))
