"""Measurement sections: fixed cross-sections of the main route, upstream of, along and
downstream of the formation's path, through which every vehicle is timed by SUMO itself
(an ``instantInductionLoop`` on every lane: one record per vehicle passing, nothing in our
step loop), in the formation run and in its twin alike (docs/metrics.md, "Sections").

After the formation's last step the stretch is drained: the members leave SUMO and SUMO runs
on until every vehicle inside the stretch has passed its last section (or left the network),
at most ``traffic.sections.drain_max`` seconds, so the vehicles the formation held up are
timed over the whole stretch. Nothing is recorded into the run's tables during the drain.

* :func:`plan_sections`: where the sections go (fixed by the scenario, the same in both runs)
  and SUMO's additional file;
* :func:`drain`: SUMO's steps after the run;
* :func:`write_tables`: ``sections.parquet`` (the passages) and ``departures.parquet``.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..record.writer import atomic_write_parquet
from .demand import route_point

if TYPE_CHECKING:  # pandas (~0.15 s to import, with pyarrow) is imported where the tables are
    import pandas as pd  # written, after the run: never before its first step

PREFIX = "section_"
"""Detector ids: ``section_<k>_<lane>``."""
FIRST_M = 20.0
"""No section nearer the route's start [m]: vehicles enter the network with their front
bumper a car length in, so a loop there would miss them."""
CHECK_EVERY_S = 1.0
"""How often the drain looks whether the stretch is empty [s of SUMO time]."""


def formation_reach(sc) -> float:
    """How far along the road the formation can get [m]: road.start plus the leader's top
    set speed over run.duration (a bound known before the run, the same for its twin)."""
    from ..scenario.schema import ProfileSpec

    spd = sc.leader.speed
    v = max(spd.values) if isinstance(spd, ProfileSpec) else float(spd)
    return float(sc.road.start) + max(v, 0.0) * float(sc.run.duration)


def section_positions(sc, route_length: float) -> list[tuple[str, float]]:
    """(role, arc length [m]) of every section, upstream first: ``upstream``, ``at`` (evenly
    over the formation's path from road.start to its reach), ``downstream``; clamped to the
    route, duplicates dropped."""
    spec = sc.traffic.sections
    lo, hi = FIRST_M, max(route_length - 1.0, FIRST_M)
    s0 = float(sc.road.start)
    s1 = formation_reach(sc)
    up = min(max(s0 - spec.upstream, lo), hi)
    down = min(max(s1 + spec.downstream, lo), hi)
    at_end = min(s1, down)
    inner = [s0 + (at_end - s0) * (i + 0.5) / spec.inner for i in range(spec.inner)] if at_end > s0 else []
    out: list[tuple[str, float]] = [("upstream", up)]
    for s in inner:
        if up < s < down:
            out.append(("at", s))
    if down > up:
        out.append(("downstream", down))
    return out


def plan_sections(sc, road, sumo_dir: Path) -> dict | None:
    """The sections of this scenario and SUMO's additional file placing them (None when
    ``traffic.sections.enabled`` is off, there is no traffic, or SUMO is attached to)."""
    spec = sc.traffic.sections
    if not spec.enabled or not sc.traffic.flows or sc.sumo.attach_port is not None:
        return None
    length = sum(road.edge_length[e] for e in road.route)
    lines, sections = ["<additional>"], []
    out = sumo_dir / "sections.xml"
    for k, (role, s) in enumerate(section_positions(sc, length)):
        edge, pos = route_point(road.route, road.edge_length, s)
        pos = min(max(pos, 0.1), road.edge_length[edge] - 0.1)
        sections.append({"section": k, "role": role, "s_m": s, "edge": edge, "pos_m": pos})
        for lane in range(road.edge_lanes[edge]):
            lines.append(f'  <instantInductionLoop id="{PREFIX}{k}_{lane}" lane="{edge}_{lane}" '
                         f'pos="{pos:.2f}" file="{out.name}"/>')
    lines.append("</additional>")
    add = sumo_dir / "sections.add.xml"
    add.write_text("\n".join(lines) + "\n")
    return {"file": add, "out": out, "sections": sections, "route": list(road.route),
            "lanechanges": sumo_dir / "lanechanges.xml"}


def sumo_options(plan: dict | None) -> list[str]:
    """SUMO options the sections need besides their additional file: every lane change on record."""
    if plan is None:
        return []
    return ["--lanechange-output", str(plan["lanechanges"])]


def _inside(plan: dict, edge: str, pos: float) -> bool:
    """A vehicle at (edge, pos) has not passed the last section yet (internal lanes count
    as inside; edges off the route as outside)."""
    last = plan["sections"][-1]
    route = plan["route"]
    if edge.startswith(":"):
        return True
    if edge not in route:
        return False
    i, j = route.index(edge), route.index(last["edge"])
    return i < j or (i == j and pos < last["pos_m"])


def drain(adapter, plan: dict, members: list[str], max_s: float, step: float,
          should_stop=None) -> dict:
    """After the run: take ``members`` out of SUMO and step SUMO until every vehicle that is
    inside the stretch now has passed its last section, at most ``max_s`` [s] (or until
    ``should_stop()``, polled every :data:`CHECK_EVERY_S`, says so: Ctrl-C). Returns what
    run.json records (``drain_s``, ``left_inside``: vehicles still inside at the end)."""
    for vid in members:
        try:
            adapter.remove_vehicle(vid)
        except Exception:
            pass  # already gone
    pending = {v for v, (edge, pos) in adapter.vehicle_places().items()
               if v not in members and _inside(plan, edge, pos)}
    n_steps, every = int(round(max_s / step)), max(1, int(round(CHECK_EVERY_S / step)))
    k = 0
    while pending and k < n_steps:
        adapter.simulation_step()
        k += 1
        if k % every == 0:
            if should_stop is not None and should_stop():
                break
            places = adapter.vehicle_places(pending)
            pending = {v for v in pending if v in places and _inside(plan, *places[v])}
    return {"drain_s": k * step, "left_inside": len(pending)}


def read_passages(xml: Path, t0: float, members: set[str], plan: dict) -> pd.DataFrame:
    """SUMO's detector records -> one row per vehicle and section it entered: ``vehicle_id``,
    ``section``, ``lane`` (index), ``t`` [s, formation time], ``v`` [m/s], ``length`` [m],
    ``vtype``, ``member`` (a formation member: the leader of the vehicle behind it, never
    one of the timed vehicles). A damaged file gives what was parsed."""
    import pandas as pd

    rows = []
    if xml.exists():
        try:
            for _, el in ET.iterparse(xml):
                if el.tag == "instantOut" and el.get("state") == "enter":
                    vid = el.get("vehID", "")
                    k, _, lane = el.get("id", "").removeprefix(PREFIX).partition("_")
                    rows.append((vid, int(k), int(lane), float(el.get("time")) - t0,
                                 float(el.get("speed", "nan")), float(el.get("length", "nan")),
                                 el.get("type", ""), vid in members))
                el.clear()
        except ET.ParseError:
            pass
    df = pd.DataFrame(rows, columns=["vehicle_id", "section", "lane", "t", "v", "length", "vtype", "member"])
    s = {sec["section"]: sec["s_m"] for sec in plan["sections"]}
    df.insert(2, "s_m", df["section"].map(s).astype(float))
    return df.sort_values(["section", "t", "lane", "vehicle_id"], kind="stable").reset_index(drop=True)


def read_lane_changes(xml: Path, t0: float, members: set[str]) -> pd.DataFrame:
    """SUMO's ``--lanechange-output`` -> ``vehicle_id``, ``t`` [s, formation time], ``from_lane``,
    ``to_lane`` (lane ids); members left out."""
    import pandas as pd

    rows = []
    if xml.exists():
        try:
            for _, el in ET.iterparse(xml):
                if el.tag == "change" and el.get("id", "") not in members:
                    rows.append((el.get("id"), float(el.get("time")) - t0, el.get("from", ""), el.get("to", "")))
                el.clear()
        except ET.ParseError:
            pass
    return pd.DataFrame(rows, columns=["vehicle_id", "t", "from_lane", "to_lane"])


def write_tables(out_dir: Path, plan: dict | None, departures: list[tuple[str, float]], t0: float,
                 members: set[str]) -> dict:
    """``sections.parquet`` (the passages, each with ``lane_changes_before``: the vehicle's
    lane changes since its previous passage) and ``departures.parquet`` (``vehicle_id``,
    ``depart`` [s, formation time]: every vehicle SUMO inserted, warm-up and drain included).
    Returns run.json's ``sections`` entry."""
    import pandas as pd

    dep = pd.DataFrame(departures, columns=["vehicle_id", "depart"])
    dep["depart"] = dep["depart"].astype(float) - t0
    dep = dep[~dep["vehicle_id"].isin(members)].reset_index(drop=True)
    atomic_write_parquet(out_dir / "departures.parquet", dep)
    if plan is None:
        return {"enabled": False}
    p = read_passages(plan["out"], t0, members, plan)
    lc = read_lane_changes(plan["lanechanges"], t0, members)
    p["lane_changes_before"] = _changes_between(p, lc)
    atomic_write_parquet(out_dir / "sections.parquet", p)
    return {"enabled": True, "sections": plan["sections"], "passages": int(len(p)),
            "lane_changes": int(len(lc))}


def _changes_between(p: pd.DataFrame, lc: pd.DataFrame) -> np.ndarray:
    """For each passage: the vehicle's lane changes after its previous passage (or, at its
    first section, none counted) up to this one."""
    out = np.zeros(len(p), dtype=np.int64)
    if not len(p) or not len(lc):
        return out
    times = {v: np.sort(g["t"].to_numpy(float)) for v, g in lc.groupby("vehicle_id")}
    for vid, g in p.groupby("vehicle_id"):
        tl = times.get(vid)
        if tl is None:
            continue
        g = g.sort_values("t")
        tt = g["t"].to_numpy(float)
        c = np.searchsorted(tl, tt, side="right")
        prev = np.concatenate(([c[0]], c[:-1]))
        out[g.index.to_numpy()] = c - prev
    return out


def stretch_s(plan: dict) -> tuple[float, float]:
    """Arc length of the first and the last section [m]."""
    return plan["sections"][0]["s_m"], plan["sections"][-1]["s_m"]


__all__ = ["plan_sections", "sumo_options", "drain", "write_tables", "formation_reach",
           "section_positions", "stretch_s"]
