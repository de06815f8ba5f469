"""Generate the plain-XML sources of the formation-traci road networks and build them.

Usage (from the repository root)::

    python -m sumo_nets.build                 # rewrite sumo_nets/*.{nod,edg,con,net}.xml
    python -m sumo_nets.build --outdir DIR    # build into another directory
    python -m sumo_nets.build --check         # rebuild in a temp dir, compare with the committed files

Only the netconvert shipped with the ``eclipse-sumo`` wheel is used (``sumo.SUMO_HOME/bin``,
or the ``netconvert`` next to ``sys.executable``), never a system SUMO.

Conventions shared by all networks
----------------------------------
* right-hand traffic, lane width 3.5 m, motorway speed limit 36.11 m/s (130 km/h), on-ramp
  22.22 m/s (80 km/h); every lane disallows the vehicle classes that SUMO's OSM type map
  excludes from motorways (pedestrian, bicycle, moped, scooter, wheelchair, rail, ...);
* every edge uses ``spreadType="right"`` (the SUMO default): the edge geometry given in the
  ``.edg.xml`` is the *left* (median-side) border of the carriageway and the lanes lie to the
  right of it.  On the straight networks the reference line is y = 0 and lane k of an n-lane
  edge has its centreline at y = -(n - k - 0.5) * 3.5, i.e. for 3 lanes lane 0 (rightmost) at
  -8.75, lane 1 at -5.25 and lane 2 (leftmost) at -1.75.  Because lane positions are measured
  from the left border, adding a lane on the right (acceleration lane) or dropping the
  rightmost lane leaves all through lanes exactly where they were, so the through lanes are
  straight and kink-free across every joint;
* the road starts at the origin and runs along +x; ``--offset.disable-normalization`` keeps
  net coordinates equal to the source coordinates;
* coordinates are written with 4 decimals (``--precision 4``) so that headings and curvature
  can be derived from the lane polylines without rounding noise;
* netconvert's header comment carries a creation timestamp; the build replaces that line with
  a fixed one (there is no netconvert option to omit it), so two builds give identical bytes.

curved3 curvature profile (design line = left border of the carriageway)
-------------------------------------------------------------------------
Curvature kappa(s) is piecewise linear in arc length s (positive = left turn):

======  ======  =====================  ============================
from s  length  element                kappa
======  ======  =====================  ============================
0       800     straight               0
800     200     clothoid (A = 400)     0 -> +1/800
1000    600     left arc, R = 800      +1/800
1600    200     clothoid (A = 400)     +1/800 -> 0
1800    600     straight               0
2400    200     clothoid (A = 447.2)   0 -> -1/1000
2600    800     right arc, R = 1000    -1/1000
3400    200     clothoid (A = 447.2)   -1/1000 -> 0
3600    2400    straight               0
======  ======  =====================  ============================

Total 6000 m.  Heading change is +1.0 rad over the left bend and -1.0 rad over the right
bend, so the road ends heading +x again.  Heading is the exact integral of kappa; x and y
are integrated numerically (5-point Gauss-Legendre per output interval) and the shape is
sampled every <= 4 m on clothoids and arcs.  Lane k centreline is offset d_k to the right of
the design line, so its curvature is kappa / (1 + d_k * kappa) (radius R + d_k in the left
bend, R - d_k in the right bend).
"""

from __future__ import annotations

import argparse
import filecmp
import math
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

NETS_DIR = Path(__file__).resolve().parent

LANE_WIDTH = 3.5
MOTORWAY_SPEED = 36.11  # 130 km/h
RAMP_SPEED = 22.22  # 80 km/h
# the disallow list of SUMO's OSM type map for highway.motorway / highway.motorway_link
# (data/typemap/osmNetconvert.typ.xml): no pedestrians, bicycles, mopeds, rail, ...
DISALLOW = ("pedestrian bicycle moped scooter wheelchair rail rail_urban rail_electric rail_fast "
            "tram subway cable_car ship aircraft drone container")
MOTORWAY_PRIORITY = 14  # as highway.motorway in the OSM type map
RAMP_PRIORITY = 9  # as highway.motorway_link
SHAPE_STEP = 4.0  # maximum spacing of shape points on curved geometry [m]
PRECISION = 4  # decimals of coordinates in the generated files

