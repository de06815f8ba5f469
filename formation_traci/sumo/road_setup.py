"""Resolve a scenario's [road] into geometry and check the formation fits, before SUMO starts.

Every problem is a :class:`ScenarioError` naming the scenario file, the field and what was
expected: unknown network, edge or lane, a route whose lanes do not connect, a slot off the
road anywhere along the route, members that would be inserted on top of each other.
"""
from __future__ import annotations

import math
import os
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sumo_nets import main_route as bundled_main_route

from ..models.params import VehicleParams
from ..road.geometry import ReferenceLine, load_net
from ..road.ramps import ramp_joins
from ..road.lanes import (LaneCentres, LaneShapes, geometric_route_lanes, geometric_route_shape,
                          lane_centre_offsets, sideways_internal_lanes)
from ..scenario.load import ScenarioError
from ..scenario.schema import Scenario
from .routes import resolve_route

MAIN_ROUTES = {
    "straight3": ["entry", "main"],
    "straight3_long": ["entry", "main"],
    "curved3": ["entry", "main"],
    "onramp": ["mw_up", "mw_accel", "mw_down"],
    "lanedrop": ["mw_up", "mw_down"],
    "offramp": ["mw_up", "mw_decel", "mw_down"],
    "shortcut": ["mw_up", "mw_arc", "mw_down"],
}
"""Default main route of each bundled network (sumo_nets/README.md)."""


@dataclass(frozen=True)
class RoadSegment:
    """Lateral extent of the road along part of the reference line."""

    edge: str
    s0: float  # [m]
    s1: float  # [m]
    d_min: float  # right road edge [m], relative to the reference line
    d_max: float  # left road edge [m]


@dataclass(frozen=True)
class Road:
    net_file: Path
    route: list[str]
    line: ReferenceLine
    segments: tuple[RoadSegment, ...]
    lane_width: float  # width of the reference lane on the first edge [m]
    edge_lanes: dict[str, int]  # lane count per route edge
    lane_d: dict[str, np.ndarray]  # per route edge: lateral offset of each lane centre from the reference line [m]
    edge_length: dict[str, float] = None  # length of lane 0 of each route edge [m]
    flow_routes: dict[str, tuple[list[str], int]] = None  # flow id -> (edges, lanes of its first edge)
    fit: dict = None  # smoothing of the reference line: length used, largest deviation, tolerance [m]
    shapes: LaneShapes = None  # SUMO's lane shapes: (lane, position, lateral offset) -> x, y
    member_forbidden: tuple[str, ...] = ()  # internal lanes members are kept off (road/lanes.py)
    lanes: LaneCentres = None  # lane_d with the reference lane per edge, looked up by arc length
    speed_limit: float = math.nan  # the highest lane speed limit along the route [m/s]
    joins: tuple = ()  # where ramp traffic joins the route (road/ramps.py RampJoin)


def resolve_net(sc: Scenario, source: Path | None) -> Path:
    from sumo_nets import NETWORK_NAMES, net_path
    name = sc.road.net
    if name in NETWORK_NAMES:
        return net_path(name)
    base = source.parent if source is not None else Path.cwd()
    path = (base / name).resolve()
    if not path.is_file():
        raise ScenarioError(source or "<scenario>", [(
            "road.net", f"no such network {name!r}: expected a bundled name "
            f"({', '.join(NETWORK_NAMES)}) or a .net.xml path relative to the scenario file")])
    why = not_a_sumo_file(path, "net")
    if why is None and "," in str(path):
        why = "SUMO splits file names at commas: move the network to a path without ','"
    if why:
        raise ScenarioError(source or "<scenario>", [("road.net", f"{name!r} is not usable: {why}")])
    return path


def not_a_sumo_file(path: Path, root: str) -> str | None:
    """Why ``path`` is not a SUMO XML file with root element ``root`` (None if it is one);
    reads only up to the first element."""
    import gzip
    import xml.etree.ElementTree as ET

    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rb") as f:
            head = f.read(1 << 16)
            if b"<!DOCTYPE" in head or b"<!ENTITY" in head:
                return "it declares a DOCTYPE or entities (a SUMO network has neither)"
            f.seek(0)
            for _, el in ET.iterparse(f, events=("start",)):
                if el.tag != root:
                    return f"its root element is <{el.tag}>, a SUMO {root} file has <{root}>"
                return None
    except (ET.ParseError, OSError, EOFError, UnicodeDecodeError) as exc:
        return f"not an XML file ({exc})"
    return "empty file"


