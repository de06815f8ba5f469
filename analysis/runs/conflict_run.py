"""Per-run conflict metrics: SUMO's SSM conflicts and the conflicts measured from the recording.

* SUMO's SSM table (``ssm.parquet``): copies merged, warm-up left out, and every record with
  an *extreme* value (TTC 0 or a DRAC no car can brake) classified as ``real``, ``insertion``,
  ``lane_change`` or ``moved_member`` (:func:`classify_extremes`); the artefacts are counted
  apart and left out of the member/other statistics.
* Conflicts from the recording (:func:`analysis.metrics.conflicts.recorded_conflicts`): members and
  the background recorded within ``traffic.record_radius``; what a run gets by default.

Definitions: ``docs/metrics.md``, "SUMO's SSM conflicts" and "Conflicts from the recording".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from analysis.metrics import conflicts as cf
from analysis.metrics import traffic as tr

__all__ = [
    "EXTREME_TTC_S", "EXTREME_DRAC_MPS2", "MEMBER_JUMP_WINDOW_S", "APPEAR_WINDOW_S",
    "SSM_CLASSES", "SSM_RUN_METRICS", "CONFLICT_RUN_METRICS", "CONFLICT_MEMBER_METRICS",
    "SsmResult", "classify_extremes", "ssm_section", "recorded_section",
]

EXTREME_TTC_S = 0.05
"""An SSM record whose minimum TTC is at most this is extreme [s] (SUMO writes 0.00 when the
gap along the lane is <= 0, its encounter type 111 "collision")."""
EXTREME_DRAC_MPS2 = 10.0
"""An SSM record whose maximum DRAC exceeds this is extreme [m/s^2]: more than any SUMO vehicle's
emergency deceleration (cars 9, trucks 7 m/s^2), so no braking avoids the crash."""
MEMBER_JUMP_WINDOW_S = 2.0
"""An extreme within this time after a member entered SUMO or SUMO put it elsewhere than asked
(``placement_mismatch``, ``move_refused``) near the conflict is a moved-member artefact [s]."""
APPEAR_WINDOW_S = 1.0
"""An extreme within this time of the encounter's begin means the pair met already in conflict:
one of the two appeared there (inserted; SUMO starts an encounter as soon as a foe is in range)."""
SSM_CLASSES = ("real", "insertion", "lane_change", "moved_member")
"""Classes of extreme SSM records; all but ``real`` are artefacts."""
COLLISION_TYPE = 111
"""SUMO's SSM encounter type of a pair whose gap along the lane is <= 0."""

_SSM_RUN = {"n": "-", "ttc_min": "s", "drac_max": "m/s^2", "pet_min": "s",
            "n_ttc_warning": "-", "n_ttc_critical": "-", "n_drac_high": "-"}
_SSM_COL = {"n": "n_conflicts", "ttc_min": "ttc_min_s", "drac_max": "drac_max_mps2",
            "pet_min": "pet_min_s", "n_ttc_warning": "n_ttc_warning",
            "n_ttc_critical": "n_ttc_critical", "n_drac_high": "n_drac_high"}
_SUFFIX = {"-": "", "s": "_s", "m/s^2": "_mps2"}

SSM_RUN_METRICS: dict[str, str] = {
    **{f"ssm_{k}_{g}{_SUFFIX[u]}": u for g in ("member", "other") for k, u in _SSM_RUN.items()},
    "ssm_n_other_near": "-", "ssm_n_before_start": "-", "ssm_n_duplicates_merged": "-",
    "ssm_n_extreme": "-", **{f"ssm_n_extreme_{c}": "-" for c in SSM_CLASSES},
    "ssm_n_artefact": "-",
}
"""Run-level metrics of SUMO's SSM table (``traffic.run``)."""

_CONF = {"n": "-", "ttc_min": "s", "drac_max": "m/s^2", "pet_min": "s", "n_ttc_critical": "-"}
CONFLICT_RUN_METRICS: dict[str, str] = {
    f"conflict_{k}_{g}{_SUFFIX[u]}": u for g in ("member", "bg") for k, u in _CONF.items()}
"""Run-level metrics of the conflicts from the recording: pairs with a member, and background
pairs (both recorded, i.e. near the formation)."""
CONFLICT_MEMBER_METRICS: dict[str, str] = {
    "conflict_n": "-", "conflict_ttc_min_s": "s", "conflict_drac_max_mps2": "m/s^2",
    "conflict_pet_min_s": "s"}