NETCONVERT_OPTIONS = (
    "--offset.disable-normalization", "true",
    "--no-turnarounds", "true",
    "--precision", str(PRECISION),
    "--default.lanewidth", str(LANE_WIDTH),
)

# ----------------------------------------------------------------------------------------
# curved3 design
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Element:
    """One element of a horizontal alignment: curvature linear from k0 to k1 over length."""

    kind: str
    length: float
    k0: float
    k1: float


R_LEFT = 800.0
R_RIGHT = 1000.0
CURVED3_PROFILE: tuple[Element, ...] = (
    Element("straight", 800.0, 0.0, 0.0),
    Element("clothoid", 200.0, 0.0, 1.0 / R_LEFT),
    Element("arc", 600.0, 1.0 / R_LEFT, 1.0 / R_LEFT),
    Element("clothoid", 200.0, 1.0 / R_LEFT, 0.0),
    Element("straight", 600.0, 0.0, 0.0),
    Element("clothoid", 200.0, 0.0, -1.0 / R_RIGHT),
    Element("arc", 800.0, -1.0 / R_RIGHT, -1.0 / R_RIGHT),
    Element("clothoid", 200.0, -1.0 / R_RIGHT, 0.0),
    Element("straight", 2400.0, 0.0, 0.0),
)
CURVED3_ENTRY_LENGTH = 300.0

# Gauss-Legendre 5-point nodes/weights on [-1, 1]
_GL_NODES = (
    0.0,
    -0.5384693101056831, 0.5384693101056831,
    -0.9061798459386640, 0.9061798459386640,
)
_GL_WEIGHTS = (
    0.5688888888888889,
    0.4786286704993665, 0.4786286704993665,
    0.2369268850561891, 0.2369268850561891,
)


def _heading_in(el: Element, theta0: float, t: float) -> float:
    """Heading at distance t into element el (exact integral of the linear curvature)."""
    return theta0 + el.k0 * t + 0.5 * (el.k1 - el.k0) / el.length * t * t


def integrate_alignment(
    profile: Sequence[Element], step: float = SHAPE_STEP,
    x0: float = 0.0, y0: float = 0.0, theta0: float = 0.0,
) -> list[tuple[float, float, float, float]]:
    """Sample an alignment given by its curvature profile.

    Returns (s, x, y, heading) tuples.  Straights contribute only their end point; curved
    elements are sampled uniformly with spacing <= step.  x(s), y(s) are the numerical
    integrals of cos/sin of the heading.
    """
    pts = [(0.0, x0, y0, theta0)]
    s, x, y, th = 0.0, x0, y0, theta0
    for el in profile:
        n = 1 if el.k0 == 0.0 and el.k1 == 0.0 else max(1, math.ceil(el.length / step - 1e-9))
        h = el.length / n
        for i in range(n):
            a = i * h
            dx = dy = 0.0
            for node, w in zip(_GL_NODES, _GL_WEIGHTS):
                t = a + 0.5 * h * (node + 1.0)
                ang = _heading_in(el, th, t)
                dx += w * math.cos(ang)
                dy += w * math.sin(ang)
            x += 0.5 * h * dx
            y += 0.5 * h * dy
            pts.append((s + (i + 1) * h, x, y, _heading_in(el, th, (i + 1) * h)))
        s += el.length
        th = _heading_in(el, th, el.length)
    return pts


def split_alignment(pts, s_split: float):
    """Split sampled alignment points at arc length s_split (must lie on a straight)."""
    before = [p for p in pts if p[0] < s_split - 1e-9]
    after = [p for p in pts if p[0] > s_split + 1e-9]
    # interpolate on the straight segment containing s_split
    p0, p1 = before[-1], after[0]
    f = (s_split - p0[0]) / (p1[0] - p0[0])
    mid = (s_split, p0[1] + f * (p1[1] - p0[1]), p0[2] + f * (p1[2] - p0[2]), p0[3])
    return before + [mid], [mid] + after


# ----------------------------------------------------------------------------------------
# plain XML writing
# ----------------------------------------------------------------------------------------


def _f(v: float) -> str:
    s = f"{v:.{PRECISION}f}"
    if float(s) == 0.0:
        s = f"{0.0:.{PRECISION}f}"
    # trim trailing zeros for readability, keep at least one decimal
    if "." in s:
        s = s.rstrip("0")
        if s.endswith("."):
            s += "0"
    return s


