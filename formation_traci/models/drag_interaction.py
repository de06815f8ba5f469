"""Formation-aware aerodynamic drag: the c_d multiplier of each member from the vehicles
around it (docs/energy.md has the sources, the fit and the range of validity).

Two published effects, each a function of the bumper-to-bumper gap g [m] and the lateral
offset dy [m] between body centres:

* wake (drafting): a vehicle ahead whose body overlaps ours sideways lowers our drag,
  dw = A_w exp(-x / lambda_w), x = g / L_ahead;
* push (base pressure): a vehicle close behind raises our base pressure and lowers our
  drag, dp = A_p exp(-x / lambda_p), x = g / L_self.

Each is scaled by the share of our width the other body covers,
o = clip((w_self + w_other) / 2 - |dy|, 0, w_self) / w_self, and only the strongest
vehicle ahead and the strongest behind count (the nearest shields the rest). The ratio is

    k = (1 - max_ahead(o dw)) (1 - max_behind(o dp)),    k = 1 alone.

Vehicles that overlap ours longitudinally (side by side) or are farther than ``max_gap``
vehicle lengths do not count. Background vehicles count like members.
"""
from __future__ import annotations

from dataclasses import dataclass

import math

import numpy as np


@dataclass(frozen=True, slots=True)
class DragInteraction:
    """Parameters of the drag-ratio law (fit in docs/energy.md)."""

    wake_amplitude: float  # A_w: wake reduction at zero gap [-]
    wake_decay: float  # lambda_w: decay length of the wake effect [lengths of the vehicle ahead]
    push_amplitude: float  # A_p: base-pressure reduction at zero gap [-]
    push_decay: float  # lambda_p: decay length of the push effect [own lengths]
    max_gap: float  # gaps beyond this many vehicle lengths do not count [-]


PLATOON_DRAG = DragInteraction(wake_amplitude=0.53, wake_decay=1.2, push_amplitude=0.68,
                               push_decay=0.5, max_gap=6.0)
"""Fit to Zabat et al. (SAE 940421) and Cerutti et al. (2021), see docs/energy.md."""


def wake_reduction(x, law: DragInteraction = PLATOON_DRAG):
    """Drag reduction [-] of a follower fully behind a vehicle, gap x [lengths of the leader]."""
    x = np.asarray(x, dtype=float)
    ok = (x >= 0.0) & (x <= law.max_gap)
    return np.where(ok, law.wake_amplitude * np.exp(-np.maximum(x, 0.0) / law.wake_decay), 0.0)


def push_reduction(x, law: DragInteraction = PLATOON_DRAG):
    """Drag reduction [-] of a vehicle with a follower fully behind it, gap x [own lengths]."""
    x = np.asarray(x, dtype=float)
    ok = (x >= 0.0) & (x <= law.max_gap)
    return np.where(ok, law.push_amplitude * np.exp(-np.maximum(x, 0.0) / law.push_decay), 0.0)


def lateral_overlap(dy, w_self, w_other):
    """Share of our width [-] covered by the other body at lateral offset dy [m] (widths [m])."""
    cover = np.clip(0.5 * (w_self + w_other) - np.abs(dy), 0.0, w_self)
    return cover / w_self


def drag_ratios(s, d, length, width, n_members: int, law: DragInteraction = PLATOON_DRAG,
                present=None) -> np.ndarray:
    """Drag ratio k [-] of each member among all vehicles.

    Parameters
    ----------
    s, d : ndarray, shape (N,)
        Body centre along the road (or the direction of travel) and across it [m]; the
        first ``n_members`` rows are the members, the rest other vehicles.
    length, width : ndarray, shape (N,)
        Body length and width [m].
    n_members : int
        Number of members (leading rows).
    law : DragInteraction
        Parameters of the law.
    present : ndarray of bool, shape (N,), optional
        Vehicles that take part (e.g. members still on the road); default all.

    Returns
    -------
    ndarray, shape (n_members,)
        c_d multiplier of every member, in (0, 1]; 1 for a member not present.
    """
    s, d, length, width = (np.asarray(a, dtype=float) for a in (s, d, length, width))
    n_all = s.shape[0]
    present = np.ones(n_all, dtype=bool) if present is None else np.asarray(present, dtype=bool)
    i = slice(0, n_members)
    # gap from member i's front to vehicle j's rear (j ahead), and from j's front to i's rear
    g_ahead = (s[None, :] - 0.5 * length[None, :]) - (s[i, None] + 0.5 * length[i, None])
    g_behind = (s[i, None] - 0.5 * length[i, None]) - (s[None, :] + 0.5 * length[None, :])
    o = lateral_overlap(d[None, :] - d[i, None], width[i, None], width[None, :])
    others = present[None, :] & ~np.eye(n_members, n_all, dtype=bool)
    o = np.where(others, o, 0.0)
    dw = o * wake_reduction(np.where(g_ahead >= 0.0, g_ahead / length[None, :], -1.0), law)
    dp = o * push_reduction(np.where(g_behind >= 0.0, g_behind / length[i, None], -1.0), law)
    k = (1.0 - dw.max(axis=1, initial=0.0)) * (1.0 - dp.max(axis=1, initial=0.0))
    return np.where(present[i], k, 1.0)


def along_heading(x, y, heading: float):
    """Positions (x, y) [m] as (along, across) a direction of travel ``heading`` [rad], for
    free-space runs where no road frame exists."""
    c, s = math.cos(heading), math.sin(heading)  # the C library's: numpy's may be SVML
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return c * x + s * y, -s * x + c * y
