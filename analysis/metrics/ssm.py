"""SUMO SSM device output and recorded events: merged conflicts, per-group summaries, counts.

Part of the traffic interaction measures (:mod:`analysis.metrics.traffic`); definitions in
``docs/metrics.md``.
"""
from __future__ import annotations

from collections.abc import Collection

import numpy as np
import pandas as pd

__all__ = ["SSM_TTC_WARNING_S", "SSM_TTC_CRITICAL_S", "SSM_DRAC_HIGH_MPS2", "SSM_GROUP_COLUMNS",
           "merge_ssm_duplicates", "ssm_summary", "event_counts"]

SSM_TTC_WARNING_S = 3.0
"""SSM conflicts with a minimum TTC below this are counted [s] (SUMO SSM threshold)."""

SSM_TTC_CRITICAL_S = 1.5
"""SSM conflicts with a minimum TTC below this are critical [s] (a common critical level
in the traffic-conflict literature, e.g. van der Horst 1990)."""

SSM_DRAC_HIGH_MPS2 = 3.0
"""SSM conflicts whose maximum DRAC exceeds this are counted [m/s^2] (SUMO SSM
threshold)."""

SSM_GROUP_COLUMNS: tuple[str, ...] = ("n_conflicts", "ttc_min_s", "drac_max_mps2",
                                      "pet_min_s", "n_ttc_warning", "n_ttc_critical",
                                      "n_drac_high")
"""Columns of :func:`ssm_summary`."""


def merge_ssm_duplicates(ssm: pd.DataFrame) -> pd.DataFrame:
    """One row per conflict: merge the copies SUMO writes for ego and foe.

    Every vehicle carries an SSM device in our runs, so an encounter appears once per
    device, with ego and foe swapped. Rows with the same unordered pair and the same
    ``begin``/``end`` are merged (smallest TTC and PET, largest DRAC).

    Parameters
    ----------
    ssm : DataFrame
        Table with the ``ssm.parquet`` columns (``begin``, ``end``, ``ego``, ``foe``,
        ``min_ttc``, ``max_drac``, ``pet``, ...).

    Returns
    -------
    DataFrame
        Same columns, one row per conflict, ``ego``/``foe`` of the first copy.
    """
    if ssm.empty:
        return ssm.copy()
    df = ssm.copy()
    a, b = df["ego"].astype(str), df["foe"].astype(str)
    df["_p1"], df["_p2"] = np.where(a <= b, a, b), np.where(a <= b, b, a)
    df["_b"], df["_e"] = df["begin"].round(6), df["end"].round(6)
    keys = ["_p1", "_p2", "_b", "_e"]
    agg = {c: "first" for c in df.columns if c not in keys}
    for c, f in (("min_ttc", "min"), ("pet", "min"), ("max_drac", "max")):
        if c in df.columns:
            agg[c] = f
    out = df.groupby(keys, sort=False, dropna=False).agg(agg).reset_index(drop=True)
    return out[[c for c in ssm.columns]]


