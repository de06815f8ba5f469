"""Event detectors of road runs: each watches one thing and writes rows to the recorder.

Kinds (docs/outputs.md): member_removed, placement_mismatch, lane_change, cut_in,
collision, collision_artefact, member_collision, stranded (sim/incidents.py), teleport, emergency_brake,
emergency_end, move_refused, end_of_road, cleared_at_insertion.
"""
from __future__ import annotations

import numpy as np

PLACEMENT_TOLERANCE = 0.1
"""SUMO's position of a member farther than this from ours is a placement_mismatch event [m]."""
MAX_REFUSED = 20
"""A member whose moveToXY is refused this many steps in a row is taken out of the run."""


class LaneTracker:
    """Last (edge, lane index) of every vehicle seen; shared by the member and traffic
    watches so a lane change is reported once per vehicle."""

    def __init__(self):
        self.prev: dict[str, tuple[str, int]] = {}
        self.lane: dict[str, str] = {}  # lane id last seen: the same lane means nothing to do
        self.version = 0  # counts the member watch's writes (TrafficWatch's check that it saw all)


class MemberWatch:
    """What SUMO reports about the members: removed, placed elsewhere, changed lane."""

    def __init__(self, rec, ids, lanes: LaneTracker, log_path=None):
        n = len(ids)
        self.rec, self.ids, self.lanes = rec, ids, lanes
        self.log_path = log_path  # SUMO's messages (sumo/messages.py): its reasons for a removal
        self.mismatch = np.zeros(n, dtype=bool)
        self.lane_prev = np.full(n, -1)
        self._off = False  # any member in self.mismatch
        self._settled = None  # lanes of the last read when every member was in it and in SUMO

    @property
    def settled(self):
        """The lanes of the last read when every member was in it and in SUMO (None: none)."""
        return self._settled

    def forget_lanes(self) -> None:
        """The next read compares no lanes (members went out of the run)."""
        self._settled = None

    @property
    def off(self) -> bool:
        """A member was misplaced at the last placement check."""
        return self._off

    def removed(self, t, i, sumo_id: str, ev=None):
        """Member i (SUMO's ``sumo_id``) is no longer in SUMO: the event with SUMO's reason
        (:func:`removal_reason`; ``ev``: what SUMO reported for the last step)."""
        why = removal_reason(sumo_id, ev, self.log_path, self.lanes.lane.get(self.ids[i], ""))
        self.rec.add_event(t, "member_removed", self.ids[i], "", why)

    def placement(self, t, gap_sumo, n_off: int):
        """``n_off``: how many gaps exceed PLACEMENT_TOLERANCE (sumo/sense.py counts them)."""
        if n_off == 0 and not self._off:
            return  # every member where the model put it, now and at the last read (the usual step)
        off = gap_sumo > PLACEMENT_TOLERANCE
        new = off & ~self.mismatch
        for i in (np.flatnonzero(new) if new.any() else ()):
            self.rec.add_event(t, "placement_mismatch", self.ids[i], "",
                               f"SUMO has the member {gap_sumo[i]:.2f} m from where the model put it")
        self.mismatch, self._off = off, n_off > 0

    def unchanged(self, idx, lanes: list[str], lane_idx) -> bool:
        """True when :meth:`lane_changes` of the members ``idx`` (all present) on ``lanes`` with
        lane indices ``lane_idx`` has nothing to do but forget :attr:`_settled` (each on the
        lane it was on); sumo/fused_path.py then leaves it out."""
        seen, ids, prev = self.lanes.lane, self.ids, self.lane_prev
        return all(seen.get(ids[i]) == lane and prev[i] == li
                   for i, lane, li in zip(idx, lanes, lane_idx))

    def lane_changes(self, t, idx_act, present, lanes, lane_idx):
        every = len(idx_act) == len(self.ids) and present.all()
        if every and lanes == self._settled:
            return  # every member on the lane it was on at the last read (a lane's index is fixed)
        prev, ids, seen = self.lanes.prev, self.ids, self.lanes.lane
        for j, i in enumerate(idx_act):
            if present[j] and seen.get(ids[i]) == lanes[j] and self.lane_prev[i] == lane_idx[j]:
                continue  # on the lane it was on: nothing changes
            self.lanes.version += 1
            if present[j]:
                seen[ids[i]] = lanes[j]
            if present[j] and self.lane_prev[i] >= 0 and lane_idx[j] != self.lane_prev[i] \
                    and lanes[j].rsplit("_", 1)[0] == prev.get(ids[i], ("", -1))[0]:
                self.rec.add_event(t, "lane_change", ids[i], "", f"{self.lane_prev[i]} -> {lane_idx[j]}")
            if present[j]:
                self.lane_prev[i] = lane_idx[j]
                prev[ids[i]] = (lanes[j].rsplit("_", 1)[0], int(lane_idx[j]))
        self._settled = list(lanes) if every else None