def _shape(points) -> str:
    return " ".join(f"{_f(x)},{_f(y)}" for x, y in points)


@dataclass
class Node:
    id: str
    x: float
    y: float
    type: str = "priority"


@dataclass
class Edge:
    id: str
    frm: str
    to: str
    num_lanes: int
    speed: float = MOTORWAY_SPEED
    priority: int = MOTORWAY_PRIORITY
    shape: list[tuple[float, float]] | None = None
    acceleration_lanes: tuple[int, ...] = ()
    comment: str = ""


@dataclass
class Connection:
    frm: str
    to: str
    from_lane: int
    to_lane: int


@dataclass
class Network:
    name: str
    description: str
    nodes: list[Node]
    edges: list[Edge]
    connections: list[Connection] = field(default_factory=list)


HEADER = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"


def _generated_note(net: Network) -> str:
    return (f"<!-- {net.name}: {net.description}\n"
            f"     Generated by sumo_nets/build.py; edit the generator, not this file, and run\n"
            f"     'python -m sumo_nets.build' to rebuild. -->\n")


def write_plain_xml(net: Network, outdir: Path) -> list[Path]:
    outdir.mkdir(parents=True, exist_ok=True)
    files = []
    nod = [HEADER, _generated_note(net),
           '<nodes xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
           'xsi:noNamespaceSchemaLocation="http://sumo.dlr.de/xsd/nodes_file.xsd">\n']
    for n in net.nodes:
        nod.append(f'    <node id="{n.id}" x="{_f(n.x)}" y="{_f(n.y)}" type="{n.type}"/>\n')
    nod.append("</nodes>\n")
    p = outdir / f"{net.name}.nod.xml"
    p.write_text("".join(nod), encoding="utf-8", newline="\n")
    files.append(p)

    edg = [HEADER, _generated_note(net),
           '<edges xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
           'xsi:noNamespaceSchemaLocation="http://sumo.dlr.de/xsd/edges_file.xsd">\n']
    for e in net.edges:
        if e.comment:
            edg.append(f"    <!-- {e.comment} -->\n")
        attrs = (f'id="{e.id}" from="{e.frm}" to="{e.to}" priority="{e.priority}" '
                 f'numLanes="{e.num_lanes}" speed="{_f(e.speed)}" width="{_f(LANE_WIDTH)}" '
                 f'spreadType="right" disallow="{DISALLOW}"')
        if e.shape is not None:
            attrs += f'\n          shape="{_shape(e.shape)}"'
        if e.acceleration_lanes:
            edg.append(f"    <edge {attrs}>\n")
            for idx in e.acceleration_lanes:
                edg.append(f'        <lane index="{idx}" acceleration="true"/>\n')
            edg.append("    </edge>\n")
        else:
            edg.append(f"    <edge {attrs}/>\n")
    edg.append("</edges>\n")
    p = outdir / f"{net.name}.edg.xml"
    p.write_text("".join(edg), encoding="utf-8", newline="\n")
    files.append(p)

    if net.connections:
        con = [HEADER, _generated_note(net),
               '<connections xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
               'xsi:noNamespaceSchemaLocation="http://sumo.dlr.de/xsd/connections_file.xsd">\n']
        for c in net.connections:
            con.append(f'    <connection from="{c.frm}" to="{c.to}" '
                       f'fromLane="{c.from_lane}" toLane="{c.to_lane}"/>\n')
        con.append("</connections>\n")
        p = outdir / f"{net.name}.con.xml"
        p.write_text("".join(con), encoding="utf-8", newline="\n")
        files.append(p)
    return files


# ----------------------------------------------------------------------------------------
# network definitions
# ----------------------------------------------------------------------------------------


def straight3() -> Network:
    return Network(
        name="straight3",
        description="straight 3-lane motorway, 6000 m along +x (entry 300 m + main 5700 m)",
        nodes=[Node("n0", 0, 0, "dead_end"), Node("n1", 300, 0), Node("n2", 6000, 0, "dead_end")],
        edges=[
            Edge("entry", "n0", "n1", 3, comment="0 m .. 300 m"),
            Edge("main", "n1", "n2", 3, comment="300 m .. 6000 m"),
        ],
    )