def ssm_summary(ssm: pd.DataFrame, groups: pd.Series | np.ndarray | None = None, *,
                ttc_warning: float = SSM_TTC_WARNING_S,
                ttc_critical: float = SSM_TTC_CRITICAL_S,
                drac_high: float = SSM_DRAC_HIGH_MPS2) -> pd.DataFrame:
    """Counts and extremes of SSM conflicts per group.

    Parameters
    ----------
    ssm : DataFrame
        Conflicts (one row each, see :func:`merge_ssm_duplicates`) with ``min_ttc`` [s],
        ``max_drac`` [m/s^2], ``pet`` [s].
    groups : array_like of str, optional
        Group label of each row (e.g. ``"member"``/``"other"``); default one group
        ``"all"``.
    ttc_warning : float
        Conflicts with ``min_ttc < ttc_warning`` are counted in ``n_ttc_warning`` [s].
    ttc_critical : float
        Conflicts with ``min_ttc < ttc_critical`` are counted in ``n_ttc_critical`` [s].
    drac_high : float
        Conflicts with ``max_drac > drac_high`` are counted in ``n_drac_high`` [m/s^2].

    Returns
    -------
    DataFrame
        Index: the group labels (sorted); columns :data:`SSM_GROUP_COLUMNS`:
        ``n_conflicts``, ``ttc_min_s``, ``drac_max_mps2``, ``pet_min_s`` (NaN when the
        group has no finite value) and the three counts.

    Examples
    --------
    >>> t = pd.DataFrame({"min_ttc": [2.0, 1.0, np.nan], "max_drac": [1.0, 4.0, 0.5],
    ...                   "pet": [np.nan] * 3})
    >>> ssm_summary(t, ["a", "a", "b"]).loc["a", ["n_conflicts", "n_ttc_critical"]].tolist()
    [2, 1]
    """
    n = len(ssm)
    g = np.asarray(groups, dtype=object) if groups is not None else np.full(n, "all",
                                                                            dtype=object)
    if g.shape != (n,):
        raise ValueError(f"groups must have one label per row ({n}), got shape {g.shape}")
    ttc = pd.to_numeric(ssm.get("min_ttc", pd.Series(np.nan, index=ssm.index)),
                        errors="coerce").to_numpy(float)
    drac = pd.to_numeric(ssm.get("max_drac", pd.Series(np.nan, index=ssm.index)),
                         errors="coerce").to_numpy(float)
    pet = pd.to_numeric(ssm.get("pet", pd.Series(np.nan, index=ssm.index)),
                        errors="coerce").to_numpy(float)
    rows = {}
    for label in sorted(set(g.tolist())):
        m = g == label
        rows[label] = {
            "n_conflicts": int(m.sum()),
            "ttc_min_s": float(np.nanmin(ttc[m])) if np.isfinite(ttc[m]).any() else np.nan,
            "drac_max_mps2": float(np.nanmax(drac[m])) if np.isfinite(drac[m]).any() else np.nan,
            "pet_min_s": float(np.nanmin(pet[m])) if np.isfinite(pet[m]).any() else np.nan,
            "n_ttc_warning": int(np.sum(ttc[m] < ttc_warning)),
            "n_ttc_critical": int(np.sum(ttc[m] < ttc_critical)),
            "n_drac_high": int(np.sum(drac[m] > drac_high)),
        }
    return pd.DataFrame.from_dict(rows, orient="index", columns=list(SSM_GROUP_COLUMNS))


def event_counts(events: pd.DataFrame, ids: Collection[str], kinds: Collection[str],
                 roles: tuple[str, ...] = ("vehicle_id", "other_id")) -> pd.DataFrame:
    """Number of events of each kind that involve each of some vehicles.

    Parameters
    ----------
    events : DataFrame
        Table with the ``events.parquet`` columns (``kind``, ``vehicle_id``,
        ``other_id``).
    ids : collection of str
        Vehicles to count for (e.g. the members).
    kinds : collection of str
        Event kinds to count (e.g. ``"collision"``, ``"cut_in"``).
    roles : tuple of str
        Columns in which a vehicle counts as involved.

    Returns
    -------
    DataFrame
        Index ``ids``, one integer column per kind; an event naming the vehicle in
        several roles counts once.
    """
    ids = [str(i) for i in ids]
    out = pd.DataFrame(0, index=pd.Index(ids, name="id"), columns=list(kinds), dtype=int)
    if events is None or events.empty or "kind" not in events.columns:
        return out
    ev = events.loc[events["kind"].astype(str).isin(list(kinds))]
    for k in kinds:
        e = ev.loc[ev["kind"].astype(str) == k]
        for i in ids:
            hit = np.zeros(len(e), dtype=bool)
            for r in roles:
                if r in e.columns:
                    hit |= (e[r].astype(str) == i).to_numpy()
            out.loc[i, k] = int(hit.sum())
    return out
