"""Several formations on one road: each sees the members of the others as traffic.

SUMO's neighbour reads leave every member out (sumo/adapter/neighbours.py); a formation's
governor, gap and lane checks must still see the members of the other formations. Each
step :class:`Peers` keeps every member as a neighbour row (body centre, heading, speed,
acceleration, body, lane, road coordinates: the same fields SUMO's vehicles have in
:class:`~.world.Sensed`), and :meth:`Peers.sensed_for` gives a formation what the world
sensed with the other formations' members in SUMO appended to its neighbours. The rows the
formations' governors take (rear, offset, half width, speed, and each row's member) are
:func:`peer_table`'s, a kernel the compiled step of a road run (sumo/fused_step.py) calls too.
With one formation nothing of this runs.
"""
from __future__ import annotations

from itertools import compress

import numpy as np

from ..control.reference_records import MemberRows, NeighbourRows
from ..core.kernels import kernel
from ..sim.world import sensed_of
from .types import Neighbours
from ..sim.world import Sensed

_NO_MATES = np.empty(0)


@kernel
def peer_table(nb, members, length, width, d_front):
    """SUMO's vehicles ``nb`` (control/reference_records.py NeighbourRows; its ``mate_rear``
    is not read) joined by the members with ``members.active`` (MemberRows: their arc length,
    offset [m] and speed [m/s]; ``length``, ``width`` and CoG to front bumper ``d_front`` of
    their SUMO types [m]): rear bumper's arc length, offset, half width [m], speed [m/s], the
    released members' flags (members: False) and each row's member (-1: a SUMO vehicle),
    SUMO's rows first, then the members in order."""
    m = nb.rear.shape[0]
    active = members.active
    k = m
    for i in range(active.shape[0]):
        if active[i]:
            k += 1
    rear, d, half, speed = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    flags = np.zeros(k, dtype=np.bool_)
    owner = np.full(k, -1, dtype=np.int64)
    for j in range(m):
        rear[j] = nb.rear[j]
        d[j] = nb.d[j]
        half[j] = nb.half_w[j]
        speed[j] = nb.v[j]
        flags[j] = nb.in_formation[j]
    q = m
    for i in range(active.shape[0]):
        if not active[i]:
            continue
        rear[q] = members.s[i] + d_front[i] - length[i]  # front bumper less the length
        d[q] = members.d[i]
        half[q] = width[i] / 2
        speed[q] = members.v[i]
        owner[q] = i
        q += 1
    return rear, d, half, speed, flags, owner


