"""Several formations on one road: each sees the members of the others as traffic.

SUMO's neighbour reads leave every member out (sumo/adapter/neighbours.py); a formation's
governor, gap and lane checks must still see the members of the other formations. Each
step :class:`Peers` keeps every member as a neighbour row (body centre, heading, speed,
acceleration, body, lane, road coordinates: the same fields SUMO's vehicles have in
:class:`~.world.Sensed`), and :meth:`Peers.sensed_for` gives a formation what the world
sensed with the other formations' members in SUMO appended to its neighbours. With one
formation nothing of this runs.
"""
from __future__ import annotations

from itertools import compress

import numpy as np

from ..sim.world import sensed_of
from .types import Neighbours
from ..sim.world import Sensed


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
                     m_s + shift, m_d, m_s + self.d_front - self.length)

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
        idx = np.flatnonzero(present)
        x, y, psi, v, a, s, d, rear = (q[idx] for q in self.rows)
        n_nb = len(nb.ids)
        flagged = len(sensed.nb_in_formation) == n_nb
        in_f = (np.append(sensed.nb_in_formation, np.zeros(len(idx), dtype=np.bool_)) if flagged
                else np.zeros(n_nb + len(idx), dtype=np.bool_))
        arrays = (np.append(nb.x, x), np.append(nb.y, y), np.append(nb.heading, psi), np.append(nb.v, v),
                  np.append(nb.a, a), np.append(nb.length, self.length[idx]),
                  np.append(nb.width, self.width[idx]), np.append(nb.lane_index, self.lane_index[idx]),
                  np.append(sensed.nb_s, s), np.append(sensed.nb_d, d), np.append(sensed.nb_rear, rear),
                  np.append(sensed.nb_half_w, self.width[idx] / 2), in_f)
        joined = Neighbours(list(nb.ids) + [self.sumo_ids[i] for i in idx],
                            list(nb.types) + [self.types[i] for i in idx], *arrays[:7],
                            list(nb.lane_ids) + [self.lane_ids[i] for i in idx], arrays[7])
        owner = np.concatenate([np.full(n_nb, -1, dtype=np.int64), idx])
        self._step_of, self._table = sensed, (joined, arrays, owner, flagged)
        return self._table
