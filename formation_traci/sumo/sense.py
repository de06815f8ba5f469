"""A step's sense in one compiled call (sumo/world.py ``SumoWorld.sense``).

:func:`sense_step` gives, for every member, its arc length and lateral offset along the
reference line (road/fast_line.py ``to_frenet_many``), its speed, and how far SUMO has it from
our pose (``sumo_gap``: the larger of the CoG distance and the distance between our front
bumper and the point SUMO's lane, lane position and lateral lane position give on SUMO's lane
shapes); for every neighbour its centre and heading (SUMO's front bumper converted) and its
place along the line. :class:`PackedLanes` packs the lane shapes of road/lanes.py ``LaneShapes`` into two
arrays the kernel reads. The arithmetic is that of ``LaneShapes.xy``, sumo/types.py's
conversions and ``math.hypot`` (:func:`~..kernels.py_hypot`), bit for bit
(tests/test_fast_paths.py).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..core.kernels import bisect_right, kernel, py_hypot
from ..road.fast_line import to_frenet_many
from .types import cog_to_sumo_one, sumo_to_cog_one


class SumoRows(NamedTuple):
    """SUMO's rows of the members as :func:`sense_step` takes them (sumo/world.py
    SumoWorld._member_rows; ``li`` of length 0: no rows)."""

    front: np.ndarray  # (n, 2) front bumper x, y [m] (NaN: not in SUMO)
    angle: np.ndarray  # (n,) SUMO's angle [deg]
    lane_pos: np.ndarray  # (n,) lane position [m]
    lat: np.ndarray  # (n,) lateral position [m]
    li: np.ndarray  # (n,) packed lane rows (-1: not used)


class NeighbourReads(NamedTuple):
    """SUMO's rows of the neighbours as :func:`sense_step` takes them."""

    front: np.ndarray  # (m, 2) front bumper x, y [m]
    angle: np.ndarray  # (m,) SUMO's angle [deg]
    length: np.ndarray  # (m,) [m]
    width: np.ndarray  # (m,) [m]
    guess: np.ndarray  # (m,) last step's arc length [m] (NaN: none)


class PackedLanes:
    """SUMO lane shapes (road/lanes.py ``LaneShapes``) packed as the lanes are first seen:
    ``table`` (m, 3) rows (first point, number of points, scale from SUMO's lane position to
    the shape's length) and ``points`` (k, 3) rows (x [m], y [m], length along the shape [m])."""

    def __init__(self, shapes):
        self.shapes = shapes
        self._index: dict[str, int] = {}
        self.table = np.zeros((0, 3))
        self.points = np.zeros((0, 3))
        self._last: list[str] | None = None
        self._last_idx = np.empty(0, dtype=np.int64)

    def index(self, lane_id: str) -> int:
        """Row of ``lane_id`` in :attr:`table` (-1 for no lane: '')."""
        i = self._index.get(lane_id)
        if i is None:
            if not lane_id:
                return -1
            px, py, cum, scale = self.shapes.shape(lane_id)
            i = self._index[lane_id] = len(self.table)
            self.table = np.vstack([self.table, [[len(self.points), len(px), scale]]])
            self.points = np.vstack([self.points, np.column_stack([px, py, cum])])
        return i

    def indices(self, lanes: list[str]) -> np.ndarray:
        """Rows of ``lanes`` (kept while the list stays the same: callers do not write it; a
        read-only array would be another type to :func:`sense_step`, a second compiled copy
        of it to load at every start)."""
        if lanes != self._last:
            self._last = list(lanes)
            self._last_idx = np.array([self.index(lane) for lane in lanes], dtype=np.int64)
        return self._last_idx


@kernel
def lane_point(table, points, li, pos, lat):
    """``LaneShapes.xy`` of lane row ``li``: the point at lane position ``pos`` [m] and
    ``lat`` [m] left of the lane's centre line (x, y [m])."""
    first = int(table[li, 0])
    n = int(table[li, 1])
    last = points[first + n - 1, 2]
    g = pos * table[li, 2]
    if 0.0 > g:
        g = 0.0
    if last < g:
        g = last
    k = bisect_right(points[first:first + n, 2], g) - 1
    if k < 0:
        k = 0
    if k > n - 2:
        k = n - 2
    a = first + k
    sx = points[a + 1, 0] - points[a, 0]
    sy = points[a + 1, 1] - points[a, 1]
    length = py_hypot(sx, sy)
    if length == 0.0:
        length = 1.0
    tx = sx / length
    ty = sy / length
    along = g - points[a, 2]
    x = points[a, 0] + tx * along
    y = points[a, 1] + ty * along
    return x - lat * ty, y + lat * tx