def removal_reason(vid: str, ev, log_path=None, lane: str = "") -> str:
    """Why SUMO no longer has member ``vid`` (its SUMO id): what SUMO reported of it for the last
    step (``ev``, sumo/types.py StepEvents: a collision, a teleport, an arrival) and SUMO's own
    last message naming it in its log ``log_path`` (sumo/messages.py), else that SUMO reported
    none of them; ``lane``: the lane it was last seen on."""
    why = []
    if ev is not None:
        for c, v, where in ev.collisions:
            if vid in (c, v):
                why.append(f"collision with {v if vid == c else c} on lane {where}")
        if vid in ev.teleports:
            why.append("SUMO teleports it (off the road until the teleport ends)")
        if vid in ev.arrived:
            why.append("it arrived at the end of its route in SUMO")
    said = _last_message(log_path, vid)
    if said:
        why.append(f"SUMO: {said}")
    if not why:
        why.append("SUMO reported no collision, teleport or arrival of it and no message about it")
    at = f" (last on lane {lane})" if lane else ""
    return f"SUMO no longer has the member{at}: " + "; ".join(why)


def _last_message(log_path, vid: str) -> str:
    """SUMO's last warning or error naming vehicle ``vid`` in its log, or ''."""
    try:
        text = log_path.read_text(encoding="utf-8", errors="replace") if log_path is not None else ""
    except OSError:
        return ""
    lines = [ln for ln in text.splitlines() if f"'{vid}'" in ln]
    return lines[-1].partition(": ")[2] if lines else ""


def log_sumo_events(rec, t, ev, members: set[str], names: dict | None = None,
                    clearance_of=None) -> None:
    """Collisions and teleports SUMO reported for the last step (``names``: SUMO id -> member
    id of vehicles taken over by a join). Collisions go to the recorder's incidents
    (sim/incidents.py), classified by ``clearance_of(a, b)``: our signed body clearance [m]."""
    names = names or {}
    if ev is None:
        return
    if ev.collisions and rec.incidents is None:  # a recorder outside a run (tests)
        for c, v, lane in ev.collisions:
            rec.add_event(t, "collision", names.get(c, c), names.get(v, v), f"lane {lane}")
    elif ev.collisions:
        rec.incidents.sumo_collisions(t, [(names.get(c, c), names.get(v, v), lane)
                                          for c, v, lane in ev.collisions],
                                      clearance_of or (lambda a, b: np.nan))
    for vid in ev.teleports:
        vid = names.get(vid, vid)
        rec.add_event(t, "teleport", vid, "", "member" if vid in members else "")


