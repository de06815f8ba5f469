"""The formation reference of one step: an explicit value the controller kernels consume.

A :class:`Reference` holds, for every control period of the step and every member:

* the virtual car as that member knows it (``vc``: x, y [m], theta [rad], v [m/s], omega
  [rad/s], v_dot [m/s^2], omega_dot [rad/s^2], s [m] along the road line or NaN);
* the member's slot (``slots``: dx, dy [m] and their first and second time derivatives)
  in its frame (``frame``: FRAME_VEHICLE, eq 2.4, or FRAME_ROAD, road/targets.py);
* which members are in the run (``active``) and the traffic safety layer's caps on the
  speed reference (``v_cap`` [m/s]) and desired acceleration (``a_cap`` [m/s^2]).

Reference generators (:mod:`.reference_free`, :mod:`.reference_road`) produce it; any
number of transforms (a maneuver planner moving slots, a communication channel handing a
member a delayed virtual car) may replace it before sim/fleet.py's kernels run
(docs/architecture.md). A transform is ``f(reference) -> reference``.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field, replace
from typing import Callable, Protocol, runtime_checkable

import numpy as np

from ..core.kernels import kernel
from ..core.states import LeaderState

VC_FIELDS = ("x", "y", "theta", "v", "omega", "v_dot", "omega_dot", "s")
"""Columns of Reference.vc (last axis)."""
SLOT_FIELDS = ("dx", "dy", "dx_dot", "dy_dot", "dx_ddot", "dy_ddot")
"""Columns of Reference.slots (last axis) [m, m, m/s, m/s, m/s^2, m/s^2]."""
FRAME_VEHICLE = 0
"""Slot offsets in the virtual car's frame (rigid structure, eq 2.4)."""
FRAME_ROAD = 1
"""Slot offsets in road (Frenet) coordinates of the reference line (road/targets.py)."""

NO_LINE = np.zeros(1)
"""Line buffer of free-space references (no member has a road-frame slot)."""


@dataclass(frozen=True, eq=False)
class Reference:
    """The formation reference for the step starting at ``t`` (see the module docstring)."""

    t: float  # start of the step [s]
    dt: float  # control period [s]
    vc: np.ndarray  # (n_ctrl, n, 8) float64, VC_FIELDS
    slots: np.ndarray  # (n_ctrl, n, 6) float64, SLOT_FIELDS
    frame: np.ndarray  # (n,) int64, FRAME_*
    active: np.ndarray  # (n,) bool
    v_cap: np.ndarray  # (n,) [m/s], +inf: none
    a_cap: np.ndarray  # (n,) [m/s^2], +inf: none
    line: np.ndarray = field(default_factory=lambda: NO_LINE, repr=False)  # road/fast_line.py G
    truth: np.ndarray = field(default=None, repr=False)  # (8,) the virtual car itself at t
    info: dict = field(default_factory=dict, repr=False)  # generator diagnostics (events)
    a_cap_from: np.ndarray | None = field(default=None, repr=False)  # (n,) the caps at the
    # start of the step: period j's cap goes from it to a_cap (j / n_ctrl; sim/fleet.py
    # cap_at); None: a_cap held over the step. A transform that changes a_cap changes it too

    @property
    def n_ctrl(self) -> int:
        return self.vc.shape[0]

    def leader(self) -> LeaderState:
        """The virtual car itself at t (recorded as the 'vc' rows)."""
        return LeaderState(*(float(q) for q in self.truth[:7]))

    def with_(self, **changes) -> "Reference":
        """A copy with fields replaced (arrays are not copied: transforms copy what they
        change)."""
        return replace(self, **changes)


Transform = Callable[[Reference], Reference]


@runtime_checkable
class SensingTransform(Protocol):
    """A transform told what the world sensed before it is applied (comm/link.py): the step
    index, its time [s], the formation's Sensed, its members' (pos, vel, heading) and the
    recorder. With ``error_against_truth = True`` the formation error is recorded against
    the true virtual car (sim/formation.py Formation.true_error)."""

    def sense(self, k: int, t: float, sensed, kinematics, rec) -> None: ...

    def __call__(self, ref: Reference) -> Reference: ...


@dataclass(frozen=True)
class WorldCommand:
    """What a reference generator asks of the world before its step's reference
    (control/maneuvers: a leave or a join), handed over by the loop (sim/world.py
    ``command``): ``release`` member i to the world's own driver (``vehicle``: the exit edge,
    or ""), ``take_over`` the world's vehicle ``vehicle`` as member i, or ``enter``: member i's
    own vehicle enters the road under the world's driver at ``where`` = (s, d, v); or
    ``record`` the planner's event ``event`` (a maneuver started, ended, ...) with ``detail``,
    in the order the planner gave them."""

    kind: str
    member: int = -1
    vehicle: str = ""
    where: tuple | None = None
    event: str = ""
    detail: str = ""


class ReferenceGenerator(Protocol):
    """A formation's reference generator (control/reference_free.py, reference_road.py)."""

    def plan(self, t: float, sensed) -> list[WorldCommand]: ...

    def reference(self, t: float, sensed) -> Reference: ...

    def commit(self) -> None: ...

    def stop_reason(self, t: float) -> tuple[str, str, str] | None: ...


def constant_slots(offsets: np.ndarray, n_ctrl: int) -> np.ndarray:
    """(n_ctrl, n, 6) slots of a fixed structure: offsets (n, 2), zero rates."""
    offsets = np.nan_to_num(np.asarray(offsets, dtype=float))
    out = np.zeros((n_ctrl, len(offsets), 6))
    out[:, :, 0:2] = offsets
    return out


def apply(ref: Reference, transforms) -> Reference:
    """``ref`` through every transform in order."""
    for tr in transforms:
        ref = tr(ref)
    return ref


@kernel
def cap_at(a_from, a_to, j, n_ctrl):
    """Acceleration cap [m/s^2] of control period j of n_ctrl: from the step's start value
    ``a_from`` to its end value ``a_to`` in proportion to j (Reference.a_cap_from: the caps
    change once per outer step, the members' caps change continuously); ``a_to`` when either
    is not finite (a cap that appears or lifts) or when the two are equal (held)."""
    if math.isfinite(a_from) and math.isfinite(a_to):
        return a_from + (a_to - a_from) * j / n_ctrl
    return a_to


@kernel
def set_vc_period(vc, j, X, Y, th, v, om, v_dot, om_dot, s):
    """Every member's copy of the virtual car in control period j (Reference.vc rows)."""
    for i in range(vc.shape[1]):
        vc[j, i, 0] = X
        vc[j, i, 1] = Y
        vc[j, i, 2] = th
        vc[j, i, 3] = v
        vc[j, i, 4] = om
        vc[j, i, 5] = v_dot
        vc[j, i, 6] = om_dot
        vc[j, i, 7] = s