def build_road(sc: Scenario, source: Path | None) -> Road:
    src = source or "<scenario>"
    net_file = resolve_net(sc, source)
    try:
        net = load_net(net_file)
    except Exception as exc:  # sumolib's SAX parser: a truncated or corrupt network
        raise ScenarioError(src, [("road.net", f"{net_file.name!r} is not a readable SUMO network: "
                                               f"{type(exc).__name__}: {exc}")]) from None
    spec = sc.road.route or MAIN_ROUTES.get(sc.road.net) or bundled_main_route(sc.road.net)
    if not spec:
        raise ScenarioError(src, [("road.route", "required for a network that is not bundled "
                                                 "(list of edge ids in driving order, or {from, to})")])
    route, problems = resolve_route(net, spec, "road.route", sc.road.lane)
    flow_routes = {}
    for i, f in enumerate(sc.traffic.flows):
        if f.route is None:
            edges = route
        else:
            edges, more = resolve_route(net, f.route, f"traffic.flows.{i}.route")
            problems += more
        if edges:
            flow_routes[f.id] = (edges, net.getEdge(edges[0]).getLaneNumber() if net.hasEdge(edges[0]) else 0)
        if f.populate and edges and not set(edges) <= set(route or ()):
            problems.append((f"traffic.flows.{i}.populate", "expected the flow's route on the main route "
                             "(populate places its vehicles along the main route's edges)"))
    if problems:
        raise ScenarioError(src, [(fld, f"{msg} ({net_file.name})") for fld, msg in problems])
    bad_exits = [(f"maneuvers.{i}.exit", f"expected an edge of {net_file.name} off the route (an off-ramp), got {mv.exit!r}")
                 for i, mv in enumerate(sc.maneuvers) if mv.exit is not None
                 and (not net.hasEdge(mv.exit) or mv.exit in route)]
    if bad_exits:
        raise ScenarioError(src, bad_exits)
    first = net.getEdge(route[0])
    if sc.road.lane >= first.getLaneNumber():
        raise ScenarioError(src, [("road.lane", f"edge {route[0]!r} has lanes 0..{first.getLaneNumber() - 1}, "
                                                f"got {sc.road.lane}")])
    try:
        lanes, line, fit = _reference(str(net_file), tuple(route), sc.road.lane, sc.road.fit_tolerance, net)
    except ValueError as exc:
        raise ScenarioError(src, [("road.route", f"lane {sc.road.lane} cannot be followed along the route: {exc}")]) from None
    segments = []
    lane_d = {}
    ref = []  # the reference lane's index on each route edge (its geometric lane)
    for lane_id in lanes:
        if lane_id.startswith(":"):
            continue
        lane = net.getLane(lane_id)
        edge = lane.getEdge()
        shape = np.asarray([p[:2] for p in lane.getShape()], dtype=float)
        s_ends, _ = line.to_frenet(shape[[0, -1]])
        offs = lane_centre_offsets(net, edge.getID(), line)  # from SUMO's shapes (gaps included)
        widths = np.array([ln.getWidth() for ln in edge.getLanes()])
        lane_d[edge.getID()] = offs
        ref.append(lane.getIndex())
        segments.append(RoadSegment(edge.getID(), float(s_ends[0]), float(s_ends[1]),
                                    float(np.min(offs - widths / 2)), float(np.max(offs + widths / 2))))
    if sc.road.start >= line.length - sc.road.end_margin:
        raise ScenarioError(src, [("road.start", f"must be less than the route length minus end_margin "
                                                 f"({line.length - sc.road.end_margin:.1f} m)")])
    width = first.getLane(sc.road.lane).getWidth()
    centres = LaneCentres(np.maximum.accumulate([seg.s0 for seg in segments]),
                          [lane_d[seg.edge] for seg in segments], ref, width)
    return Road(net_file, route, line, tuple(segments), width,
                {e: net.getEdge(e).getLaneNumber() for e in route}, lane_d,
                {e: net.getEdge(e).getLane(0).getLength() for e in route}, flow_routes, fit, LaneShapes(net),
                tuple(sideways_internal_lanes(net, route)), centres,
                max(ln.getSpeed() for e in route for ln in net.getEdge(e).getLanes()),
                tuple(ramp_joins(net, route)))


_REFERENCE_CACHE: dict = {}


