"""Which member takes which new slot: paths that do not cross when they need not.

Members move from their slots to the new ones along synchronised straight lines (every
member follows the same quintic h(tau) of control/maneuvers/transition.py). For discs
moving that way, the assignment that minimises the sum of squared path lengths keeps every
pair apart at least as far as at the start and the goal allow (Turpin, Michael & Kumar,
"CAPT: Concurrent assignment and planning of trajectories", IJRR 2014): its paths do not
cross. Vehicles are long and narrow, so lengths are measured in a scaled road frame where a
vehicle's footprint plus its margins is about square: along / ALONG_SCALE, across /
ACROSS_SCALE. The Hungarian method (scipy.optimize.linear_sum_assignment) finds the optimum;
:func:`min_clearance` checks the resulting paths with the real body rectangles.
"""
from __future__ import annotations

import numpy as np

ALONG_SCALE = 8.0
"""Length of a car plus its margins [m] (the along axis of the scaled frame)."""
ACROSS_SCALE = 3.5
"""Lane width [m] (the across axis of the scaled frame)."""
TIE_BREAK = 1e-6
"""Weight of the path length added to the squared length: breaks exact ties only [-]."""


def assign_slots(current: np.ndarray, targets: np.ndarray,
                 along_scale: float = ALONG_SCALE, across_scale: float = ACROSS_SCALE) -> np.ndarray:
    """Index of the target slot of every member.

    Parameters
    ----------
    current : ndarray, shape (n, 2)
        Members' present slots (along, across) [m].
    targets : ndarray, shape (m, 2), m >= n
        The new formation's slots [m]; m - n slots stay free.

    Returns
    -------
    ndarray of int, shape (n,)
        ``targets[result[i]]`` is member i's new slot; the sum of squared scaled path lengths
        is minimal. Ties (e.g. the two outer members of a row going to a column) are broken
        towards the shorter sum of path lengths, so a member that can keep its place does.
    """
    current = np.asarray(current, dtype=float).reshape(-1, 2)
    targets = np.asarray(targets, dtype=float).reshape(-1, 2)
    if len(targets) < len(current):
        raise ValueError(f"{len(targets)} slots for {len(current)} members")
    scale = np.array([along_scale, across_scale])
    diff = (current[:, None, :] - targets[None, :, :]) / scale
    cost = np.sum(diff * diff, axis=2)
    cost = cost + TIE_BREAK * np.sqrt(cost)
    from scipy.optimize import linear_sum_assignment  # only when a maneuver reassigns slots

    rows, cols = linear_sum_assignment(cost)
    out = np.empty(len(current), dtype=int)
    out[rows] = cols
    return out


def min_clearance(start: np.ndarray, goal: np.ndarray, lengths, widths, samples: int = 201) -> float:
    """Smallest clearance [m] between any two members moving synchronously from ``start`` to
    ``goal`` (both (n, 2), road frame), bodies as road-aligned rectangles.

    The clearance of a pair is max(|d_along| - (L_i + L_j)/2, |d_across| - (W_i + W_j)/2):
    positive when the rectangles are apart, negative when they overlap. Because every member
    follows the same h(tau) in [0, 1], sampling h uniformly covers the whole transition.
    """
    start = np.asarray(start, dtype=float)
    goal = np.asarray(goal, dtype=float)
    n = len(start)
    if n < 2:
        return np.inf
    L = np.broadcast_to(np.asarray(lengths, dtype=float), (n,))
    W = np.broadcast_to(np.asarray(widths, dtype=float), (n,))
    h = np.linspace(0.0, 1.0, samples)[:, None, None]
    p = start[None] + h * (goal - start)[None]  # (samples, n, 2)
    i, j = np.triu_indices(n, 1)
    da = np.abs(p[:, i, 0] - p[:, j, 0]) - (L[i] + L[j]) / 2
    dc = np.abs(p[:, i, 1] - p[:, j, 1]) - (W[i] + W[j]) / 2
    return float(np.min(np.maximum(da, dc)))
