"""Where SUMO put the formation's members, read through their subscriptions.

A mixin of the SUMO adapter (sumo/adapter/__init__.py, the only module that imports
libsumo/traci): it works on the adapter's ``api`` and its member bookkeeping and imports no
SUMO itself. Per member it keeps the lane last read, the neighbour lane its body reaches
into (sumo/adapter/__init__.py ``place`` puts it there first) and its route window.
"""
from __future__ import annotations

from operator import add, le

import numpy as np


class MemberReads:
    """The members' subscription rows as arrays (:meth:`read_members`, :meth:`settled_members`)
    and what follows from their lanes."""

    api = None
    members: dict
    _member_get = None
    native = None
    _member_lane: dict
    _overlap: dict
    _ends: dict
    _window_lane: dict
    _lane_geometry: dict
    _settled = None
    _all_here: np.ndarray

    def read_members(self, ids: list[str]):
        """Where SUMO put each member, in SUMO's frame (sumo/sense.py converts it): front
        bumper (n, 2) [m], angle (n,) [deg, CW from north], lane ids, lane index, lateral
        position in the lane [m], lane position of the front bumper [m]; ``present`` is False
        for members SUMO no longer has (NaN, '' and -1 there). One subscription read; per
        member only what changed (its lane) costs more."""
        if not ids:
            return self._read_some_members(ids, [])
        res = self.api.vehicle.getAllSubscriptionResults()
        rows = [res.get(vid) for vid in ids]
        if not all(rows):
            return self._read_some_members(ids, rows)
        pos, ang, lanes, lane_index, lat, lane_pos = zip(*map(self._member_get, rows))
        lanes = list(lanes)
        self._track_lanes(ids, lanes, lane_index, lat)
        here = self._all_here
        if len(here) != len(ids):
            here = self._all_here = np.ones(len(ids), dtype=bool)
            here.flags.writeable = False  # shared between steps
        ang, lat, lane_pos = np.array((ang, lat, lane_pos), dtype=float)  # rows of one array
        return (np.array(pos, dtype=float), ang, lanes, np.array(lane_index, dtype=np.int64), lat,
                lane_pos, here)

    def settled_members(self, ids: list[str]):
        """:meth:`read_members`' rows when every member of ``ids`` is in SUMO on the lane of the
        last read and inside it (nothing for :meth:`_track_lanes` to do, so nothing changes
        here): a table (n, 5) of front bumper x, y [m], angle [deg], lateral position [m] and
        lane position [m], the lane ids and the lane indices; None otherwise
        (sumo/fused_path.py: :meth:`read_members` then reads)."""
        settled = self._settled
        if settled is None or self._overlap or self._ends or ids != settled[0]:
            return None
        if self.native is not None:  # the C++ reads (sumo/adapter/native_reads.py): the same rows
            got = self.native.member_table(ids)
            if got is None:
                return None
            tb, lanes, index = got
            lat = tb[:, 3].tolist()
        else:
            get = self._all_results().get
            rows = [get(vid) for vid in ids]
            if not all(rows):
                return None
            pos, ang, lane, index, lat, lane_pos = self._member_keys
            lanes = [r[lane] for r in rows]
            tb = np.array([(*r[pos], r[ang], r[lat], r[lane_pos]) for r in rows], dtype=float)
            index, lat = [r[index] for r in rows], [r[lat] for r in rows]
        if lanes != settled[1] or not all(map(le, map(add, map(abs, lat), settled[2]), settled[3])):
            return None
        return tb, lanes, index

    def _read_some_members(self, ids, rows):
        """:meth:`read_members` when SUMO no longer has some of the members (NaN, '' and -1)."""
        n = len(ids)
        here = [i for i, r in enumerate(rows) if r]
        front = np.full((n, 2), np.nan)
        ang, lat, lane_pos = (np.full(n, np.nan) for _ in range(3))
        lane_index, lanes = np.full(n, -1, dtype=np.int64), [""] * n
        for i, vid in enumerate(ids):
            if not rows[i]:
                self._member_lane.pop(vid, None)
                self._overlap.pop(vid, None)
                self._ends.pop(vid, None)
        if here:
            sub = [ids[i] for i in here]
            fs, angs, ls, lis, lts, lps, _ = self.read_members(sub)
            front[here], ang[here], lane_index[here], lat[here], lane_pos[here] = fs, angs, lis, lts, lps
            for j, i in enumerate(here):
                lanes[i] = ls[j]
        return front, ang, lanes, lane_index, lat, lane_pos, np.array([bool(r) for r in rows], dtype=bool)

    def _track_lanes(self, ids, lanes, lane_index, lat) -> None:
        """Per member: its lane as read, the neighbour lane its body reaches into (for
        :meth:`place`) and its route window, which moves on when it entered a new edge.
        Nothing to do while the same members are on the lanes of the last read, each inside
        its lane, with no overlap and every route window checked on its lane (the usual
        step: :attr:`_settled`)."""
        settled = self._settled
        if (settled is not None and not self._overlap and lanes == settled[1] and ids == settled[0]
                and all(map(le, map(add, map(abs, lat), settled[2]), settled[3]))):
            return
        member_lane, overlap, window_lane = self._member_lane, self._overlap, self._window_lane
        for vid, lane, li, lt in zip(ids, lanes, lane_index, lat):
            member_lane[vid] = lane
            other = self._overlapped_lane(lane, li, lt, self.members[vid].width)
            if other is not None:
                overlap[vid] = other
            elif overlap:
                overlap.pop(vid, None)
            if window_lane.get(vid) != lane:
                self._advance_route_window(vid, lane)
            self._track_end(vid, lane)
        self._settled = None
        if all(window_lane.get(vid) == lane for vid, lane in zip(ids, lanes)):
            self._settled = (list(ids), lanes, [self.members[vid].width / 2 for vid in ids],
                             [self._half_lane(lane) for lane in lanes])

    def _half_lane(self, lane_id: str) -> float:
        """Half the width of a lane [m] for :meth:`_track_lanes` (inf: never overlapped)."""
        if not lane_id or lane_id.startswith(":"):
            return np.inf
        return self._lane_geo(lane_id)[0] / 2

    def _lane_geo(self, lane_id: str) -> tuple[float, int, str]:
        """A lane's width [m], its edge's number of lanes and the edge id (read once)."""
        geo = self._lane_geometry.get(lane_id)
        if geo is None:
            edge = lane_id.rsplit("_", 1)[0]
            geo = self._lane_geometry[lane_id] = (self.api.lane.getWidth(lane_id),
                                                  self.api.edge.getLaneNumber(edge), edge)
        return geo

    def _overlapped_lane(self, lane_id: str, lane_index: int, lat: float, width: float):
        """The neighbour lane a member's body reaches into (lateral position ``lat`` [m] on
        lane ``lane_id``, body ``width`` [m]), or None."""
        if not lane_id or lane_id.startswith(":"):
            return None
        lane_w, n_lanes, edge = self._lane_geo(lane_id)
        if abs(lat) + width / 2 <= lane_w / 2:
            return None
        other = lane_index + (1 if lat > 0 else -1)
        if other < 0 or other >= n_lanes:
            return None
        return f"{edge}_{other}"
