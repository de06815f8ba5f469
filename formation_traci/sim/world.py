"""The World protocol: what the step loop (sim/runner.py) asks of free space and of SUMO.

Per step: ``sense`` (what the world reports at the start of the step, for the reference
generator and the recorder) -> ``observe`` (events and surroundings once the reference is
known) -> ``stop_reason`` -> ``actuate`` (the members' new poses) -> ``step`` (the world's
own time step). ``start`` before the first step, ``close`` always at the end.
"""
from __future__ import annotations

from dataclasses import dataclass, field
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
    # behind them do (issue 32; empty: none)
    nb_in_formation: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.bool_))


class World(Protocol):
    records_members: bool  # False for a baseline twin: the formation is not in this world

    def start(self) -> None: ...

    def sense(self, k: int, t: float, state) -> Sensed: ...

    def observe(self, t: float, sensed: Sensed, ref) -> None: ...

    def stop_reason(self, t: float) -> tuple[str, str, str] | None: ...

    def actuate(self, t_next: float, state, v_before: np.ndarray) -> None: ...

    def step(self, k: int, t_next: float) -> None: ...

    def close(self) -> None: ...


class FreeSpace:
    """No road, no traffic: the members' model is the whole world."""

    records_members = True

    def __init__(self, n: int):
        self.sensed = Sensed(active=np.ones(n, dtype=bool))

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

    def close(self) -> None:
        pass