"""Per-member metrics of the conflicts from the recording."""


def _f(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


@dataclass
class SsmResult:
    """What the SSM section adds to a run's traffic metrics."""

    run: dict[str, Any] = field(default_factory=dict)
    members: dict[str, dict[str, Any]] = field(default_factory=dict)
    table: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=list(tr.SSM_GROUP_COLUMNS)))
    member_conflicts: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(
        columns=["begin", "end", "ego", "foe", "min_ttc", "min_ttc_time", "max_drac",
                 "max_drac_time", "pet"]))
    extremes: pd.DataFrame = field(default_factory=pd.DataFrame)
    unavailable: str | None = None


def _num(df: pd.DataFrame, col: str) -> np.ndarray:
    if col not in df.columns:
        return np.full(len(df), np.nan)
    return pd.to_numeric(df[col], errors="coerce").to_numpy(float)


def _member_jumps(members: set[str], events: pd.DataFrame | None, t_insert: float) -> pd.DataFrame:
    """When each member entered SUMO or SUMO put it elsewhere than asked: ``vehicle_id``, ``t``."""
    rows = [(m, t_insert) for m in members]
    if events is not None and {"kind", "vehicle_id", "t"} <= set(events.columns):
        e = events.loc[events["kind"].astype(str).isin(["placement_mismatch", "move_refused"])
                       & events["vehicle_id"].astype(str).isin(members)]
        rows += list(zip(e["vehicle_id"].astype(str), pd.to_numeric(e["t"], errors="coerce")))
    return pd.DataFrame(rows, columns=["vehicle_id", "t"])


def classify_extremes(merged: pd.DataFrame, members: set[str], events: pd.DataFrame | None,
                      member_s: pd.DataFrame | None, t_insert: float) -> np.ndarray:
    """Class of each SSM record with an extreme value ("" for the others).

    Rules, first match wins (docs/metrics.md):

    1. ``moved_member``: within :data:`MEMBER_JUMP_WINDOW_S` after a member entered SUMO
       (``t_insert``) or was put elsewhere than asked (``placement_mismatch``,
       ``move_refused``), the member being ego or foe, or within ``SSM_RANGE_M`` of where
       SUMO put the minimum TTC (``min_ttc_s``);
    2. ``real``: SUMO reported a ``collision`` of the pair between ``begin`` and ``end``;
    3. ``insertion``: the extreme came within :data:`APPEAR_WINDOW_S` of the encounter's
       begin: the pair met already in conflict, so one of them had just appeared;
    4. ``lane_change``: TTC 0 with SUMO's encounter type 111 (gap along the lane <= 0; or no
       type recorded, runs before it was) without any collision: the two share a lane side by
       side (sublane model, a lane change under way), and SUMO's lane-based gap is not a
       distance between the bodies;
    5. ``real`` otherwise.

    Parameters
    ----------
    merged : DataFrame
        SSM conflicts (``begin``, ``end``, ``ego``, ``foe``, ``min_ttc``, ``min_ttc_time``,
        ``max_drac``, ``max_drac_time``, optional ``min_ttc_type``, ``min_ttc_s``).
    members : set of str
        Member ids.
    events : DataFrame or None
        ``events.parquet``.
    member_s : DataFrame or None
        Members' ``t``, ``vehicle_id``, ``s`` (where they were).
    t_insert : float
        When the members entered SUMO [s].

    Returns
    -------
    ndarray of str
        One of :data:`SSM_CLASSES` per extreme record, ``""`` for the others.
    """
    n = len(merged)
    out = np.full(n, "", dtype=object)
    ttc, drac = _num(merged, "min_ttc"), _num(merged, "max_drac")
    extreme = (ttc <= EXTREME_TTC_S) | (drac > EXTREME_DRAC_MPS2)
    if not extreme.any():
        return out
    when = np.where(ttc <= EXTREME_TTC_S, _num(merged, "min_ttc_time"), _num(merged, "max_drac_time"))
    when = np.where(np.isfinite(when), when, _num(merged, "begin"))
    begin, end = _num(merged, "begin"), _num(merged, "end")
    ego, foe = merged["ego"].astype(str).to_numpy(), merged["foe"].astype(str).to_numpy()
    where_s, kind = _num(merged, "min_ttc_s"), _num(merged, "min_ttc_type")
    jumps = _member_jumps(members, events, t_insert)
    coll = set()
    if events is not None and {"kind", "vehicle_id", "other_id", "t"} <= set(events.columns):
        c = events.loc[events["kind"].astype(str) == "collision"]
        coll = list(zip(c["vehicle_id"].astype(str), c["other_id"].astype(str),
                        pd.to_numeric(c["t"], errors="coerce")))
    for i in np.flatnonzero(extreme):
        j = jumps.loc[(jumps["t"] <= when[i]) & (when[i] - jumps["t"] <= MEMBER_JUMP_WINDOW_S)]
        near = False
        for m in j["vehicle_id"]:
            if m in (ego[i], foe[i]):
                near = True
            elif member_s is not None and np.isfinite(where_s[i]):
                ms = member_s.loc[(member_s["vehicle_id"] == m)
                                  & (np.abs(member_s["t"] - when[i]) < 0.5 * MEMBER_JUMP_WINDOW_S), "s"]
                near = near or bool((np.abs(ms - where_s[i]) <= cf.SSM_RANGE_M).any())
        if near:
            out[i] = "moved_member"
        elif any({a, b} == {ego[i], foe[i]} and begin[i] - 1e-9 <= t <= end[i] for a, b, t in coll):
            out[i] = "real"
        elif when[i] - begin[i] <= APPEAR_WINDOW_S:
            out[i] = "insertion"
        elif ttc[i] <= EXTREME_TTC_S and (kind[i] == COLLISION_TYPE or not np.isfinite(kind[i])):
            out[i] = "lane_change"
        else:
            out[i] = "real"
    return out


