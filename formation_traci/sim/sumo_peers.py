"""Several formations on one road: each sees the members of the others as traffic.

SUMO's neighbour reads leave every member out (sim/sumo_neighbours.py); a formation's
governor, gap and lane checks must still see the members of the other formations. Each
step :class:`Peers` keeps every member as a neighbour row (body centre, heading, speed,
acceleration, body, lane, road coordinates: the same fields SUMO's vehicles have in
:class:`~.world.Sensed`), and :meth:`Peers.sensed_for` gives a formation what the world
sensed with the other formations' members in SUMO appended to its neighbours. With one
formation nothing of this runs.
"""
from __future__ import annotations

import numpy as np

from .world import sensed_of
from .sumo_types import Neighbours
from .world import Sensed


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
        """What formation ``sl`` senses: :func:`~.formation.sensed_of`, its neighbours joined
        by the members of the other formations that are ``present`` (in the run and in SUMO)."""
        part = sensed_of(sensed, sl)
        if self.rows is None or sensed.nb is None:
            return part
        mask = present.copy()
        mask[sl] = False
        idx = np.flatnonzero(mask)
        if not len(idx):
            return part
        x, y, psi, v, a, s, d, rear = (q[idx] for q in self.rows)
        nb = sensed.nb
        part.nb = Neighbours(
            list(nb.ids) + [self.sumo_ids[i] for i in idx], list(nb.types) + [self.types[i] for i in idx],
            np.append(nb.x, x), np.append(nb.y, y), np.append(nb.heading, psi), np.append(nb.v, v),
            np.append(nb.a, a), np.append(nb.length, self.length[idx]),
            np.append(nb.width, self.width[idx]), list(nb.lane_ids) + [self.lane_ids[i] for i in idx],
            np.append(nb.lane_index, self.lane_index[idx]))
        part.nb_s, part.nb_d, part.nb_v = np.append(sensed.nb_s, s), np.append(sensed.nb_d, d), part.nb.v
        part.nb_rear = np.append(sensed.nb_rear, rear)
        part.nb_half_w = np.append(sensed.nb_half_w, self.width[idx] / 2)
        if len(sensed.nb_in_formation) == len(nb.ids):
            part.nb_in_formation = np.append(sensed.nb_in_formation, np.zeros(len(idx), dtype=np.bool_))
        return part