def straight3_long() -> Network:
    return Network(
        name="straight3_long",
        description="straight 3-lane motorway, 10000 m along +x (entry 300 m + main 9700 m)",
        nodes=[Node("n0", 0, 0, "dead_end"), Node("n1", 300, 0), Node("n2", 10000, 0, "dead_end")],
        edges=[
            Edge("entry", "n0", "n1", 3, comment="0 m .. 300 m"),
            Edge("main", "n1", "n2", 3, comment="300 m .. 10000 m"),
        ],
    )


def curved3() -> Network:
    pts = integrate_alignment(CURVED3_PROFILE)
    entry, main = split_alignment(pts, CURVED3_ENTRY_LENGTH)
    end = main[-1]
    return Network(
        name="curved3",
        description=("3-lane motorway, 6000 m: 800 m straight, 200 m clothoid, 600 m left arc R=800, "
                     "200 m clothoid, 600 m straight, 200 m clothoid, 800 m right arc R=1000, "
                     "200 m clothoid, 2400 m straight (entry 300 m + main 5700 m)"),
        nodes=[
            Node("n0", 0, 0, "dead_end"),
            Node("n1", entry[-1][1], entry[-1][2]),
            Node("n2", end[1], end[2], "dead_end"),
        ],
        edges=[
            Edge("entry", "n0", "n1", 3, comment="s = 0 m .. 300 m (straight)"),
            Edge("main", "n1", "n2", 3, shape=[(p[1], p[2]) for p in main],
                 comment="s = 300 m .. 6000 m; curvature profile documented in sumo_nets/build.py"),
        ],
    )


# on-ramp layout (x positions along the motorway, y = 0 is the left border)
ONRAMP_MERGE_X = 1500.0
ONRAMP_ACCEL_LENGTH = 300.0
ONRAMP_END_X = 4000.0
ONRAMP_RAMP_DX = 400.0  # x-extent of the ramp edge
ONRAMP_RAMP_OFFSET = 15.0  # gap between motorway right border and ramp left border at the ramp start


def ramp_reference_line(step: float = SHAPE_STEP) -> list[tuple[float, float]]:
    """Left border of the ramp lane.

    y(x) = -3*3.5 - D * (1 - u)^3 with u = (x - x_start) / 400 m: the ramp starts D = 15 m to
    the right of the motorway's right border at an angle of atan(3D/400) = 6.4 deg, its
    curvature decreases linearly to zero, and it arrives tangentially (zero angle and zero
    curvature) exactly on the line of the acceleration lane (lane 0 of mw_accel).
    """
    return cubic_ramp(ONRAMP_MERGE_X - ONRAMP_RAMP_DX, ONRAMP_RAMP_DX, ONRAMP_RAMP_OFFSET, True, step)


def cubic_ramp(x_start: float, dx: float, offset: float, joining: bool,
               step: float = SHAPE_STEP) -> list[tuple[float, float]]:
    """Left border of a ramp lane over x_start .. x_start + dx [m]: y = -3*3.5 - offset w^3
    with w = 1 - u (joining: tangent to the motorway lanes' line at the end) or w = u
    (leaving: tangent at the start), u = (x - x_start) / dx, sampled every <= step."""
    n = math.ceil(dx / step)
    pts = []
    for i in range(n + 1):
        u = i / n
        w = (1.0 - u) if joining else u
        pts.append((x_start + u * dx, -3 * LANE_WIDTH - offset * w ** 3))
    return pts


