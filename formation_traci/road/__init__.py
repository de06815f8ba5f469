"""Road geometry layer.

* :mod:`.geometry`: :class:`ReferenceLine`, a smooth arc-length-parametrised curve fitted to
  a SUMO lane polyline (heading, curvature, curvature rate, Frenet projection), and the
  sumolib helpers that walk a route's lanes and give lane offsets; :mod:`.line_fit` fits the
  polyline, :mod:`.line_pack` and :mod:`.fast_line` evaluate the line (compiled, once).
* :mod:`.leader`: the virtual car on the line, eq (2.3) with omega = v kappa.
* :mod:`.targets`: formation slots in road coordinates and their exact derivatives, used in
  place of eq (2.4).

Only sumolib is used to read networks; this package never imports libsumo or traci.
"""
from .geometry import (
    LINE_FIT_DEFAULT,
    LineFit,
    LinePoint,
    ReferenceLine,
    clean_polyline,
    lane_offsets,
    load_net,
    reference_line_from_net,
    route_lanes,
    route_shape,
)
from .leader import road_leader_state
from .targets import road_targets

__all__ = [
    "LINE_FIT_DEFAULT",
    "LineFit",
    "LinePoint",
    "ReferenceLine",
    "clean_polyline",
    "lane_offsets",
    "load_net",
    "reference_line_from_net",
    "road_leader_state",
    "road_targets",
    "route_lanes",
    "route_shape",
]