def ssm_section(ssm: pd.DataFrame | None, ids: list[str], t_first: float, t_last: float,
                settings, bg_keys: set | None, dt: float, events: pd.DataFrame | None,
                member_s: pd.DataFrame | None) -> SsmResult:
    """SUMO's SSM conflicts of one run.

    Parameters
    ----------
    ssm : DataFrame or None
        ``ssm.parquet``.
    ids : list of str
        Member ids.
    t_first : float
        First recorded time [s]; conflicts ended before it are the warm-up's.
    t_last : float
        Last recorded time [s].
    settings : AnalysisSettings
        ``ssm_ttc_warning_s``, ``ssm_ttc_critical_s``, ``ssm_drac_high_mps2``.
    bg_keys : set of (vehicle id, step) or None
        Recorded background rows (``ssm_n_other_near``); None without a background table.
    dt : float
        Sample spacing [s].
    events : DataFrame or None
        ``events.parquet`` (for :func:`classify_extremes`).
    member_s : DataFrame or None
        Members' ``t``, ``vehicle_id``, ``s`` (for :func:`classify_extremes`).

    Returns
    -------
    SsmResult
        Run and per-member metrics, the summary per group (``member``, ``other``,
        ``artefact``), the member conflicts without artefacts, the extreme records with their
        ``class``, and why nothing was computed (or None).
    """
    res = SsmResult()
    if ssm is None or not {"begin", "end", "ego", "foe"} <= set(ssm.columns):
        res.unavailable = ("ssm.parquet missing (sumo.ssm off or not a SUMO run)" if ssm is None
                           else "ssm.parquet lacks begin/end/ego/foe")
        return res
    id_set, run, st = set(ids), res.run, settings
    s0 = ssm.assign(ego=ssm["ego"].astype(str), foe=ssm["foe"].astype(str))
    merged = tr.merge_ssm_duplicates(s0)
    run["ssm_n_duplicates_merged"] = int(len(s0) - len(merged))
    during = (_num(merged, "end") >= t_first) & (_num(merged, "begin") <= t_last)
    run["ssm_n_before_start"] = int((~during).sum())
    merged = merged.loc[during].reset_index(drop=True)
    is_m = (merged["ego"].isin(id_set) | merged["foe"].isin(id_set)).to_numpy().copy()
    if "member_involved" in merged.columns:
        is_m |= merged["member_involved"].fillna(False).astype(bool).to_numpy()
    cls = classify_extremes(merged, id_set, events, member_s, t_first + (dt if math.isfinite(dt) else 0.0))
    artefact = np.isin(cls, [c for c in SSM_CLASSES if c != "real"])
    run["ssm_n_extreme"] = int((cls != "").sum())
    for c in SSM_CLASSES:
        run[f"ssm_n_extreme_{c}"] = int((cls == c).sum())
    run["ssm_n_artefact"] = int(artefact.sum())
    groups = np.where(artefact, "artefact", np.where(is_m, "member", "other"))
    res.table = tr.ssm_summary(merged, groups, ttc_warning=st.ssm_ttc_warning_s,
                               ttc_critical=st.ssm_ttc_critical_s, drac_high=st.ssm_drac_high_mps2)
    for g in ("member", "other"):
        for k, u in _SSM_RUN.items():
            name = f"ssm_{k}_{g}{_SUFFIX[u]}"
            if g in res.table.index:
                val = res.table.loc[g, _SSM_COL[k]]
                run[name] = _f(val) if u != "-" else int(val)
            elif u == "-":
                run[name] = 0
    other = merged.loc[~is_m & ~artefact]
    if bg_keys is not None:
        when = pd.Series(_num(other, "min_ttc_time"), index=other.index)
        when = when.fillna(pd.Series(_num(other, "max_drac_time"), index=other.index))
        when = when.fillna(pd.Series(_num(other, "begin"), index=other.index))
        kk = cf.time_keys(when.to_numpy(float), dt)
        run["ssm_n_other_near"] = int(sum((e_, k_) in bg_keys or (f_, k_) in bg_keys
                                          for e_, f_, k_ in zip(other["ego"], other["foe"], kk)))
    res.member_conflicts = merged.loc[is_m & ~artefact].reset_index(drop=True)
    res.extremes = merged.assign(**{"class": cls}).loc[cls != ""].reset_index(drop=True)
    res.members = {m_id: _member_ssm(res.member_conflicts, m_id) for m_id in ids}
    return res