def onramp() -> Network:
    accel_end = ONRAMP_MERGE_X + ONRAMP_ACCEL_LENGTH
    ramp = ramp_reference_line()
    conns = [Connection("mw_up", "mw_accel", k, k + 1) for k in range(3)]
    conns.append(Connection("ramp", "mw_accel", 0, 0))
    conns += [Connection("mw_accel", "mw_down", k + 1, k) for k in range(3)]
    return Network(
        name="onramp",
        description=("3-lane motorway, 4000 m along +x, with a 1-lane on-ramp from the right joining "
                     "at x=1500 m into a 300 m acceleration lane (4 lanes) that ends at x=1800 m"),
        nodes=[
            Node("n0", 0, 0, "dead_end"),
            Node("n_merge", ONRAMP_MERGE_X, 0),
            Node("n_accel_end", accel_end, 0),
            Node("n_end", ONRAMP_END_X, 0, "dead_end"),
            Node("n_ramp", ramp[0][0], ramp[0][1], "dead_end"),
        ],
        edges=[
            Edge("mw_up", "n0", "n_merge", 3, comment="motorway upstream of the merge, x = 0 .. 1500"),
            Edge("mw_accel", "n_merge", "n_accel_end", 4, acceleration_lanes=(0,),
                 comment="x = 1500 .. 1800; lane 0 = acceleration lane (continues the ramp), lanes 1-3 = motorway"),
            Edge("mw_down", "n_accel_end", "n_end", 3,
                 comment="x = 1800 .. 4000; the acceleration lane has ended (lane drop 4 -> 3)"),
            Edge("ramp", "n_ramp", "n_merge", 1, speed=RAMP_SPEED, priority=RAMP_PRIORITY, shape=ramp,
                 comment="on-ramp, x = 1100 .. 1500, arrives tangentially on the line of mw_accel lane 0"),
        ],
        connections=conns,
    )


LANEDROP_X = 2500.0
LANEDROP_END_X = 4000.0


def lanedrop() -> Network:
    return Network(
        name="lanedrop",
        description=("3-lane motorway, 4000 m along +x; the rightmost lane (index 0) ends at x=2500 m, "
                     "2 lanes continue"),
        nodes=[
            Node("n0", 0, 0, "dead_end"),
            Node("n_drop", LANEDROP_X, 0),
            Node("n_end", LANEDROP_END_X, 0, "dead_end"),
        ],
        edges=[
            Edge("mw_up", "n0", "n_drop", 3, comment="x = 0 .. 2500, 3 lanes; lane 0 ends at x = 2500"),
            Edge("mw_down", "n_drop", "n_end", 2, comment="x = 2500 .. 4000, 2 lanes"),
        ],
        connections=[Connection("mw_up", "mw_down", 1, 0), Connection("mw_up", "mw_down", 2, 1)],
    )


# off-ramp layout (x positions along the motorway, y = 0 is the left border)
OFFRAMP_DECEL_X = 2000.0
OFFRAMP_DECEL_LENGTH = 250.0
OFFRAMP_END_X = 4000.0
OFFRAMP_RAMP_DX = 400.0  # x-extent of the off-ramp edge
OFFRAMP_RAMP_OFFSET = 15.0  # gap between motorway right border and ramp left border at the ramp end


def offramp_reference_line(step: float = SHAPE_STEP) -> list[tuple[float, float]]:
    """Left border of the off-ramp lane: the on-ramp's curve mirrored in x.

    y(x) = -3*3.5 - D u^3 with u = (x - x_diverge) / 400 m: the ramp leaves the line of the
    deceleration lane (lane 0 of mw_decel) tangentially (zero angle and curvature) and ends
    D = 15 m to the right of the motorway's right border at an angle of atan(3D/400) = 6.4 deg.
    """
    return cubic_ramp(OFFRAMP_DECEL_X + OFFRAMP_DECEL_LENGTH, OFFRAMP_RAMP_DX, OFFRAMP_RAMP_OFFSET,
                      False, step)


def offramp() -> Network:
    diverge = OFFRAMP_DECEL_X + OFFRAMP_DECEL_LENGTH
    ramp = offramp_reference_line()
    conns = [Connection("mw_up", "mw_decel", k, k + 1) for k in range(3)]
    conns += [Connection("mw_decel", "mw_down", k + 1, k) for k in range(3)]
    conns.append(Connection("mw_decel", "offramp", 0, 0))
    return Network(
        name="offramp",
        description=("3-lane motorway, 4000 m along +x, with a 250 m deceleration lane on the right "
                     "from x=2000 m (4 lanes) and a 1-lane off-ramp leaving it at x=2250 m"),
        nodes=[
            Node("n0", 0, 0, "dead_end"),
            Node("n_decel", OFFRAMP_DECEL_X, 0),
            Node("n_diverge", diverge, 0),
            Node("n_end", OFFRAMP_END_X, 0, "dead_end"),
            Node("n_ramp_end", ramp[-1][0], ramp[-1][1], "dead_end"),
        ],
        edges=[
            Edge("mw_up", "n0", "n_decel", 3, comment="motorway upstream of the exit, x = 0 .. 2000"),
            Edge("mw_decel", "n_decel", "n_diverge", 4,
                 comment="x = 2000 .. 2250; lane 0 = deceleration lane (entered by a lane change), lanes 1-3 = motorway"),
            Edge("mw_down", "n_diverge", "n_end", 3, comment="x = 2250 .. 4000, 3 lanes"),
            Edge("offramp", "n_diverge", "n_ramp_end", 1, speed=RAMP_SPEED, priority=RAMP_PRIORITY, shape=ramp,
                 comment="off-ramp, x = 2250 .. 2650, leaves the line of mw_decel lane 0 tangentially"),
        ],
        connections=conns,
    )


