"""Per-step inputs of the members' driving resistance: drag ratio and road grade.

:class:`FreeSpaceLoad` and :class:`RoadLoad` are the ``road_load`` part of a run
(sim/loop.py RunParts): the loop calls one once per outer step, once the step's reference is
known and before its signals are recorded; the values are held over the step's control
periods (sim/fleet.py ``Fleet.set_road_load``). The drag law itself is
models/drag_interaction.py. The grade comes from the elevation (z) of the reference lane's
shape in the SUMO network; a network without elevation (all bundled ones) and free space
give 0 (docs/energy.md).
"""
from __future__ import annotations

import math

import numpy as np

from ..core.kernels import bisect_right, kernel

from ..models.drag_interaction import (PLATOON_DRAG, along_heading, drag_ratios, law_row,
                                       road_ratios_into)
from ..models.params import VehicleParams
from ..scenario.schema import Scenario


def interaction_on(sc: Scenario) -> bool:
    """True when the scenario asks for resistances with the formation-aware drag."""
    return sc.energy.resistances and sc.energy.drag_interaction


class FreeSpaceLoad:
    """Drag ratios in free space: each formation's members among themselves, resolved along
    its virtual car's heading (free space has no common direction of travel: one formation
    does not shelter another); no grade."""

    def __init__(self, veh, rows=None):
        self.veh = veh  # one VehicleParams, or one per member
        self.rows = rows  # each formation's rows (slices), in the formations' order; None: one

    def __call__(self, state, sensed, ref):
        """(drag ratio (n,), None) for positions state.x[:, :2] [m] and ref.truth's heading(s)."""
        truth = ref.truth
        headings = [float(truth[2])] if truth.ndim == 1 else [float(h) for h in truth[:, 2]]
        return self.ratios(state.x[:, :2], headings), None

    def ratios(self, pos: np.ndarray, headings) -> np.ndarray:
        """Drag ratio [-] of each member at positions (n, 2) [m], the formations' virtual
        cars heading ``headings`` [rad] (one per formation)."""
        if self.rows is None or len(self.rows) == 1:
            return free_space_ratios(self.veh, pos, headings[0])
        out, every = np.empty(len(pos)), np.arange(len(pos))
        for rows, heading in zip(self.rows, headings):
            mine = every[rows]
            out[mine] = free_space_ratios(self.veh, pos[mine], heading, mine)
        return out


class RoadLoad:
    """Drag ratios among SUMO's vehicles (or 1 without the interaction) and the grade under
    each member (or None: the network has no elevation)."""

    def __init__(self, sc: Scenario, veh, road, line):
        self.veh, self.drag = veh, interaction_on(sc)
        self.elevation = elevation_profile(road.net_file, road.route, sc.road.lane, line)
        self._chassis = None  # chassis(veh, n), made at the first call

    def __call__(self, state, sensed, ref):
        nb, n_nb = sensed.nb, len(sensed.nb_s)
        ratio = 1.0
        if self.drag:
            ratio = ratios_among(self.chassis(len(sensed.m_s)), sensed.m_s, sensed.m_d,
                                 sensed.active, (sensed.nb_s, sensed.nb_d,
                                                 nb.length if n_nb else sensed.nb_s,
                                                 nb.width if n_nb else sensed.nb_s))
        grade = None if self.elevation is None else grade_at(self.elevation, sensed.m_s)
        return ratio, grade

    def chassis(self, n: int) -> np.ndarray:
        """(3, n): the members' length, width and CoG to front bumper [m] (:func:`chassis`)."""
        if self._chassis is None:
            self._chassis = chassis(self.veh, n)
        return self._chassis

    def kernel_inputs(self, n: int) -> tuple[np.ndarray, ...]:
        """What the compiled road step takes to compute this load itself (sumo/fused_records.py
        RoadRun): the members' chassis and the drag law's row ((3, n), (5,); (3, n) zeros and
        (0,) without the interaction), the elevation profile's s and z [m] ((0,) each without
        elevation)."""
        drag = (self.chassis(n), _PLATOON_ROW) if self.drag else (np.zeros((3, n)), np.zeros(0))
        grade = (np.zeros(0), np.zeros(0)) if self.elevation is None else self.elevation
        return (*drag, *(np.ascontiguousarray(a, dtype=np.float64) for a in grade))


_PLATOON_ROW = law_row(PLATOON_DRAG)
"""The drag law as the kernels take it (the same array every call)."""


def road_load_part(sc: Scenario, veh, road=None, line=None, rows=None):
    """The run's ``road_load`` part for the members' chassis ``veh`` (one VehicleParams, or
    one per member): None without resistances (nothing to compute), else
    :class:`RoadLoad` on a road (``road``: sumo/road_setup.py Road, ``line``: its reference
    line) or :class:`FreeSpaceLoad` (``rows``: each formation's rows; None when the drag
    interaction is off: ratio 1)."""
    if not sc.energy.resistances:
        return None
    if road is not None:
        return RoadLoad(sc, veh, road, line)
    return FreeSpaceLoad(veh, rows) if interaction_on(sc) else None


