"""The incidents themselves: who, when, where (run.json ``incidents.events``).

Every incident the verdict counts (sim/incidents.py) is also one entry here: its kind, the run
time t [s], the formation, the vehicle (a member, or a formation's virtual car), the other party
(the member or SUMO vehicle it collided with; '' when none), where the vehicle was (SUMO edge,
lane index, arc length s [m] along the formation's road; None where not known, e.g. in free
space) and the kind's value (:data:`INCIDENT_EVENT_KINDS`). The first :data:`MAX_EVENTS` are
kept whole; every one is counted per formation and kind. A new incident kind is one entry of
:data:`INCIDENT_EVENT_KINDS` and its producer's ``rec.add_event(..., value=...)``.
"""
from __future__ import annotations

import math

INCIDENT_EVENT_KINDS: dict[str, tuple[str, str]] = {
    "member_collision": ("member_collisions", "body clearance [m] (negative: overlap; NaN: not known)"),
    "member_removed": ("member_removed", "-"),
    "emergency_brake": ("emergency_brakes", "braking request [m/s^2]"),
    "stranded": ("stranded", "speed [m/s]"),
}
"""Event kind -> (its run.json ``incidents`` count, what its ``value`` is)."""

MAX_EVENTS = 100
"""Incidents kept whole in run.json (the rest counted; all are in events.parquet)."""


def _num(x) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


class IncidentLog:
    """The run's incidents as they happen (see the module docstring).

    ``formation_of``: vehicle id -> formation id (members and virtual cars); ``locate``
    (set by a road world): vehicle id -> (edge, lane index, s [m]) where it was last sensed."""

    def __init__(self, formation_of: dict | None = None):
        self.formation_of = dict(formation_of or {})
        self.locate = None
        self.events: list[dict] = []
        self.total = 0
        self.by_formation: dict[str, dict[str, int]] = {}

    def add(self, t: float, kind: str, vehicle_id: str, other_id: str = "", value=None) -> None:
        """One incident of ``kind`` (a key of :data:`INCIDENT_EVENT_KINDS`) at run time t [s]."""
        fid = self.formation_of.get(vehicle_id) or self.formation_of.get(other_id) or ""
        count = INCIDENT_EVENT_KINDS[kind][0]
        per = self.by_formation.setdefault(fid, {})
        per[count] = per.get(count, 0) + 1
        self.total += 1
        if len(self.events) >= MAX_EVENTS:
            return
        edge, lane, s = (None, None, None)
        if self.locate is not None:
            edge, lane, s = self.locate(vehicle_id)
        self.events.append({"kind": kind, "t": round(float(t), 6), "formation_id": fid or None,
                            "vehicle_id": vehicle_id, "other_id": other_id or None, "edge": edge,
                            "lane": lane, "s": _num(s), "value": _num(value)})

    def meta(self) -> dict:
        """run.json ``incidents``' additions: ``events`` (the first :data:`MAX_EVENTS`),
        ``events_total`` and ``by_formation`` (formation id -> count name -> n)."""
        return {"events": list(self.events), "events_total": self.total,
                "by_formation": {k: dict(v) for k, v in sorted(self.by_formation.items())}}


def describe(ev: dict) -> str:
    """One line naming an incident of run.json ``incidents.events``."""
    where = ", ".join(p for p in (
        f"formation {ev['formation_id']}" if ev.get("formation_id") else "",
        f"edge {ev['edge']}" if ev.get("edge") else "",
        f"lane {ev['lane']}" if ev.get("lane") is not None else "",
        f"s = {ev['s']:.1f} m" if ev.get("s") is not None else "") if p)
    other = f" with {ev['other_id']}" if ev.get("other_id") else ""
    value = ""
    if ev.get("value") is not None:
        value = {"member_collision": f"clearance {ev['value']:.2f} m",
                 "emergency_brake": f"braking request {ev['value']:.2f} m/s^2",
                 "stranded": f"v = {ev['value']:.2f} m/s"}.get(ev["kind"], f"value {ev['value']:.3g}")
    return (f"t = {ev['t']:.2f} s {ev['kind']}: {ev['vehicle_id']}{other}"
            + (f" ({where})" if where else "") + (f", {value}" if value else ""))