class TrafficWatch:
    """Lane changes of nearby vehicles; a cut-in when one becomes the vehicle right ahead
    of a member inside its time gap."""

    def __init__(self, rec, ids, lanes: LaneTracker, time_gap: float, min_gap: float):
        self.rec, self.ids, self.lanes = rec, ids, lanes
        self.time_gap, self.min_gap = time_gap, min_gap
        self._last = ([], [], -1)  # vehicles and lanes of the last call, lanes.version after it

    def __call__(self, t, nb, lead_idx, gap, v_m, active):
        ids, lanes, version = self._last
        if nb.lane_ids == lanes and nb.ids == ids and self.lanes.version == version:
            return  # the vehicles of the last call on their lanes, nobody else wrote: no change
        changed = set()
        prev, seen = self.lanes.prev, self.lanes.lane
        for j, (vid, lane) in enumerate(zip(nb.ids, nb.lane_ids)):
            if seen.get(vid) == lane:
                continue  # on the lane it was on: nothing changes
            seen[vid] = lane
            edge = lane.rsplit("_", 1)[0]
            li = int(nb.lane_index[j])
            old = prev.get(vid)
            if old is not None and old[0] == edge and old[1] != li and not edge.startswith(":"):
                self.rec.add_event(t, "lane_change", vid, "", f"{old[1]} -> {li}")
                changed.add(j)
            prev[vid] = (edge, li)
        self._last = (list(nb.ids), list(nb.lane_ids), self.lanes.version)
        if not changed:
            return
        for i in np.flatnonzero(active):
            j = lead_idx[i]
            if j >= 0 and j in changed and gap[i] < self.min_gap + self.time_gap * v_m[i]:
                self.rec.add_event(t, "cut_in", nb.ids[j], self.ids[i],
                                   f"gap {gap[i]:.1f} m ahead of the member")


class EmergencyWatch:
    """``emergency_brake`` when the virtual car or a member starts braking harder than
    comfortable (the planner's emergency flags, control/longitudinal.py), ``emergency_end``
    when that ends."""

    def __init__(self, rec, ids, vc_ids=None):
        self.rec, self.ids = rec, list(ids)
        self.vc_ids = list(vc_ids or ["vc"])  # one virtual car per formation
        self.on = np.zeros(len(self.ids) + len(self.vc_ids), dtype=bool)  # members, then the virtual cars
        self._any_on = False  # self.on.any()

    @property
    def any_on(self) -> bool:
        """The virtual car or a member was on emergency braking at the last call."""
        return self._any_on

    def __call__(self, t, info: dict) -> None:
        """``info``: Reference.info; several formations: ``emergency`` and ``a_request`` one
        per virtual car (sim/formation.py join_references)."""
        members, vc = info["emergency_members"], info["emergency"]
        if not (np.any(vc) or self._any_on or members.any()):
            return  # nobody braking hard, before or now
        now = np.append(members, vc)
        n = len(self.ids)
        a_vc = np.atleast_1d(info["a_request"])
        for i in np.flatnonzero(now != self.on):
            who = self.vc_ids[i - n] if i >= n else self.ids[i]
            a = a_vc[i - n] if i >= n else info["a_cap_request"][i]
            if now[i]:
                self.rec.add_event(t, "emergency_brake", who, "", f"braking request {-a:.2f} m/s^2", value=-a)
            else:
                self.rec.add_event(t, "emergency_end", who, "", "back within comfortable braking")
        self.on = now
        self._any_on = bool(now.any())


class RefusalWatch:
    """Counts refused moves per member; after MAX_REFUSED in a row the member leaves."""

    def __init__(self, rec, ids, sumo_ids=None):
        self.rec, self.ids = rec, ids
        self.sumo_ids = ids if sumo_ids is None else sumo_ids  # SUMO's id of each member (join)
        self.run = np.zeros(len(ids), dtype=int)
        self.counting = False  # a member's run of refusals is under way (self.run.any())

    def __call__(self, t, act_idx, refused: dict, active, adapter) -> None:
        if not refused:  # every move taken (the usual step)
            if self.counting:
                self.run[act_idx] = 0
                self.counting = bool(self.run.any())
            return
        for i in act_idx:
            vid = self.ids[i]
            if self.sumo_ids[i] not in refused:
                self.run[i] = 0
                continue
            self.run[i] += 1
            self.rec.add_event(t, "move_refused", vid, "", refused[self.sumo_ids[i]])
            if self.run[i] >= MAX_REFUSED:
                active[i] = False
                adapter.remove_vehicle(self.sumo_ids[i])
                self.rec.add_event(t, "member_removed", vid, "",
                                   f"dropped after {MAX_REFUSED} refused moves in a row")
        self.counting = bool(self.run.any())