SHORTCUT_BUMP = 150.0  # how far the mainline swings left between x = 1000 and 2000 m [m]


def shortcut() -> Network:
    """A motorway whose mainline swings 150 m to the left between x = 1000 and 2000 m (1018 m
    long) while a 1-lane off-ramp, link and on-ramp run straight along its right (969 m):
    the shortest path between the ends leaves the motorway (routes by ends)."""
    bump = [(1000.0 + x, SHORTCUT_BUMP * 0.5 * (1.0 - math.cos(2.0 * math.pi * x / 1000.0)))
            for x in (4.0 * i for i in range(251))]
    y_ramp = -3 * LANE_WIDTH - 20.0  # left border of the ramp lane
    conns = [Connection("mw_up", "mw_arc", k, k) for k in range(3)]
    conns += [Connection("mw_arc", "mw_down", k, k) for k in range(3)]
    conns += [Connection("mw_up", "offramp", 0, 0), Connection("offramp", "link", 0, 0),
              Connection("link", "onramp", 0, 0), Connection("onramp", "mw_down", 0, 0)]
    ramp = dict(speed=RAMP_SPEED, priority=RAMP_PRIORITY)
    return Network(
        name="shortcut",
        description=("3-lane motorway, 3000 m along +x, swinging 150 m left between x=1000 and "
                     "2000 m; an off-ramp from lane 0 at x=1000 m, a straight 1-lane link and an "
                     "on-ramp into lane 0 at x=2000 m are the shorter path"),
        nodes=[
            Node("n0", 0, 0, "dead_end"), Node("n_div", 1000, 0), Node("n_merge", 2000, 0),
            Node("n_end", 3000, 0, "dead_end"), Node("n_r1", 1100, y_ramp), Node("n_r2", 1900, y_ramp),
        ],
        edges=[
            Edge("mw_up", "n0", "n_div", 3, comment="x = 0 .. 1000"),
            Edge("mw_arc", "n_div", "n_merge", 3, shape=bump, comment="the mainline's swing"),
            Edge("mw_down", "n_merge", "n_end", 3, comment="x = 2000 .. 3000"),
            Edge("offramp", "n_div", "n_r1", 1, shape=[(1000.0, -2 * LANE_WIDTH), (1100.0, y_ramp)], **ramp),
            Edge("link", "n_r1", "n_r2", 1, **ramp, comment="straight, along the mainline's right"),
            Edge("onramp", "n_r2", "n_merge", 1, shape=[(1900.0, y_ramp), (2000.0, -2 * LANE_WIDTH)], **ramp),
        ],
        connections=conns,
    )


def motorway100() -> Network:
    from .motorway100 import motorway100 as make  # its own module: 100 km of generated edges

    return make()


NETWORKS: dict[str, Callable[[], Network]] = {
    "straight3": straight3,
    "straight3_long": straight3_long,
    "curved3": curved3,
    "onramp": onramp,
    "lanedrop": lanedrop,
    "offramp": offramp,
    "shortcut": shortcut,
    "motorway100": motorway100,
}

# ----------------------------------------------------------------------------------------
# running netconvert
# ----------------------------------------------------------------------------------------


def find_sumo_binary(name: str) -> Path:
    """Locate a SUMO binary (netconvert, sumo, ...) of the eclipse-sumo wheel."""
    candidates = []
    try:
        import sumo  # the eclipse-sumo wheel's python package

        candidates.append(Path(sumo.SUMO_HOME) / "bin" / name)
    except ImportError:
        pass
    candidates.append(Path(sys.executable).parent / name)
    for c in candidates:
        if c.is_file():
            return c
    raise FileNotFoundError(
        f"{name} of the eclipse-sumo wheel not found (looked at {', '.join(map(str, candidates))}); "
        "install the project's dependencies (pip install eclipse-sumo==1.28.0)")


