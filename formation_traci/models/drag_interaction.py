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

from ..core.kernels import kernel


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


@kernel
def _reduction(x, amplitude, decay, max_gap):
    """A_exp(-x / decay) for a gap 0 <= x <= max_gap [lengths], else 0 (the C library's exp:
    numpy's loop is SIMD code whose last bits depend on the CPU)."""
    if x >= 0.0 and x <= max_gap:
        return amplitude * math.exp(-x / decay)
    return 0.0


def wake_reduction(x: float, law: DragInteraction = PLATOON_DRAG) -> float:
    """Drag reduction [-] of a follower fully behind a vehicle, gap x [lengths of the leader]."""
    return _reduction(float(x), law.wake_amplitude, law.wake_decay, law.max_gap)


def push_reduction(x: float, law: DragInteraction = PLATOON_DRAG) -> float:
    """Drag reduction [-] of a vehicle with a follower fully behind it, gap x [own lengths]."""
    return _reduction(float(x), law.push_amplitude, law.push_decay, law.max_gap)


@kernel
def lateral_overlap(dy, w_self, w_other):
    """Share [-] of our width w_self [m] covered by a body of width w_other [m] whose centre
    is dy [m] to the side of ours."""
    cover = min(max(0.5 * (w_self + w_other) - abs(dy), 0.0), w_self)
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
    s, d, length, width = (np.ascontiguousarray(a, dtype=np.float64) for a in (s, d, length, width))
    present = (np.ones(s.shape[0], dtype=np.bool_) if present is None
               else np.ascontiguousarray(present, dtype=np.bool_))
    out = np.empty(int(n_members))
    _ratios_into(s, d, length, width, present, law_row(law), out)
    return out


@kernel
def road_ratios_into(m_s, m_d, present, bodies, nb, law, out):
    """Drag ratio [-] of each member on a road among SUMO's vehicles, into ``out`` (n,): the
    members' centres of gravity (m_s, m_d) [m] along and across the road, ``present`` the
    members still in SUMO, ``bodies`` (3, n) their length, width and CoG to front bumper [m],
    ``nb`` the other vehicles' (body centre s, d, length, width) [m], ``law`` (A_w, lambda_w,
    A_p, lambda_p, max_gap)."""
    nb_s, nb_d, nb_length, nb_width = nb
    n, m = m_s.shape[0], nb_s.shape[0]
    s, d = np.empty(n + m), np.empty(n + m)
    length, width = np.empty(n + m), np.empty(n + m)
    here = np.ones(n + m, dtype=np.bool_)
    for i in range(n):
        s[i] = m_s[i] + (bodies[2, i] - 0.5 * bodies[0, i])  # CoG -> body centre
        d[i], length[i], width[i], here[i] = m_d[i], bodies[0, i], bodies[1, i], present[i]
    for j in range(m):
        s[n + j], d[n + j], length[n + j], width[n + j] = nb_s[j], nb_d[j], nb_length[j], nb_width[j]
    _ratios_into(s, d, length, width, here, law, out)


def law_row(law: DragInteraction = PLATOON_DRAG) -> np.ndarray:
    """The law's parameters as the kernels take them: (A_w, lambda_w, A_p, lambda_p, max_gap)."""
    return np.array([law.wake_amplitude, law.wake_decay, law.push_amplitude, law.push_decay,
                     law.max_gap])


@kernel
def _ratios_into(s, d, length, width, present, law, out):
    """:func:`drag_ratios` of the first len(out) vehicles into ``out``; ``law``: (A_w, lambda_w,
    A_p, lambda_p, max_gap)."""
    for i in range(out.shape[0]):
        if not present[i]:
            out[i] = 1.0
            continue
        wake = push = 0.0  # the strongest vehicle ahead and behind
        front, rear = s[i] + 0.5 * length[i], s[i] - 0.5 * length[i]
        for j in range(s.shape[0]):
            if j == i or not present[j]:
                continue
            o = lateral_overlap(d[j] - d[i], width[i], width[j])
            g_ahead = (s[j] - 0.5 * length[j]) - front  # our front to its rear
            g_behind = rear - (s[j] + 0.5 * length[j])  # its front to our rear
            if g_ahead >= 0.0:
                wake = max(wake, o * _reduction(g_ahead / length[j], law[0], law[1], law[4]))
            if g_behind >= 0.0:
                push = max(push, o * _reduction(g_behind / length[i], law[2], law[3], law[4]))
        out[i] = (1.0 - wake) * (1.0 - push)


def along_heading(x, y, heading: float):
    """Positions (x, y) [m] as (along, across) a direction of travel ``heading`` [rad], for
    free-space runs where no road frame exists."""
    c, s = math.cos(heading), math.sin(heading)  # the C library's: numpy's may be SVML
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return c * x + s * y, -s * x + c * y
