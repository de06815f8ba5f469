"""Gaps in a formation's columns against the members' bodies and braking.

A member right behind another in its column (road-frame slots whose bodies overlap sideways)
must stop behind it when the formation brakes as hard as it can: with the virtual car's
emergency braking, each member follows it by its own speed law (its capability ``b`` [m/s^2]:
the law's peak, control/schedule.py ``law_peak``, at most the virtual car's ``decel_emergency``;
the kinematic model follows at ``decel_emergency``), and from the leader's top speed v the two
stopping distances differ by (v^2 / 2) (1 / b_follower - 1 / b_leader) when the follower brakes
less. With a reaction of one outer step (the reference and the caps change once per
``run.step``) plus the follower's drive lag, and the standstill gap ``leader.min_gap``:

    needed gap = max(0, (v^2 / 2) (1 / b_f - 1 / b_l)) + v (run.step + drive_lag_f) + min_gap

Slots whose bodies overlap (bumper gap < 0) are refused when the scenario is read
(:func:`check_column_bodies`, exit 2); a gap below the needed one is a warning in run.json
``warnings`` and on stderr (:func:`column_gap_warnings`). docs/model.md, "Mixed formations".
"""
from __future__ import annotations

import sys

import numpy as np

from ..control.schedule import law_peak
from ..scenario.load import ScenarioError


def column_pairs(slots, is_road, vehicles) -> list[tuple[int, int, float]]:
    """(follower i, leader j, bumper gap [m]) for every road-frame member i and the nearest
    road-frame member j ahead of it whose body overlaps i's sideways at their slots
    (``slots`` (n, 2): along, across [m] of the CoG; ``vehicles``: chassis per member)."""
    out = []
    road = [i for i in range(len(vehicles)) if is_road[i]]
    for i in road:
        vi = vehicles[i]
        best = None
        for j in road:
            vj = vehicles[j]
            if j == i or slots[j, 0] <= slots[i, 0] or \
                    abs(slots[j, 1] - slots[i, 1]) >= (vi.width + vj.width) / 2:
                continue
            gap = slots[j, 0] - slots[i, 0] - vi.cog_to_front_bumper - (vj.length - vj.cog_to_front_bumper)
            if best is None or gap < best[2]:
                best = (i, j, float(gap))
        if best is not None:
            out.append(best)
    return out


def needed_gap(v: float, b_follower: float, b_leader: float, reaction: float, min_gap: float) -> float:
    """Bumper gap [m] a follower braking at ``b_follower`` [m/s^2] needs behind a leader
    braking at ``b_leader`` from ``v`` [m/s], reacting ``reaction`` [s] later, to stop
    ``min_gap`` [m] behind it (module docstring)."""
    return max(0.0, 0.5 * v * v * (1.0 / b_follower - 1.0 / b_leader)) + v * reaction + min_gap


def check_column_bodies(sc, slots, is_road, vehicles, source) -> None:
    """Refuse slots in a column whose bodies overlap (bumper gap < 0), naming both members."""
    problems = []
    for i, j, gap in column_pairs(slots, is_road, vehicles):
        if gap < 0.0:
            problems.append((f"members.{i}.slot", (
                f"member {sc.members[i].id!r}'s slot is {gap:.2f} m behind the rear of "
                f"{sc.members[j].id!r}'s in their column: their bodies "
                f"({vehicles[i].length:.1f} m, {vehicles[j].length:.1f} m) overlap; move it at "
                f"least {-gap:.2f} m further back")))
    if problems:
        raise ScenarioError(source or "<scenario>", problems)


def member_braking(sc, gains, decel_emergency: float) -> np.ndarray:
    """Each member's braking capability b [m/s^2] (module docstring); ``gains`` (n, 6) as
    sim/fleet.py Fleet.gains."""
    n = len(sc.members)
    if sc.vehicle.model != "dynamic":
        return np.full(n, float(decel_emergency))
    return np.array([min(law_peak(*g[:3]), decel_emergency) for g in np.asarray(gains)])


def column_gap_warnings(sc, slots, is_road, vehicles, gains, v_top: float, decel_emergency: float,
                        meta: dict) -> list[str]:
    """A warning (run.json ``warnings``, stderr) for every column pair whose slots' bumper gap
    is below :func:`needed_gap` at the leader's top speed ``v_top`` [m/s]; returns them."""
    b = member_braking(sc, gains, decel_emergency)
    texts = []
    for i, j, gap in column_pairs(slots, is_road, vehicles):
        need = needed_gap(v_top, b[i], b[j], sc.run.step + vehicles[i].drive_lag_s, sc.leader.min_gap)
        if gap >= need:
            continue
        fi, fj = sc.members[i].id, sc.members[j].id
        texts.append(
            f"member {fi!r} is {gap:.2f} m behind {fj!r} in their column; to stop behind it from "
            f"the leader's top speed {v_top:.2f} m/s it needs {need:.2f} m ({fi!r} brakes at "
            f"{b[i]:.3f} m/s^2, {fj!r} at {b[j]:.3f} m/s^2 by their speed laws): in an emergency "
            "stop of the virtual car the formation cannot be held (docs/model.md, 'Mixed formations')")
    have = meta.setdefault("warnings", [])
    for text in texts:
        if text not in have:  # formations of one flow share their slots
            have.append(text)
            print(f"warning: {text}", file=sys.stderr)
    return texts
