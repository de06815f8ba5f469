"""The members' dynamic state between steps (sim/fleet.py steps it)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class FleetState:
    """Dynamic state of the members: vehicle states and the controller's theta* (2.11)."""

    x: np.ndarray  # (n, n_states)
    theta_star: np.ndarray  # (n,) [rad]
    speed_in: np.ndarray  # (n,) unicycle only: speed input applied last [m/s]
    u_last: np.ndarray | None = None  # (n,) every member's u0 of the last control period
    # (a_r [m/s^2], dynamic model): what a platoon law reads of its predecessor and of its
    # own controller state (control/laws); None: zeros (nothing computed yet)

    def copy(self) -> "FleetState":
        return FleetState(self.x.copy(), self.theta_star.copy(), self.speed_in.copy(),
                          None if self.u_last is None else self.u_last.copy())

    def hold(self, rows: slice, held: "FleetState") -> None:
        """Rows ``rows`` set to ``held`` (a formation's own state, in place)."""
        self.x[rows], self.theta_star[rows], self.speed_in[rows] = held.x, held.theta_star, held.speed_in
        if self.u_last is not None:
            self.u_last[rows] = 0.0 if held.u_last is None else held.u_last

    def hold_where(self, mask: np.ndarray, held: "FleetState") -> None:
        """Rows where ``mask`` (n,) set to those of ``held`` (a state of every row, in place)."""
        self.x[mask], self.theta_star[mask], self.speed_in[mask] = held.x[mask], held.theta_star[mask], held.speed_in[mask]
        if self.u_last is not None:
            self.u_last[mask] = held.u_last[mask]

    def rows(self, rows: slice) -> "FleetState":
        """A copy of rows ``rows`` (a formation's own state)."""
        return FleetState(self.x[rows].copy(), self.theta_star[rows].copy(), self.speed_in[rows].copy(),
                          None if self.u_last is None else self.u_last[rows].copy())
