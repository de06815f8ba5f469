"""Traffic demand asked for, inserted, and measured (docs/sumo.md, "Demand").

* :func:`flow_report`: per flow the vehicles asked for over its window up to the run's end
  (warm-up included) and the vehicles SUMO inserted; :func:`report_shortfall` turns a flow
  below :data:`SHORTFALL_SHARE` into an ``insertion_shortfall`` event and a warning (stderr
  and run.json ``warnings``); :func:`report_formation_shortfall` does the same for a formation
  flow (``formation_shortfall``).
* :func:`write_detectors` / :func:`read_detectors`: an induction loop and a 200 m lane-area
  detector on every lane at one point of the main route, so a run reports the traffic it
  really had there (flow [veh/h], density [veh/km], space-mean speed [m/s]) over the formation's
  part of the run, next to the demand it asked for.
"""
from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from .traffic import requested_vehicles

SHORTFALL_SHARE = 0.95
"""A flow that inserts less than this share of what it asked for is reported."""
DETECTOR_PERIOD = 10.0
"""Aggregation period of the measuring detectors [s]; intervals that begin in the warm-up are
left out (a warm-up that is not a multiple of it leaves out the interval it ends in)."""
AREA_LENGTH = 200.0
"""Length of the lane-area detectors that measure density [m] (shorter on a short edge)."""


def flow_report(flows, departed: dict[str, int], t_end: float,
                populated: dict[str, int] | None = None) -> dict[str, dict[str, int]]:
    """{flow id: {"requested": N, "inserted": M}}, the vehicles a flow placed along its
    route when it began (``populate``) included in both.

    Parameters
    ----------
    flows : list of (FlowSpec, edges, veh/h, end [s])
        The flows as written to SUMO's route file.
    departed : dict
        Flow id -> vehicles SUMO inserted.
    t_end : float
        SUMO time the run ended [s].
    populated : dict
        Flow id -> vehicles it placed along its route when it began.
    """
    populated = populated or {}
    return {spec.id: {"requested": requested_vehicles(vph, spec.begin, end, t_end) + populated.get(spec.id, 0),
                      "inserted": int(departed.get(spec.id, 0))}
            for spec, _, vph, end in flows}


def _shortfalls(counts: dict, kind: str, say, add_event, t: float) -> list[str]:
    """A ``kind`` event at formation time ``t`` [s] and a warning on stderr for every entry of
    ``counts`` (id -> {"requested", "inserted"}) below :data:`SHORTFALL_SHARE` of its request;
    ``say(id, counts, percent)`` words it. Returns the messages."""
    msgs = []
    for fid, c in counts.items():
        if c["requested"] > 0 and c["inserted"] < SHORTFALL_SHARE * c["requested"]:
            msg = say(fid, c, 100.0 * c["inserted"] / c["requested"])
            add_event(t, kind, fid, "", msg)
            msgs.append(msg)
            print(f"warning: {msg}", file=sys.stderr)
    return msgs


def report_shortfall(report: dict[str, dict[str, int]], add_event, t: float) -> list[str]:
    """Warn (stderr) and record an ``insertion_shortfall`` event at formation time ``t`` [s]
    for every flow that inserted less than :data:`SHORTFALL_SHARE` of its request.
    ``add_event(t, kind, vehicle_id, other_id, detail)`` records the event. Returns the messages."""
    return _shortfalls(report, "insertion_shortfall", lambda fid, r, pct: (
        f"flow {fid!r} inserted {r['inserted']} of {r['requested']} vehicles asked for "
        f"({pct:.0f} %): the road could not take the demand"), add_event, t)


def report_formation_shortfall(flows: dict, add_event, t: float) -> list[str]:
    """Warn (stderr) and record a ``formation_shortfall`` event at formation time ``t`` [s] for
    every formation flow (run.json ``formation_flows``) that inserted less than
    :data:`SHORTFALL_SHARE` of the formations due within the run (they waited for room on the
    road). Returns the messages."""
    return _shortfalls(flows, "formation_shortfall", lambda fid, c, pct: (
        f"formation flow {fid!r} inserted {c['inserted']} of {c['requested']} formations due "
        f"({pct:.0f} %): the others found no room on the road"), add_event, t)


