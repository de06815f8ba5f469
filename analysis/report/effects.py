"""Paired effects over seeds: each case's formation run minus its twin (the ``fx_*`` summary
columns), per grid point the mean over the seeds, its standard error and a 95 % confidence
interval (Student t with n - 1 degrees of freedom), and whether that interval excludes zero.
One seed gives the mean and ``no confidence interval``. Written as ``effects.csv``
(docs/sweeps.md, "Twins and paired effects").
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from run_contract.rundir import RUN_FINISHED

from .sweep_metrics import EFFECT_KEYS

EFFECT_COLUMNS = ("metric", "mean", "se", "ci95_lo", "ci95_hi", "n_seeds", "distinguishable", "note")
"""Columns of ``effects.csv`` after the grid axes."""


def t_quantile_975(dof: int) -> float:
    """The 97.5 % quantile of Student's t with ``dof`` degrees of freedom (scipy)."""
    from scipy.stats import t

    return float(t.ppf(0.975, dof))


def paired_effects(summary: pd.DataFrame, axes: list[str], metrics=EFFECT_KEYS,
                   statuses=RUN_FINISHED) -> pd.DataFrame:
    """Per combination of ``axes`` values and per paired metric: mean over the seeds whose
    run reached its end (also with incidents) and has a value, standard error ``s / sqrt(n)``
    (``s`` with ddof 1), the 95 % interval ``mean -+ t(0.975, n - 1) * se``, ``n_seeds``,
    ``distinguishable`` (the interval excludes 0) and a ``note``: ``no confidence interval``
    with one seed, ``no value`` with none, and ``over n of m seeds`` naming each case left
    out and why (its status, its twin's status) whenever a seed of the grid point is missing.

    Parameters
    ----------
    summary : DataFrame
        ``summary.parquet`` of a sweep with twins.
    axes : list of str
        The swept columns (grid and random fields); the seeds are what is averaged over.
    metrics : iterable of str
        The summary columns to average (default: the paired ``fx_*`` effects; a sweep's
        ``means.csv`` gives the section measures, :func:`write_means`).
    statuses : tuple of str
        The case statuses averaged over (``means.csv``: also runs that ended with incidents).

    Returns
    -------
    DataFrame
        Columns: the axes, then :data:`EFFECT_COLUMNS`.
    """
    groups = summary.groupby(axes, sort=True, dropna=False) if axes else [((), summary)]
    rows = []
    for key, g_all in groups:
        key = key if isinstance(key, tuple) else (key,)
        g = g_all[g_all["status"].isin(statuses)]
        for metric in metrics:
            x = pd.to_numeric(g[metric], errors="coerce").to_numpy(float) if metric in g else np.array([])
            ok = np.isfinite(x)
            x = x[ok]
            n = int(x.size)
            row = dict(zip(axes, key), metric=metric, mean=float(x.mean()) if n else math.nan,
                       se=math.nan, ci95_lo=math.nan, ci95_hi=math.nan, n_seeds=n,
                       distinguishable=pd.NA, note="")
            if n >= 2:
                se = float(x.std(ddof=1) / math.sqrt(n))
                half = t_quantile_975(n - 1) * se
                row.update(se=se, ci95_lo=row["mean"] - half, ci95_hi=row["mean"] + half,
                           distinguishable=bool(row["mean"] - half > 0 or row["mean"] + half < 0))
            else:
                row["note"] = "no confidence interval" if n == 1 else "no value"
            if n < len(g_all):
                used = set(g["case_id"][ok]) if metric in g else set()
                row["note"] = "; ".join(p for p in (row["note"], _left_out(g_all, used)) if p)
            rows.append(row)
    out = pd.DataFrame(rows, columns=[*axes, *EFFECT_COLUMNS])
    out["distinguishable"] = out["distinguishable"].astype("boolean")
    return out


def _left_out(cases: pd.DataFrame, used: set) -> str:
    """``over n of m seeds`` and, for each case of ``cases`` not in ``used``, why."""
    out = []
    for _, r in cases[~cases["case_id"].isin(used)].iterrows():
        twin = r.get("twin_status")
        why = (f"twin {twin}" if isinstance(twin, str) and twin not in RUN_FINISHED
               else f"{r['status']}" if r["status"] not in RUN_FINISHED else "no value")
        out.append(f"{r['case_id']} ({why})")
    return f"over {len(used)} of {len(cases)} seeds, without " + ", ".join(out)


def write_effects(summary: pd.DataFrame, axes: list[str], path: Path) -> pd.DataFrame:
    """:func:`paired_effects` written atomically to ``path`` (CSV). Returns the table."""
    eff = paired_effects(summary, axes)
    tmp = path.with_name(f".{path.name}.tmp")
    eff.to_csv(tmp, index=False)
    os.replace(tmp, path)
    return eff


def write_means(summary: pd.DataFrame, axes: list[str], path: Path) -> pd.DataFrame | None:
    """Per grid point, the mean over the seeds of every section measure
    (analysis/runs/section_measures.py SECTION_METRICS) with its 95 % confidence interval, as
    :func:`paired_effects`, written atomically to ``path`` (CSV; ``means.csv`` of a sweep of
    road runs, e.g. a penetration study). None (nothing written) when no case has them."""
    from .sweep_metrics import SECTION_METRICS

    if not any(m in summary and summary[m].notna().any() for m in SECTION_METRICS):
        return None
    table = paired_effects(summary, axes, SECTION_METRICS, ("completed", "completed_with_incidents"))
    tmp = path.with_name(f".{path.name}.tmp")
    table.to_csv(tmp, index=False)
    os.replace(tmp, path)
    return table