class Peers:
    """Every member as a neighbour row, refreshed at each sense (module docstring)."""

    def __init__(self, ids: list[str], sumo_ids: list[str], mtypes, groups: list[slice]):
        self.ids, self.sumo_ids, self.groups = ids, sumo_ids, groups
        self.types = [mt.id for mt in mtypes]
        self.length = np.array([mt.length for mt in mtypes], dtype=float)  # [m]
        self.width = np.array([mt.width for mt in mtypes], dtype=float)  # [m]
        self.d_front = np.array([mt.d_front for mt in mtypes], dtype=float)  # CoG to front bumper [m]
        n = len(ids)
        self.lane_ids = [""] * n
        self.lane_index = np.full(n, -1, dtype=np.int64)
        self.rows = None
        self._step_of = self._table = None  # the Sensed the joined table is of, and the table

    def lanes(self, idx, lanes, lane_index) -> None:
        """The members' lanes as SUMO last reported them (``idx``: the members read)."""
        for j, i in enumerate(idx):
            self.lane_ids[i] = lanes[j]
        self.lane_index[:] = np.where(np.isfinite(lane_index), lane_index, -1).astype(np.int64)

    def update(self, pos, heading, v, a, m_s, m_d) -> None:
        """The members' CoG pos (n, 2) [m], heading [rad], speed [m/s], acceleration [m/s^2] and
        road coordinates [m] of this step."""
        shift = self.d_front - self.length / 2  # CoG -> body centre, along the heading [m]
        c, s = np.cos(heading), np.sin(heading)
        self.rows = (pos[:, 0] + shift * c, pos[:, 1] + shift * s, heading, v, a,
                     m_s + shift, m_d, m_s)

    def sensed_for(self, sensed: Sensed, sl: slice, present: np.ndarray) -> Sensed:
        """What formation ``sl`` senses: :func:`~.world.sensed_of`, its neighbours joined by
        the members of the other formations that are ``present`` (in the run and in SUMO).
        The joined table is built once per step (:meth:`_joined`); a formation takes it less
        its own members (boolean masks: no Python loop over vehicles)."""
        part = sensed_of(sensed, sl)
        if self.rows is None or sensed.nb is None:
            return part
        nb, arrays, owner, flagged = self._joined(sensed, present)
        if not (owner >= 0).any():
            return part
        keep = (owner < sl.start) | (owner >= sl.stop)
        pick = (lambda a: a) if keep.all() else (lambda a: a[keep])  # noqa: E731
        x, y, psi, v, a, length, width, lane_index, s, d, rear, half_w, in_f = map(pick, arrays)
        lists = [nb.ids, nb.types, nb.lane_ids]
        if not keep.all():
            lists = [list(compress(q, keep)) for q in lists]
        part.nb = Neighbours(lists[0], lists[1], x, y, psi, v, a, length, width, lists[2], lane_index)
        part.nb_s, part.nb_d, part.nb_v, part.nb_rear, part.nb_half_w = s, d, v, rear, half_w
        if flagged:
            part.nb_in_formation = in_f
        return part

    def table(self, sensed: Sensed, present: np.ndarray):
        """The joined table's arrays a formation group's kernel reads (sim/formation_group.py):
        rear arc length, lateral offset, half width [m], speed [m/s], the released members'
        flags and each row's member index (-1: a SUMO vehicle)."""
        if self.rows is None:
            n = len(sensed.nb.ids)
            flags = sensed.nb_in_formation if len(sensed.nb_in_formation) == n else np.zeros(n, dtype=np.bool_)
            return (sensed.nb_rear, sensed.nb_d, sensed.nb_half_w, sensed.nb_v, flags,
                    np.full(n, -1, dtype=np.int64))
        _, arrays, owner, _ = self._joined(sensed, present)
        return arrays[10], arrays[9], arrays[11], arrays[3], arrays[12], owner

    def _joined(self, sensed: Sensed, present: np.ndarray):
        """SUMO's neighbours of this step and every present member, as one table: (Neighbours
        with the joined lists, the arrays, each row's member index or -1, whether the released
        members' flags are there); built on the first call of a step."""
        if self._step_of is sensed:
            return self._table
        nb = sensed.nb
        present = np.ascontiguousarray(present, dtype=np.bool_)
        idx = np.flatnonzero(present)
        x, y, psi, v, a, s, m_d, m_s = self.rows
        n_nb = len(nb.ids)
        flagged = len(sensed.nb_in_formation) == n_nb
        rear, d, half_w, speed, in_f, owner = peer_table(
            NeighbourRows(_f64(sensed.nb_rear), _f64(sensed.nb_d), _f64(sensed.nb_half_w), _f64(nb.v),
                          (sensed.nb_in_formation if flagged else np.zeros(n_nb, dtype=np.bool_)), _NO_MATES),
            MemberRows(_f64(m_s), _f64(m_d), _f64(v), present), self.length, self.width, self.d_front)
        arrays = (np.append(nb.x, x[idx]), np.append(nb.y, y[idx]), np.append(nb.heading, psi[idx]), speed,
                  np.append(nb.a, a[idx]), np.append(nb.length, self.length[idx]),
                  np.append(nb.width, self.width[idx]), np.append(nb.lane_index, self.lane_index[idx]),
                  np.append(sensed.nb_s, s[idx]), d, rear, half_w, in_f)
        joined = Neighbours(list(nb.ids) + [self.sumo_ids[i] for i in idx],
                            list(nb.types) + [self.types[i] for i in idx], *arrays[:7],
                            list(nb.lane_ids) + [self.lane_ids[i] for i in idx], arrays[7])
        self._step_of, self._table = sensed, (joined, arrays, owner, flagged)
        return self._table


def _f64(a) -> np.ndarray:
    """a as a contiguous float64 array (no copy when it already is one)."""
    return np.ascontiguousarray(a, dtype=np.float64)
