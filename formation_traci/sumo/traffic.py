"""Background traffic as a SUMO route file: vehicle types, routes and seeded flows."""
from __future__ import annotations

import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

from ..scenario.schema import FlowSpec

CAR = dict(vClass="passenger", length="4.5", width="1.8", minGap="2.5", maxSpeed="41.67",
           accel="2.6", decel="4.5", emergencyDecel="9.0", sigma="0.5", color="200,200,200")
"""SUMO passenger car (Krauss car-following, SUMO's default lane-change model)."""
TRUCK = dict(vClass="truck", length="12.0", width="2.5", minGap="3.0", maxSpeed="25.0",
             accel="1.0", decel="4.0", emergencyDecel="7.0", sigma="0.5", color="120,120,120")
"""SUMO truck, 90 km/h limited."""
BASE_TYPES = {"car": CAR, "truck": TRUCK}


def _attrs(d: dict) -> str:
    return " ".join(f"{k}={quoteattr(str(v))}" for k, v in d.items())


def flow_vehicles_per_hour(flow: FlowSpec, lanes_of_first_edge: int) -> float:
    """Total demand of a flow [veh/h]."""
    if flow.veh_per_hour is not None:
        return flow.veh_per_hour
    return flow.veh_per_hour_per_lane * lanes_of_first_edge


def requested_vehicles(vph: float, begin: float, end: float, t_end: float) -> int:
    """Vehicles a flow of ``vph`` [veh/h] asks SUMO for before ``min(end, t_end)`` [s]: SUMO
    departs them every 3600 / vph seconds from ``begin`` on (the first at ``begin``).
    SUMO rounds departure times to its millisecond clock, so where a departure falls on
    ``t_end`` itself SUMO may insert one vehicle more than this count."""
    window = min(end, t_end) - begin
    if vph <= 0 or window <= 0:
        return 0
    return int(math.ceil(window * vph / 3600.0 - 1e-9))


POPULATE_JITTER = 0.3
"""A populated vehicle's place along the route varies by up to this share of the spacing."""


def populate_places(vph: float, v_mps: float, lengths: list[float], seed: int) -> list[tuple[int, float]]:
    """Where a flow's vehicles stand when it begins with ``populate``: (index of the route
    edge, position on it [m]) in driving order.

    Free flow of ``vph`` [veh/h] at ``v_mps`` [m/s] has a density of vph / (3600 v) vehicles
    per metre of road (all lanes): one vehicle every ``3600 v / vph`` metres along the route,
    each moved by up to :data:`POPULATE_JITTER` of that spacing (the run's seed; its own
    stream), none in the last 50 m of an edge (SUMO's junctions) nor the route's last 100 m.
    ``lengths`` [m]: the route's edges."""
    import numpy as np

    spacing = 3600.0 * v_mps / vph
    total = float(sum(lengths))
    n = max(int((total - 100.0) / spacing), 0)
    rng = np.random.default_rng([int(seed), 0x706F70])  # its own stream: 'pop'
    s_all = (np.arange(n) + 0.5 + rng.uniform(-POPULATE_JITTER, POPULATE_JITTER, n)) * spacing
    starts = np.concatenate([[0.0], np.cumsum(lengths)])
    places = []
    for s in s_all.tolist():
        k = int(np.searchsorted(starts, s, side="right")) - 1
        pos = s - float(starts[k])
        if 0 <= k < len(lengths) and pos <= lengths[k] - 50.0:
            places.append((k, round(pos, 2)))
    return places


def write_routes(path: Path, flows: list[tuple[FlowSpec, list[str], float]], end: float,
                 populated: dict[str, list[tuple[int, float]]] | None = None) -> Path:
    """Write vTypes, routes and flows. ``flows`` holds (spec, edges, veh/h); ``end`` [s] is
    the default end of every flow. Each flow draws its types from its own distribution.
    ``populated``: flow id -> (route edge index, position [m]) of its vehicles placed when it
    begins (:func:`populate_places`), SUMO vehicles ``<flow id>.p<n>`` on the rest of its route,
    written downstream first: SUMO inserts each at the highest speed that is safe behind the
    vehicles ahead of it (``departSpeed="max"``), while one written upstream first would have to be
    safe for a fast vehicle already behind it, fail, and hold up every later one on its edge."""
    populated = populated or {}
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<routes>"]
    for spec, edges, vph in flows:
        dist = f"{spec.id}_types"
        lines.append(f'  <vTypeDistribution id="{dist}">')
        for kind, share in spec.mix.items():
            if share <= 0:
                continue
            dev = spec.speed_dev if kind == "car" else spec.speed_dev / 2
            attrs = dict(BASE_TYPES[kind], speedFactor=f"normc(1,{dev},0.2,2)", probability=share)
            lines.append(f'    <vType id="{spec.id}_{kind}" {_attrs(attrs)}/>')
        lines.append("  </vTypeDistribution>")
        lines.append(f'  <route id="{spec.id}_route" edges="{" ".join(edges)}"/>')
        for k in sorted({k for k, _ in populated.get(spec.id, ())}):
            lines.append(f'  <route id="{spec.id}_route.{k}" edges="{" ".join(edges[k:])}"/>')
    for spec, edges, vph in flows:
        placed = list(enumerate(populated.get(spec.id, ())))
        for n, (k, pos) in placed[::-1]:  # downstream first: each is inserted behind those ahead
            lines.append(f'  <vehicle id="{spec.id}.p{n}" type="{spec.id}_types" route="{spec.id}_route.{k}" '
                         f'depart="{spec.begin}" departLane="best" departSpeed="{spec.depart_speed}" '
                         f'departPos="{pos}"/>')
        f_end = spec.end if spec.end is not None else end
        lines.append(
            f'  <flow id="{spec.id}" type="{spec.id}_types" route="{spec.id}_route" '
            f'begin="{spec.begin}" end="{f_end}" vehsPerHour="{vph:.3f}" '
            f'departLane="{spec.depart_lane}" departSpeed="{spec.depart_speed}" departPos="{spec.depart_pos}"/>')
    lines.append("</routes>")
    path.write_text("\n".join(lines) + "\n")
    return path
