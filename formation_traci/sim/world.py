"""The World protocol: what the step loop (runner.py) asks of free space and of SUMO.

Per step: ``sense`` (what the world reports at the start of the step, for the reference
generator and the recorder) -> ``observe`` (events and surroundings once the reference is
known) -> ``stop_reason`` -> ``actuate`` (the members' new poses) -> ``step`` (the world's
own time step). ``start`` before the first step, ``close`` always at the end.

``command`` carries out what a reference generator asks before its reference (a maneuver's
leave or join, control/reference.py WorldCommand); ``adopt`` writes vehicles the world handed
to the formation into the fleet state. Members enter and leave at any step: ``spawn(t, rows)`` puts the fleet rows ``rows`` into the
run (they enter the world where their state says at the next ``actuate``; every member of a
run is spawned before its first step), ``retire(t, rows, why)`` takes them out of the run and
the world at once (an event ``member_retired`` says why).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

_EMPTY = np.empty(0)


@dataclass
class Sensed:
    """What the world reports at the start of a step (road coordinates where it has a road)."""

    active: np.ndarray  # (n,) bool: members still in the run
    extra: dict = field(default_factory=dict)  # recorded columns the world supplies, (n,)
    v_m: np.ndarray = field(default_factory=lambda: _EMPTY)  # members' speed [m/s]
    m_s: np.ndarray = field(default_factory=lambda: _EMPTY)  # members' arc length along the reference line [m]
    m_d: np.ndarray = field(default_factory=lambda: _EMPTY)  # members' lateral offset, left positive [m]
    nb: object = None  # sumo_adapter.Neighbours or None
    nb_s: np.ndarray = field(default_factory=lambda: _EMPTY)  # neighbours' arc length [m]
    nb_d: np.ndarray = field(default_factory=lambda: _EMPTY)  # neighbours' lateral offset [m]
    nb_rear: np.ndarray = field(default_factory=lambda: _EMPTY)  # neighbours' rear arc length [m]
    nb_half_w: np.ndarray = field(default_factory=lambda: _EMPTY)  # neighbours' half width [m]
    nb_v: np.ndarray = field(default_factory=lambda: _EMPTY)  # neighbours' speed [m/s]
    # neighbours that are released members still inside the formation (behind the front of a
    # member in their lane): the virtual car's slot law does not brake for them, the members
    # behind them do (empty: none)
    nb_in_formation: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.bool_))
    # the world's upper bound on the formation's requested acceleration [m/s^2] (inf: none;
    # SUMO's world: opening a gap for ramp traffic, sumo/merge_watch.py)
    a_limit: float = float("inf")
    a_limits: object = None  # (k,) the same per formation, in the world's order (None: none)


def sensed_of(sensed: Sensed, sl: slice) -> Sensed:
    """What the world sensed, as formation ``sl`` sees it: its members' rows (views), every
    neighbour. Its transforms' recorded columns go back into ``sensed`` with
    sim/formation.py ``merge_extra``."""
    n = len(sensed.active)
    pick = (lambda a: a[sl] if isinstance(a, np.ndarray) and a.shape[:1] == (n,) else a)
    return replace(sensed, active=sensed.active[sl],
                   extra={k: pick(v) for k, v in sensed.extra.items()},
                   v_m=pick(sensed.v_m), m_s=pick(sensed.m_s), m_d=pick(sensed.m_d))


class World(Protocol):
    records_members: bool  # False for a baseline twin: the formation is not in this world

    def start(self) -> None: ...

    def sense(self, k: int, t: float, state) -> Sensed: ...

    def observe(self, t: float, sensed: Sensed, ref) -> None: ...

    def stop_reason(self, t: float) -> tuple[str, str, str] | None: ...

    def actuate(self, t_next: float, state, v_before: np.ndarray) -> None: ...

    def step(self, k: int, t_next: float) -> None: ...

    def command(self, t: float, commands: list, sensed: Sensed, vc_id: str) -> None: ...

    def sensed_for(self, sensed: Sensed, rows: slice) -> Sensed: ...  # a formation's view of it

    def has_room(self, t: float, rows: slice, state) -> bool: ...  # may members ``rows`` enter now?

    def adopt(self, state, ref): ...

    def spawn(self, t: float, rows: np.ndarray) -> None: ...

    def retire(self, t: float, rows: np.ndarray, why: str) -> None: ...

    def drain(self) -> None: ...  # after a run that ended normally (SUMO: the sections' drain)

    def close(self) -> None: ...


class FreeSpace:
    """No road, no traffic: the members' model is the whole world."""

    records_members = True

    def __init__(self, n: int, rec=None):
        self.sensed = Sensed(active=np.ones(n, dtype=bool))
        self.rec = rec  # sim/recorder.py Recorder, for the events (None: none recorded)

    def command(self, t, commands, sensed, vc_id) -> None:
        if commands:
            raise ValueError(f"free space cannot carry out {[c.kind for c in commands]}")

    def adopt(self, state, ref):
        return state

    def has_room(self, t, rows, state) -> bool:
        return True

    def sensed_for(self, sensed, rows) -> Sensed:
        """Formations in free space do not see each other: their members' rows only."""
        return sensed_of(sensed, rows)

    def spawn(self, t, rows) -> None:
        self.sensed.active[rows] = True

    def retire(self, t, rows, why: str) -> None:
        act = self.sensed.active
        for i in np.atleast_1d(rows):
            if act[i] and self.rec is not None:
                self.rec.add_event(t, "member_retired", self.rec.member_ids[i], "", why)
            act[i] = False

    def start(self) -> None:
        pass

    def sense(self, k, t, state) -> Sensed:
        return self.sensed

    def observe(self, t, sensed, ref) -> None:
        pass

    def stop_reason(self, t):
        return None

    def actuate(self, t_next, state, v_before) -> None:
        pass

    def step(self, k, t_next) -> None:
        pass

    def drain(self) -> None:
        pass

    def close(self) -> None:
        pass