def route_point(edges: list[str], lane_lengths: dict[str, float], s: float) -> tuple[str, float]:
    """Edge and position on it [m] at arc length ``s`` [m] along a route (internal lanes
    ignored); clamped to the route."""
    for e in edges:
        if s <= lane_lengths[e]:
            return e, max(s, 0.0)
        s -= lane_lengths[e]
    return edges[-1], lane_lengths[edges[-1]]


def write_detectors(path: Path, out: Path, edge: str, n_lanes: int, length: float, pos: float) -> float:
    """Additional file: on every lane of ``edge`` (lane length ``length`` [m]) an induction loop
    at ``pos`` [m] and a lane-area detector of up to :data:`AREA_LENGTH` around it. Returns
    the lane-area detectors' length [m]."""
    pos = min(max(pos, 0.1), length - 0.1)
    a0 = max(0.0, min(pos - AREA_LENGTH / 2, length - AREA_LENGTH))
    a1 = min(length, a0 + AREA_LENGTH)
    lines = ["<additional>"]
    for k in range(n_lanes):
        lane = f"{edge}_{k}"
        lines.append(f'  <inductionLoop id="measure_e1_{k}" lane="{lane}" pos="{pos:.2f}" '
                     f'period="{DETECTOR_PERIOD}" file="{out.name}"/>')
        lines.append(f'  <laneAreaDetector id="measure_e2_{k}" lane="{lane}" pos="{a0:.2f}" '
                     f'endPos="{a1:.2f}" period="{DETECTOR_PERIOD}" file="{out.name}"/>')
    lines.append("</additional>")
    path.write_text("\n".join(lines) + "\n")
    return a1 - a0


def read_detectors(out: Path, t0: float, area_m: float, t1: float = float("inf")) -> dict | None:
    """Flow [veh/h] summed over the lanes, density [veh/km] summed over the lanes and
    space-mean speed q/k [m/s] over the detector intervals that begin at or after ``t0`` [s]
    (the formation's part of the run); ``area_m`` is the lane-area detectors' length [m].
    None if there is no complete interval."""
    if not out.exists():
        return None
    counts, seconds, veh_seconds, n_area = 0, set(), 0.0, 0
    try:
        for _, el in ET.iterparse(out):
            if el.tag != "interval":
                continue
            b, e = float(el.get("begin")), float(el.get("end"))
            if b < t0 - 1e-6 or e > t1 + 1e-6:  # the formation's part only (no drain)
                continue
            det = el.get("id", "")
            if det.startswith("measure_e1_"):
                counts += int(float(el.get("nVehContrib", 0)))
                seconds.add((b, e))
            elif det.startswith("measure_e2_"):
                veh_seconds += float(el.get("meanVehicleNumber", 0.0)) * (e - b)
                n_area += 1
            el.clear()
    except ET.ParseError:
        pass
    span = sum(e - b for b, e in seconds)
    if span <= 0 or not n_area or area_m <= 0:
        return None
    q = counts * 3600.0 / span
    k = veh_seconds / span / (area_m / 1000.0)
    return {"flow_veh_h": q, "density_veh_km": k, "speed_mps": (q / k / 3.6) if k > 0 else None,
            "seconds": span}


def measure_plan(sc, road, sumo_dir: Path) -> dict | None:
    """Detectors that measure flow and density at ``traffic.measure_at`` along the main route."""
    if sc.traffic.measure_at is None or not sc.traffic.flows or sc.sumo.attach_port is not None:
        return None
    edge, pos = route_point(road.route, road.edge_length, sc.traffic.measure_at)
    out = sumo_dir / "measure.xml"
    area = write_detectors(sumo_dir / "measure.add.xml", out, edge, road.edge_lanes[edge],
                           road.edge_length[edge], pos)
    return {"file": sumo_dir / "measure.add.xml", "out": out, "edge": edge, "pos": pos, "area_m": area}


def traffic_meta(meta, rec, flows, departed, t_sumo, t0, measure, populated=None) -> None:
    """run.json ``traffic``: flows requested/inserted, the measured operating point; a
    flow short of its demand is an ``insertion_shortfall`` event and a warning."""
    report = flow_report(flows, departed, t_sumo, populated)
    tr = meta["traffic"] = {"flows": report}
    meta.setdefault("warnings", []).extend(report_shortfall(report, rec.add_event, max(t_sumo - t0, 0.0)))
    if measure is not None:
        tr["measured"] = {"edge": measure["edge"], "pos_m": measure["pos"],
                          **(read_detectors(measure["out"], t0, measure["area_m"], t_sumo) or {})}