def _reference(net_file: str, route: tuple, lane: int, tolerance: float | None, net):
    """Geometric lanes of the reference lane along the route, and the line fitted to them
    within ``tolerance`` [m] (None: the default band, widened to the lane's on a coarse
    polyline; road/smoothing.py, road/coarse.py); kept per network file (and its mtime),
    route, lane and tolerance in the process, and on disk (sumo/road_cache.py)."""
    key = (net_file, os.stat(net_file).st_mtime_ns, route, lane, tolerance)
    if key not in _REFERENCE_CACHE:
        from . import road_cache
        from ..road.line_pack import packed
        from ..road.smoothing import FIT_SETTINGS, FIT_TOLERANCE_DEFAULT, fit_within, lane_tolerance

        disk_key = road_cache.entry_key(net_file, route, lane, tolerance, FIT_SETTINGS)
        got = road_cache.load(disk_key)
        if got is None:
            lanes = geometric_route_lanes(net, route, lane)
            xy = geometric_route_shape(net, route, lane)
            if tolerance is None:  # the default: the lane's band on a coarse polyline
                band = lane_tolerance(min(net.getLane(x).getWidth() for x in lanes if not x.startswith(":")))
                line, length, dev = fit_within(xy, FIT_TOLERANCE_DEFAULT, lane_band=band)
                tolerance = FIT_TOLERANCE_DEFAULT
            else:
                line, length, dev = fit_within(xy, tolerance)
            got = (lanes, line, {"smoothing_length_m": length, "max_deviation_m": dev,
                                 "tolerance_m": tolerance})
            road_cache.store(disk_key, lanes, line, packed(line), got[2])
        if len(_REFERENCE_CACHE) > 8:
            _REFERENCE_CACHE.clear()
        _REFERENCE_CACHE[key] = got
    return _REFERENCE_CACHE[key]


def slot_offsets(sc: Scenario, road: Road, lane_shift: int = 0) -> np.ndarray:
    """(n, 2) road-frame slots (along, across) [m]; a slot given in lanes lies on SUMO's lane
    centre relative to the reference lane's, on the edge where the slot starts
    (road/lanes.py ``LaneCentres.across``, the mapping the maneuvers use too). ``lane_shift``:
    the formation's lane, in lanes left of the reference lane (a further formation's ``lane``);
    a slot's ``lanes`` count from it."""
    out = []
    for m in sc.members:
        if m.slot is None:
            out.append([np.nan, np.nan])
        else:
            s = sc.road.start + m.slot.along
            across = (m.slot.across if m.slot.across is not None
                      else float(road.lanes.across(m.slot.lanes + lane_shift, s)))
            if m.slot.across is not None and lane_shift:
                across += float(road.lanes.across(lane_shift, s))
            out.append([m.slot.along, across])
    return np.array(out, dtype=float)


def lane_band_slack(road: Road) -> float:
    """How far a body may reach past SUMO's road edge [m]: as far as the reference line of a
    coarsely drawn road leaves the polyline beyond its tolerance (road/coarse.py: where the
    road's curve lies between the chords, the line lies between them too)."""
    from ..road.smoothing import SMOOTHING
    fit = road.fit or {}
    if fit.get("smoothing_length_m", SMOOTHING) <= SMOOTHING:
        return 0.0
    return max(0.0, fit["max_deviation_m"] - fit["tolerance_m"])


def check_slots(sc: Scenario, road: Road, slots: np.ndarray, vehicles: list[VehicleParams], source,
                s_max: float | None = None) -> None:
    """A slot must keep the member's body (``vehicles``, one per member) on the road
    everywhere the formation will drive (up to the virtual car's arc length ``s_max`` [m]
    when maneuvers change the slots there), less :func:`lane_band_slack`."""
    problems = []
    slack = lane_band_slack(road)
    for i, m in enumerate(sc.members):
        half = vehicles[i].width / 2 - slack
        if m.slot is None:
            continue
        dx, dy = slots[i]
        s_first = sc.road.start + dx
        for seg in road.segments:
            if seg.s1 < s_first or (s_max is not None and seg.s0 > s_max + dx):
                continue
            if dy - half < seg.d_min - 1e-6 or dy + half > seg.d_max + 1e-6:
                problems.append((f"members.{i}.slot", (
                    f"member {m.id!r} lies off the road on edge {seg.edge!r}: its body spans "
                    f"d = {dy - half:.2f}..{dy + half:.2f} m, the road {seg.d_min:.2f}..{seg.d_max:.2f} m "
                    f"(d relative to lane {sc.road.lane} of the first edge, left positive)")))
                break
    if problems:
        raise ScenarioError(source or "<scenario>", problems)


def check_positions(sc: Scenario, road: Road, pos0: np.ndarray, source) -> None:
    """A member given an initial ``position`` must start on the road: its centre within
    :data:`MATCH_THRESHOLD` of the road's edges along the route (farther, SUMO refuses to place it
    and the run would drop it after it started)."""
    from .types import MATCH_THRESHOLD

    problems = []
    for i, m in enumerate(sc.members):
        if m.position is None:
            continue
        s, d = (float(v[0]) for v in road.line.to_frenet(np.asarray([pos0[i]], float)))
        seg = next((g for g in road.segments if g.s0 <= s <= g.s1), None)
        if seg is None or not seg.d_min - MATCH_THRESHOLD <= d <= seg.d_max + MATCH_THRESHOLD:
            where = (f"off the route (arc length {s:.1f} m of {road.line.length:.1f} m)" if seg is None else
                     f"{d:.1f} m from the reference line, the road spans {seg.d_min:.2f}..{seg.d_max:.2f} m")
            problems.append((f"members.{i}.position", f"member {m.id!r} would start off the road: its position "
                                                      f"{list(m.position)} lies {where} (at most {MATCH_THRESHOLD:g} m "
                                                      "beyond the road's edge)"))
    if problems:
        raise ScenarioError(source or "<scenario>", problems)