@kernel
def sense_step(G, pos, vel, s_guess, heading, d_front, rows, table, points, tolerance, nbs):
    """One step's sense, members then neighbours, in one call.

    Members: arc length s [m] and lateral offset d [m] of our CoG ``pos`` (n, 2) [m] along
    the line ``G`` (``s_guess``: last step's s, NaN: none), speed [m/s] from ``vel`` (n, 2),
    and, when SUMO's rows are given (``rows``: :class:`SumoRows`, ``li`` of length n, else
    length 0: gap NaN), ``sumo_gap`` [m]: the larger of the distance between our CoG and
    SUMO's (SUMO's front bumper ``front`` (n, 2) [m] and ``angle`` (n,) [deg]; NaN: not in
    SUMO) and the distance between our front bumper (``d_front`` [m] ahead of the CoG along
    ``heading`` [rad]) and packed lane row ``li``'s point (``table``, ``points``:
    :class:`PackedLanes`) at ``lane_pos`` [m], ``lat`` [m] (li < 0 or a non-finite position:
    not used); and how many gaps exceed ``tolerance`` [m].

    Neighbours (m of them, ``nbs``: :class:`NeighbourReads`): their centre x, y [m] and
    heading [rad] from SUMO's front bumper ``front`` (m, 2) [m], ``angle`` [deg] and
    ``length`` [m]; their s, d along the line (``guess``: last step's s, NaN: none), the arc
    length of their rear (s - length / 2) [m] and their half width [m] (``width`` / 2).

    Returns (s, d) of members and neighbours concatenated (n + m,), the members' speed, gap
    and count of gaps over the tolerance, and the neighbours' x, y, heading, rear, half width.
    """
    front, angle, lane_pos, lat, li = rows.front, rows.angle, rows.lane_pos, rows.lat, rows.li
    nb_front, nb_angle, nb_length, nb_width = nbs.front, nbs.angle, nbs.length, nbs.width
    nb_guess = nbs.guess
    n = pos.shape[0]
    m = nb_front.shape[0]
    xy = np.empty((n + m, 2))
    guess = np.empty(n + m)
    nb_x = np.empty(m)
    nb_y = np.empty(m)
    nb_psi = np.empty(m)
    for i in range(n):
        xy[i, 0] = pos[i, 0]
        xy[i, 1] = pos[i, 1]
        guess[i] = s_guess[i]
    for j in range(m):
        nb_x[j], nb_y[j], nb_psi[j] = sumo_to_cog_one(nb_front[j, 0], nb_front[j, 1], nb_angle[j],
                                                      nb_length[j] * 0.5)
        xy[n + j, 0] = nb_x[j]
        xy[n + j, 1] = nb_y[j]
        guess[n + j] = nb_guess[j]
    s, d = to_frenet_many(G, xy, guess)  # each point its own iteration: as if projected apart
    rear = np.empty(m)
    half_w = np.empty(m)
    for j in range(m):
        rear[j] = s[n + j] - nb_length[j] / 2
        half_w[j] = nb_width[j] / 2
    v = np.empty(n)
    gap = np.full(n, np.nan)
    for i in range(n):
        v[i] = np.hypot(vel[i, 0], vel[i, 1])  # the C library's, as numpy (jit on or off)
    n_off = 0
    if li.shape[0] != n:
        return s, d, v, gap, n_off, nb_x, nb_y, nb_psi, rear, half_w
    for i in range(n):
        px = pos[i, 0]
        py = pos[i, 1]
        x, y, _ = sumo_to_cog_one(front[i, 0], front[i, 1], angle[i], d_front[i])
        g = np.hypot(x - px, y - py)
        lp = lane_pos[i]
        lt = lat[i]
        if li[i] >= 0 and math.isfinite(lt) and math.isfinite(lp):
            fx, fy, _ = cog_to_sumo_one(px, py, heading[i], d_front[i])
            sx, sy = lane_point(table, points, li[i], lp, lt)
            h = py_hypot(sx - fx, sy - fy)
            if h > g:
                g = h
        gap[i] = g
        if g > tolerance:
            n_off += 1
    return s, d, v, gap, n_off, nb_x, nb_y, nb_psi, rear, half_w


class NeighbourGuess:
    """Last step's arc length of each neighbour, the guess of :func:`sense_step`
    (the same vehicles as last step: last step's array; otherwise per id, NaN for new ones)."""

    def __init__(self):
        self._ids: list[str] = []
        self._s = np.empty(0)

    def __call__(self, ids: list[str]) -> np.ndarray:
        if ids == self._ids:
            return self._s
        last = dict(zip(self._ids, self._s.tolist()))
        return np.array([last.get(vid, np.nan) for vid in ids], dtype=float)

    def keep(self, ids: list[str], s: np.ndarray) -> None:
        self._ids, self._s = ids, s