def _bodies(veh, n: int, order=None):
    """Length, width and CoG-to-front-bumper [m] of n members, (n,) each; ``veh`` is one
    VehicleParams for all or one per member of the fleet (a mixed formation; ``order``:
    which of them, in this order)."""
    if isinstance(veh, VehicleParams):
        vehs = [veh] * n
    else:
        vehs = list(veh) if order is None else [veh[i] for i in order]
    return tuple(np.array([getattr(v, q) for v in vehs], dtype=float)
                 for q in ("length", "width", "cog_to_front_bumper"))


def free_space_ratios(veh, pos: np.ndarray, heading: float, rows=None) -> np.ndarray:
    """Drag ratio [-] of each member in free space (members only), positions (n, 2) [m]
    resolved along the virtual car's heading [rad]; ``veh``: one chassis or one per member
    (``rows``: the fleet rows of ``pos``, when ``veh`` is one per member of the fleet)."""
    s, d = along_heading(pos[:, 0], pos[:, 1], heading)
    n = len(s)
    length, width, _ = _bodies(veh, n, rows)
    return drag_ratios(s, d, length, width, n, PLATOON_DRAG)


def road_ratios(veh, m_s, m_d, active, nb_s, nb_d, nb_length, nb_width) -> np.ndarray:
    """Drag ratio [-] of each member on a road among SUMO's vehicles: members' centres of
    gravity (m_s, m_d) [m] (``active``: still in SUMO), other vehicles' centres, lengths, widths
    [m]; ``veh``: one chassis or one per member."""
    return ratios_among(chassis(veh, len(m_s)), m_s, m_d, active, (nb_s, nb_d, nb_length, nb_width))


def ratios_among(bodies: np.ndarray, m_s, m_d, active, nb) -> np.ndarray:
    """:func:`road_ratios` for the members' ``bodies`` (:func:`chassis`), ``nb`` the other
    vehicles' (s, d, length, width) [m]: the kernel the compiled road step calls too
    (models/drag_interaction.py road_ratios_into)."""
    out = np.empty(len(m_s))
    f64 = [np.ascontiguousarray(a, dtype=np.float64) for a in (m_s, m_d, *nb)]
    road_ratios_into(f64[0], f64[1], np.ascontiguousarray(active, dtype=np.bool_), bodies,
                     tuple(f64[2:]), _PLATOON_ROW, out)
    return out


def chassis(veh, n: int) -> np.ndarray:
    """(3, n): the members' length, width and CoG to front bumper [m] (``veh``: one chassis or
    one per member)."""
    return np.stack(_bodies(veh, n))


GRADE_BASE = 1.0
"""Half the base of the central difference that gives the grade from the elevation [m]."""


def elevation_profile(net, edges, lane_index: int, line) -> tuple[np.ndarray, np.ndarray] | None:
    """Elevation of the reference lane against arc length: (s [m], z [m]), or None when the
    network has no elevation. The lane's 3-D shape points (internal lanes included) are
    projected onto the reference line ``line`` (road/geometry.py)."""
    from ..road.geometry import load_net, route_lanes

    net = load_net(net)
    pts = [p for lid in route_lanes(net, edges, lane_index) for p in net.getLane(lid).getShape3D()]
    xyz = np.asarray(pts, dtype=float).reshape(-1, 3)
    if not len(xyz) or not np.any(xyz[:, 2] != 0.0):
        return None
    s, _ = line.to_frenet(xyz[:, :2])
    order = np.argsort(s, kind="stable")
    s, z = s[order], xyz[order, 2]
    keep = np.concatenate([[True], np.diff(s) > 1e-6])  # shared points of joined lanes
    return s[keep], z[keep]


def grade_at(profile: tuple[np.ndarray, np.ndarray], s) -> np.ndarray:
    """Road grade [rad] (positive uphill) at arc lengths s [m]: atan of the central difference
    of the piecewise-linear elevation over +-GRADE_BASE (:func:`grades_into`, the kernel the
    compiled road step calls)."""
    s = np.asarray(s, dtype=float)
    out = np.empty(s.size)
    grades_into(profile[0], profile[1], np.ascontiguousarray(s.ravel()), out)
    return out.reshape(s.shape)


@kernel
def grades_into(ps, pz, s, out):
    """Road grade [rad] at arc lengths s (n,) [m] into ``out``, from the elevation profile
    (ps [m], pz [m]) (:func:`elevation_profile`); the C library's atan."""
    for i in range(s.shape[0]):
        dz = interp_one(s[i] + GRADE_BASE, ps, pz) - interp_one(s[i] - GRADE_BASE, ps, pz)
        out[i] = math.atan(dz / (2.0 * GRADE_BASE))


@kernel
def interp_one(x, xp, fp):
    """``np.interp(x, xp, fp)`` for one x and increasing xp, as numpy's C loop computes it
    (bit for bit: the same cases, the same expressions)."""
    n = xp.shape[0]
    if n == 1:  # numpy's case of one point: its value everywhere, NaN included
        return fp[0]
    if math.isnan(x):
        return x
    if x > xp[n - 1]:
        return fp[n - 1]
    if x < xp[0]:
        return fp[0]
    j = bisect_right(xp, x) - 1  # xp[j] <= x < xp[j + 1]
    if j >= n - 1 or xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    y = slope * (x - xp[j]) + fp[j]
    if math.isnan(y):  # numpy: if we get nan in one direction, try the other
        y = slope * (x - xp[j + 1]) + fp[j + 1]
        if math.isnan(y) and fp[j] == fp[j + 1]:
            y = fp[j]
    return y