def check_route_ends(sc: Scenario, road: Road, along: np.ndarray, vehicles: list[VehicleParams],
                     source) -> None:
    """Every member (body ``vehicles[i]``) starts on the route with room to drive: its body
    behind the route's start, or its front within end_margin of the route's end, is refused,
    naming the member."""
    problems = []
    for i, m in enumerate(sc.members):
        veh = vehicles[i]
        rear = veh.length - veh.cog_to_front_bumper
        s = sc.road.start + float(along[i])
        field = f"members.{i}.{'slot' if m.slot is not None else 'offset'}"
        if s - rear < 0.0:
            problems.append((field, f"member {m.id!r} starts {rear - s:.1f} m behind the start of the route "
                                    f"(road.start + along = {s:.1f} m; its rear needs {rear:.2f} m)"))
        elif s + veh.cog_to_front_bumper + sc.road.end_margin > road.line.length:
            problems.append((field, f"member {m.id!r} starts beyond the end of the route: road.start + along "
                                    f"= {s:.1f} m, the route is {road.line.length:.1f} m long and the run stops "
                                    f"{sc.road.end_margin:g} m (road.end_margin) before its end"))
    if problems:
        raise ScenarioError(source or "<scenario>", problems)


def check_no_overlap(sc: Scenario, pos: np.ndarray, heading: np.ndarray,
                     vehicles: list[VehicleParams], source) -> None:
    """Members' initial footprints (``vehicles``, one per member) must not overlap each other."""
    problems = []
    for i, j in itertools.combinations(range(len(sc.members)), 2):
        vi, vj = vehicles[i], vehicles[j]
        if rectangles_overlap(pos[i], heading[i], pos[j], heading[j], vi.length, vi.width,
                              vj.length, vj.width):
            problems.append((f"members.{j}", f"member {sc.members[j].id!r} would be inserted on top of "
                                             f"{sc.members[i].id!r} (their bodies overlap at t = 0)"))
    if problems:
        raise ScenarioError(source or "<scenario>", problems)


def rectangles_overlap(p1, h1, p2, h2, length, width, length2=None, width2=None) -> bool:
    """Separating-axis test of two oriented rectangles centred at p1, p2 [m] with headings [rad]."""
    l2 = length if length2 is None else length2
    w2 = width if width2 is None else width2

    def corners(p, h, L, W):
        c, s = np.cos(h), np.sin(h)
        ax = np.array([c, s]) * L / 2
        ay = np.array([-s, c]) * W / 2
        return np.array([p + ax + ay, p + ax - ay, p - ax - ay, p - ax + ay])

    a, b = corners(np.asarray(p1), h1, length, width), corners(np.asarray(p2), h2, l2, w2)
    for h in (h1, h1 + np.pi / 2, h2, h2 + np.pi / 2):
        axis = np.array([np.cos(h), np.sin(h)])
        pa = a[:, 0] * axis[0] + a[:, 1] * axis[1]  # no BLAS matmul
        pb = b[:, 0] * axis[0] + b[:, 1] * axis[1]
        if pa.max() <= pb.min() or pb.max() <= pa.min():
            return False
    return True


def road_room(road: Road):
    """room(s0, s1) -> (d_min, d_max): the narrowest lateral extent of the road over
    [s0, s1] [m] (relative to the reference line, left positive), from its segments."""
    segments = road.segments

    def room(s0: float, s1: float) -> tuple[float, float]:
        lo, hi = -np.inf, np.inf
        for seg in segments:
            if seg.s1 >= s0 and seg.s0 <= s1:
                lo, hi = max(lo, seg.d_min), min(hi, seg.d_max)
        return lo, hi

    return room


def initial_check_limit(sc: Scenario) -> float | None:
    """How far along the route [m] the initial slots must stay on the road: up to the first
    position-triggered maneuver; only the start when the first maneuver is triggered by time
    or traffic (the planner checks the road ahead before every maneuver). None: no maneuvers."""
    if not sc.maneuvers:
        return None
    first = sc.maneuvers[0].at
    return first.s if first.s is not None else sc.road.start