_HEADER_RE = re.compile(r"<!-- generated on [^\n]*? by (Eclipse SUMO [^\n]*)\n")


def _strip_timestamp(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    text, n = _HEADER_RE.subn(
        lambda m: f"<!-- generated by {m.group(1)} via 'python -m sumo_nets.build' "
                  "(creation timestamp removed for reproducible builds)\n", text, count=1)
    if n != 1:
        raise RuntimeError(f"{path}: netconvert header comment not found")
    path.write_text(text, encoding="utf-8", newline="\n")


def build_network(net: Network, outdir: Path, netconvert: Path | None = None) -> tuple[Path, list[str]]:
    """Write the plain XML of net into outdir and run netconvert; returns (net path, warnings)."""
    netconvert = netconvert or find_sumo_binary("netconvert")
    outdir = Path(outdir).resolve()
    write_plain_xml(net, outdir)
    cmd = [str(netconvert),
           "--node-files", f"{net.name}.nod.xml",
           "--edge-files", f"{net.name}.edg.xml"]
    if net.connections:
        cmd += ["--connection-files", f"{net.name}.con.xml"]
    cmd += list(NETCONVERT_OPTIONS)
    cmd += ["--output-file", f"{net.name}.net.xml"]
    res = subprocess.run(cmd, cwd=outdir, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"netconvert failed for {net.name}:\n{res.stdout}\n{res.stderr}")
    out = outdir / f"{net.name}.net.xml"
    _strip_timestamp(out)
    warnings = [ln for ln in (res.stdout + res.stderr).splitlines()
                if ln.strip() and ln.strip() != "Success."]
    return out, warnings


def build_all(outdir: Path = NETS_DIR, names: Sequence[str] | None = None,
              verbose: bool = False) -> dict[str, list[str]]:
    """Build all (or the named) networks into outdir; returns the netconvert messages per net."""
    netconvert = find_sumo_binary("netconvert")
    messages = {}
    for name in names or NETWORKS:
        path, warnings = build_network(NETWORKS[name](), Path(outdir), netconvert)
        messages[name] = warnings
        if verbose:
            print(f"built {path}")
            for w in warnings:
                print(f"  {w}")
    return messages


def generated_files(name: str) -> list[str]:
    files = [f"{name}.nod.xml", f"{name}.edg.xml", f"{name}.net.xml"]
    if NETWORKS[name]().connections:
        files.insert(2, f"{name}.con.xml")
    return files


def check(names: Sequence[str] | None = None) -> list[str]:
    """Rebuild into a temporary directory and list files differing from the committed ones."""
    diffs = []
    with tempfile.TemporaryDirectory() as tmp:
        build_all(Path(tmp), names)
        for name in names or NETWORKS:
            for f in generated_files(name):
                committed = NETS_DIR / f
                if not committed.exists() or not filecmp.cmp(committed, Path(tmp) / f, shallow=False):
                    diffs.append(f)
    return diffs


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sumo_nets.build", description=__doc__.split("\n")[0])
    ap.add_argument("names", nargs="*", metavar="NAME",
                    help=f"networks to build (default: all of {', '.join(NETWORKS)})")
    ap.add_argument("--outdir", type=Path, default=NETS_DIR, help="output directory (default: sumo_nets/)")
    ap.add_argument("--check", action="store_true",
                    help="rebuild in a temporary directory and fail if the committed files differ")
    ap.add_argument("-q", "--quiet", action="store_true")
    args = ap.parse_args(argv)
    unknown = [n for n in args.names if n not in NETWORKS]
    if unknown:
        ap.error(f"unknown network(s) {', '.join(unknown)}; known: {', '.join(NETWORKS)}")
    names = args.names or None
    if args.check:
        diffs = check(names)
        if diffs:
            print("out of date (run python -m sumo_nets.build): " + ", ".join(diffs), file=sys.stderr)
            return 1
        if not args.quiet:
            print("sumo_nets: committed networks are up to date")
        return 0
    build_all(args.outdir, names, verbose=not args.quiet)
    return 0


if __name__ == "__main__":
    sys.exit(main())