def _member_ssm(c: pd.DataFrame, m_id: str) -> dict[str, Any]:
    """Per-member SSM metrics from the member conflicts ``c``."""
    mine = c.loc[(c["ego"] == m_id) | (c["foe"] == m_id)]
    ttc, drac = _num(mine, "min_ttc"), _num(mine, "max_drac")
    return {"ssm_n_conflicts": int(len(mine)),
            "ssm_ttc_min_s": _f(np.nanmin(ttc)) if np.isfinite(ttc).any() else None,
            "ssm_drac_max_mps2": _f(np.nanmax(drac)) if np.isfinite(drac).any() else None}


def _extremes(x: pd.DataFrame, prefix: str, suffix: str, settings) -> dict[str, Any]:
    def mn(c):
        v = _num(x, c)
        return _f(np.nanmin(v)) if np.isfinite(v).any() else None

    drac = _num(x, "max_drac")
    return {f"{prefix}n{suffix}": int(len(x)), f"{prefix}ttc_min{suffix}_s": mn("min_ttc"),
            f"{prefix}drac_max{suffix}_mps2": _f(np.nanmax(drac)) if np.isfinite(drac).any() else None,
            f"{prefix}pet_min{suffix}_s": mn("pet"),
            f"{prefix}n_ttc_critical{suffix}": int((_num(x, "min_ttc") < settings.ssm_ttc_critical_s).sum())}


def recorded_section(rows: pd.DataFrame, ids: list[str], settings
                     ) -> tuple[dict[str, Any], dict[str, dict[str, Any]], pd.DataFrame]:
    """Conflicts from the recording of one run.

    Parameters
    ----------
    rows : DataFrame
        Members' and recorded background vehicles' rows (body centre ``s``, ``d``, ``v``,
        ``length``, ``width``, ``lane_index``, ``vehicle_id``, ``key``, ``t``).
    ids : list of str
        Member ids.
    settings : AnalysisSettings
        ``ssm_ttc_warning_s``, ``ssm_drac_high_mps2`` (conflict thresholds),
        ``ssm_ttc_critical_s``.

    Returns
    -------
    (dict, dict, DataFrame)
        Run metrics (:data:`CONFLICT_RUN_METRICS`), per-member metrics
        (:data:`CONFLICT_MEMBER_METRICS`) and the conflict table
        (:data:`analysis.metrics.conflicts.CONFLICT_COLUMNS`).
    """
    st = settings
    tab = cf.recorded_conflicts(rows, ids, ttc_threshold=st.ssm_ttc_warning_s,
                                drac_threshold=st.ssm_drac_high_mps2)
    mem = tab.loc[tab["member_involved"]]
    run = {**_extremes(mem, "conflict_", "_member", st),
           **_extremes(tab.loc[~tab["member_involved"]], "conflict_", "_bg", st)}
    per = {}
    for m_id in ids:
        x = mem.loc[(mem["follower"] == m_id) | (mem["leader"] == m_id)]
        e = _extremes(x, "conflict_", "", st)
        per[m_id] = {k: e[k] for k in CONFLICT_MEMBER_METRICS}
    return run, per, tab
