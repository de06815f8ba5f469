"""Where SUMO has the members: their rows for the step's sensing, and where one of them was
last sensed (an incident's place, sim/incident_log.py). A mixin of sumo/world.py SumoWorld,
which has the attributes used here (adapter, fleet, ids, active, in_sumo, members, packed_lanes,
m_s, lanes_read, _every, _kin)."""
from __future__ import annotations

import numpy as np


class MemberRows:
    """_member_rows, locate and the members' kinematics of SumoWorld (see the module docstring)."""

    def _kinematics(self, state):
        """fleet.kinematics(state), computed once per state: actuate's is the next sense's
        (the loop hands sense the state it placed; a join's adopt writes into it only after)."""
        kin = self._kin
        if kin is None or kin[0] is not state:
            kin = self._kin = (state, *self.fleet.kinematics(state))
        return kin[1:]

    def placed(self, state, pos, vel, heading) -> None:
        """The kinematics of ``state``, just placed: the next sense's (:meth:`_kinematics`)."""
        self._kin = (state, pos, vel, heading)

    def _id_index(self, vid: str):
        """Fleet row of member ``vid`` (None: not a member)."""
        rows = getattr(self, "_rows_of_ids", None)
        if rows is None:
            rows = self._rows_of_ids = {m: i for i, m in enumerate(self.ids)}
        return rows.get(vid)

    def _member_rows(self, t):
        """SUMO's rows of the members for :func:`~.sumo_sense.sense_step` (front bumper,
        angle, lane position, lateral position, packed lane row; NaN and -1 for members out
        of the run or no longer in SUMO, who are reported removed), then the recorded lane
        index and :meth:`MemberWatch.lane_changes`' arguments."""
        n = len(self.ids)
        here_now = self.active & self.in_sumo
        every = here_now.all()
        idx_act = self._every if every else np.flatnonzero(here_now)
        front, ang, lanes, lane_idx, lat, lane_pos, present = self.adapter.read_members(
            self.sumo_ids if every else [self.sumo_ids[i] for i in idx_act])
        here = present.all()
        if not here:
            for j, i in enumerate(idx_act):
                if not present[j]:
                    self.members.removed(t, i, self.sumo_ids[i], self.ev)
                    self.active[i] = False
        li = self.packed_lanes.indices(lanes)
        self.lanes_read = (idx_act, lanes)
        if every and here:  # every member in the run and in SUMO (no copies, no masks)
            return (front, ang, lane_pos, lat, li, lane_idx.astype(float), idx_act, present, lanes,
                    lane_idx)
        rows = (np.full((n, 2), np.nan), np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan),
                np.full(n, -1, dtype=np.int64))
        for full, part in zip(rows, (front, ang, lane_pos, lat, li)):
            full[idx_act] = part
        lane_index = np.full(n, np.nan)
        lane_index[idx_act] = np.where(present, lane_idx, np.nan)
        return (*rows, lane_index, idx_act, present, lanes, lane_idx)

    def locate(self, vid: str):
        """(SUMO edge, lane index, arc length s [m]) of member ``vid`` as last sensed (None
        for what is not known: a virtual car, a member SUMO has not placed)."""
        i = self._id_index(vid)
        if i is None:
            return None, None, None
        s = float(self.m_s[i])
        rows, lanes = self.lanes_read
        at = np.flatnonzero(rows == i)
        lane = lanes[int(at[0])] if len(at) else ""
        if not lane or "_" not in lane:
            return None, None, (s if np.isfinite(s) else None)
        edge, index = lane.rsplit("_", 1)
        return edge, int(index) if index.isdigit() else None, (s if np.isfinite(s) else None)

