"""Members handed between the formation and SUMO's driver (a leave's release, a join's
take-over or entry): a mixin of sumo/world.py SumoWorld, which has the attributes used
here (adapter, rec, ids, sumo_ids, active, in_sumo, released, adopting, fleet, v_after)."""
from __future__ import annotations

from .join import adopt, enter, take_over
from .adapter import SumoError
from .traffic import CAR


class MemberHandover:
    """release / take_over / command / adopt of SumoWorld (see the module docstring)."""

    def release(self, t: float, i: int, exit_edge: str = "") -> None:
        """Leave: hand member i over to SUMO's own driver model where it is (its lane,
        position and speed); it drives on as an ordinary vehicle with a SUMO car's
        acceleration and deceleration (sumo/traffic.py CAR), routed to ``exit_edge`` when
        given, and is no longer controlled."""
        vid = self.sumo_ids[i]
        if not self.active[i] or not self.inserted or self.baseline:
            return
        v = float(self.v_after[i])
        way = f", routed to the exit {exit_edge}" if exit_edge else ""
        try:
            lane = self.adapter.release(vid, float(CAR["accel"]), float(CAR["decel"]), exit_edge)
        except SumoError as exc:
            lane, way = "?", f", not routed to the exit: {exc}"
        self.active[i] = False
        self.released.add(vid)
        self.rec.add_event(t, "handover", self.ids[i], vid if vid != self.ids[i] else "",
                           f"leave: released to SUMO at {v:.2f} m/s on lane {lane}{way}")

    def take_over(self, t: float, i: int, vid: str, sensed, where=None) -> None:
        """Join: SUMO vehicle ``vid`` becomes member i where it is, or (``where`` = (s, d, v))
        member i's own vehicle enters the road under SUMO's driver (sumo/join.py); a baseline
        twin has no formation to join."""
        if not self.inserted or self.baseline:
            return
        if where is None:
            take_over(self, t, i, vid, sensed)
        else:
            enter(self, t, i, *where)

    def command(self, t: float, commands, sensed, vc_id: str) -> None:
        """A formation's requests of this step (control/reference.py WorldCommand: leave,
        join, its events, recorded as the virtual car ``vc_id``'s), carried out in order
        before its reference."""
        for c in commands:
            if c.kind == "record":
                self.rec.add_event(t, c.event, vc_id, "", c.detail)
            elif c.kind == "release":
                self.release(t, c.member, c.vehicle)
            else:
                self.take_over(t, c.member, c.vehicle, sensed, c.where)

    def adopt(self, state, ref):
        """The fleet state with the vehicles taken over in this step written in (sumo/join.py)."""
        if self.adopting:
            adopt(self.fleet, state, ref, self.adopting)
        return state

    def joined_names(self) -> dict:
        """SUMO id -> member id of the vehicles taken over by a join."""
        return {s: m for s, m in zip(self.sumo_ids, self.ids) if s != m}
