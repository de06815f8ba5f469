"""The formation members of a run: as declared in ``run.json`` (id, slot offset of eq. 2.4,
frame) or, when not declared, taken from the trajectories with offsets inferred from
``x_des``/``y_des`` and the virtual-car pose.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from analysis.load.run_files import RUN_JSON, Issue
from run_contract.columns import VIRTUAL_CAR_ID

__all__ = ["Member", "run_members"]


@dataclass(frozen=True, slots=True)
class Member:
    """A formation member as declared in ``run.json`` (or inferred)."""

    id: str
    offset: tuple[float, float]  # m, (d_x, d_y) of eq. 2.4
    frame: str  # "vehicle" | "road" | "inferred"



def run_members(meta: dict[str, Any], traj: pd.DataFrame) -> tuple[list[Member], list[Issue]]:
    """The members of a run and the problems met.

    Parameters
    ----------
    meta : dict
        ``run.json`` content ({} when missing).
    traj : DataFrame
        Cleaned trajectories (``vehicle_id`` as str, float columns).

    Returns
    -------
    (list of Member, list of Issue)
        Declared members, then undeclared vehicles of the trajectories (offsets inferred,
        or NaN when they cannot be), and the issues (declared but without rows, inferred,
        undeclared).
    """
    members, issues = _members_from_meta(meta)
    ids_data = [v for v in pd.unique(traj["vehicle_id"]) if v != VIRTUAL_CAR_ID]
    if VIRTUAL_CAR_ID not in set(traj["vehicle_id"]):
        issues.append(Issue("error", "missing_vehicle", VIRTUAL_CAR_ID,
                            "no virtual-car rows: its path is not drawn and offsets cannot "
                            "be inferred"))
    declared = {m.id for m in members}
    twin = meta.get("baseline") is True
    for m in members:
        if m.id not in set(ids_data):
            issues.append(Issue("info", "baseline_run", m.id,
                                "baseline twin run: the formation is not driven, so the "
                                "member has no rows by design") if twin else
                          Issue("error", "missing_vehicle", m.id,
                                "member declared in run.json has no trajectory rows"))
    if "members" not in meta or not members:
        for mid in ids_data:
            off = _infer_offset(traj, mid)
            if off is not None:
                members.append(Member(mid, off, "inferred"))
        if ids_data:
            issues.append(Issue("warning", "members_inferred", "members",
                                "member list taken from the trajectories; offsets inferred "
                                "from x_des/y_des and the virtual-car pose (eq. 2.4)"
                                if members else
                                "member list taken from the trajectories; offsets unknown"))
        known = {m.id for m in members}
        members += [Member(mid, (math.nan, math.nan), "unknown") for mid in ids_data
                    if mid not in known]
    else:
        for mid in ids_data:
            if mid not in declared:
                issues.append(Issue("warning", "undeclared_vehicle", mid,
                                    "vehicle in the trajectories but not in run.json members; "
                                    "analysed without a declared offset"))
                off = _infer_offset(traj, mid)
                members.append(Member(mid, off if off else (math.nan, math.nan),
                                      "inferred" if off else "unknown"))

    return members, issues


def _members_from_meta(meta: dict[str, Any]) -> tuple[list[Member], list[Issue]]:
    raw = meta.get("members")
    if raw is None:
        return [], []
    if not isinstance(raw, list):
        return [], [Issue("error", "invalid_meta", f"{RUN_JSON}:members", "not a list")]
    out, issues = [], []
    for k, m in enumerate(raw):
        try:
            mid = str(m["id"])
            off = tuple(float(v) for v in m["offset"])
            if len(off) != 2 or not all(math.isfinite(v) for v in off):
                raise ValueError("offset must be two finite numbers")
            frame = str(m.get("frame", "vehicle"))
            if "frame" not in m:
                issues.append(Issue("warning", "missing_meta_key",
                                    f"{RUN_JSON}:members[{k}].frame",
                                    "frame missing, assumed 'vehicle'"))
            out.append(Member(mid, (off[0], off[1]), frame))
        except (KeyError, TypeError, ValueError) as exc:
            issues.append(Issue("error", "invalid_meta", f"{RUN_JSON}:members[{k}]",
                                f"unusable member entry {m!r}: {exc}"))
    return out, issues


def _infer_offset(traj: pd.DataFrame, mid: str) -> tuple[float, float] | None:
    from analysis.metrics.formation import offsets_in_vc_frame

    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, ["t", "x", "y", "heading"]]
    me = traj.loc[traj["vehicle_id"] == mid, ["t", "x_des", "y_des"]]
    j = me.merge(vc, on="t").dropna()
    if j.empty:
        return None
    dx, dy = offsets_in_vc_frame(j["x_des"], j["y_des"], j["x"], j["y"], j["heading"])
    return float(np.median(dx)), float(np.median(dy))
