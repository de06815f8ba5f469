"""A run of several formations (``[[formations]]``, docs/scenarios.md): each formation analysed
as if it had run alone, then joined, with the fleet's aggregates (docs/metrics.md, "Several
formations").

Each formation's :class:`~analysis.load.run_data.RunData` (:func:`analysis.load.run_data.
load_formations`: its rows, its virtual car, its members) goes through
:func:`analysis.runs.summary.compute_run`, so its metrics are those of the formation run alone
(formations share no state: tests/test_formations.py). The joined analysis keeps the first
formation's run-level metrics, shape and figures' data, and holds the members, string-stability
pairs, leader-age bins and string amplification of every formation; its ``fleet`` holds the
formation-level metrics of each formation and their mean and worst over the formations.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import pandas as pd

from analysis.load.run_data import Issue, RunData
from analysis.runs.settings import DEFAULT_SETTINGS, AnalysisSettings
from analysis.runs.summary import KEY_METRICS, RunAnalysis, compute_run
from analysis.runs.traffic_run import BaselineData

__all__ = ["FORMATION_METRICS", "HIGHER_IS_BETTER", "FleetAnalysis", "compute_formations",
           "formation_record", "fleet_aggregate"]

FORMATION_METRICS: dict[str, str] = {
    "n_members": "-", "n_members_with_data": "-",
    "shape_error_rms_m": "m", "shape_error_max_m": "m", "shape_error_final_m": "m",
    "string_stable": "-", "string_peak_ratio_max": "-", "string_rms_ratio_max": "-",
    "string_amplification": "-",
    "energy_kwh_per_100km": "kWh/100km", "energy_alone_kwh_per_100km": "kWh/100km",
    "energy_saving_vs_alone": "-",
}
"""The formation-level metrics of each formation, with their units: the run-level metrics of
:data:`analysis.runs.summary.RUN_METRICS` that belong to one formation, and its string
amplification (metrics.json ``formations``); each formation's record also has ``worst``, the
largest value over its members of every :data:`~analysis.runs.summary.KEY_METRICS`."""

HIGHER_IS_BETTER = frozenset({"string_stable", "energy_saving_vs_alone"})
"""Formation-level metrics whose worst value over the formations is the smallest (for
``string_stable``: False when any formation is not); every other one's worst is the largest."""

_TOTALS = ("n_members", "n_members_with_data")


@dataclass(frozen=True)
class FleetAnalysis:
    """The formations of one run: each one's formation-level metrics and the fleet's."""

    formations: dict[str, dict[str, Any]]  # formation id -> FORMATION_METRICS and "worst"
    fleet: dict[str, Any]  # n_formations, totals, "mean", "worst", "worst_formation"
    meta: dict[str, Any]  # run.json with every formation's members (each view has its own)


def formation_record(a: RunAnalysis) -> dict[str, Any]:
    """The formation-level metrics of one formation's analysis.

    Parameters
    ----------
    a : RunAnalysis
        :func:`~analysis.runs.summary.compute_run` of the formation's data.

    Returns
    -------
    dict
        :data:`FORMATION_METRICS` (None where not computed) and ``worst`` (KEY_METRICS:
        the largest value over the formation's members).
    """
    amp = [f.get("string_amplification") for f in a.formations]
    rec = {k: a.run.get(k) for k in FORMATION_METRICS}
    rec["string_amplification"] = amp[0] if amp else None
    rec["worst"] = dict(a.run.get("worst") or {})
    return rec


def _finite(values: list[Any]) -> list[float]:
    out = []
    for v in values:
        if isinstance(v, bool) or v is None:
            continue
        try:
            f = float(v)
        except (TypeError, ValueError):
            continue
        if math.isfinite(f):
            out.append(f)
    return out


def _mean_worst(key: str, by_id: Mapping[str, Any]) -> tuple[Any, Any, str | None]:
    """Mean, worst and the worst formation's id of one metric over the formations (None when
    no formation has a value; string_stable: the share of stable formations, all stable)."""
    if key == "string_stable":
        flags = {f: v for f, v in by_id.items() if isinstance(v, bool)}
        if not flags:
            return None, None, None
        bad = [f for f, v in flags.items() if not v]
        return sum(flags.values()) / len(flags), not bad, (bad[0] if bad else None)
    vals = {f: x[0] for f, v in by_id.items() if (x := _finite([v]))}
    if not vals:
        return None, None, None
    pick = min if key in HIGHER_IS_BETTER else max
    worst_id = pick(vals, key=vals.get)  # the first formation on a tie
    return sum(vals.values()) / len(vals), vals[worst_id], worst_id


def fleet_aggregate(records: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The fleet's totals and the mean and worst of each formation-level metric.

    Parameters
    ----------
    records : mapping of str to dict
        Formation id to its :func:`formation_record`.

    Returns
    -------
    dict
        ``n_formations``; ``n_members`` and ``n_members_with_data`` summed; ``mean`` and
        ``worst`` (each formation-level metric over the formations, ``worst`` per
        :data:`HIGHER_IS_BETTER`, and a ``worst`` dict over the members' KEY_METRICS: their
        largest value over the fleet); ``worst_formation``: the formation with the worst value.
    """
    mean: dict[str, Any] = {}
    worst: dict[str, Any] = {}
    which: dict[str, Any] = {}
    for k in FORMATION_METRICS:
        if k in _TOTALS:
            continue
        mean[k], worst[k], which[k] = _mean_worst(k, {f: r.get(k) for f, r in records.items()})
    mean["worst"], worst["worst"], which["worst"] = {}, {}, {}
    for k in KEY_METRICS:
        m, w, f = _mean_worst(k, {fid: (r.get("worst") or {}).get(k)
                                  for fid, r in records.items()})
        mean["worst"][k], worst["worst"][k], which["worst"][k] = m, w, f
    totals = {k: int(sum(_finite([r.get(k) for r in records.values()]))) for k in _TOTALS}
    return {"n_formations": len(records), **totals, "mean": mean, "worst": worst,
            "worst_formation": which}


def _concat(frames: list[pd.DataFrame | None], fids: list[str]) -> pd.DataFrame | None:
    """The frames one after the other, each with its ``formation_id`` as first column."""
    have = [(f, d) for f, d in zip(fids, frames) if d is not None]
    if not have:
        return None
    return pd.concat([d.assign(formation_id=f)[["formation_id", *d.columns]]
                      for f, d in have], ignore_index=True)


def _join(analyses: dict[str, RunAnalysis]) -> RunAnalysis:
    """The first formation's analysis with every formation's members, pairs and bins."""
    fids = list(analyses)
    first = analyses[fids[0]]
    members = pd.concat([a.members.assign(formation_id=f)[["formation_id", *a.members.columns]]
                         for f, a in analyses.items()])
    unavailable = {m: why for a in analyses.values() for m, why in a.unavailable.items()}
    issues = list(first.issues) + [Issue(
        "info", "several_formations", "formation_id",
        f"the run has {len(fids)} formations ({', '.join(fids)}): the members, string "
        f"stability pairs and string amplification cover all of them; the run-level metrics "
        f"(run) and the figures are formation '{fids[0]}''s; each formation's formation-level "
        "metrics are in formation_metrics, their mean and worst in fleet")]
    seen = set(first.issues)
    for f in fids[1:]:
        issues += [replace(i, what=f"formation {f}: {i.what}") for i in analyses[f].issues
                   if i not in seen]
    records = {f: formation_record(a) for f, a in analyses.items()}
    by_formation = ((first.data.meta.get("incidents") or {}).get("by_formation")) or {}
    merges = ((first.data.meta.get("merges") or {}).get("by_formation")) or {}
    for f, r in records.items():  # run.json incidents and ramp merges per formation
        r["incidents"] = dict(by_formation.get(f) or {})
        if f in merges:
            r["merges"] = dict(merges[f])
    comm = [a.comm_age for a in analyses.values()]
    return replace(
        first, members=members, unavailable=unavailable, issues=tuple(issues),
        string_stability=_concat([a.string_stability for a in analyses.values()], fids),
        signals=pd.concat([a.signals for a in analyses.values()], ignore_index=True),
        comm_age=_concat(comm, fids) if any(c is not None for c in comm) else None,
        formations=tuple(r for a in analyses.values() for r in a.formations),
        fleet=FleetAnalysis(formations=records, fleet=fleet_aggregate(records), meta=dict(
            first.data.meta, members=[m for a in analyses.values()
                                      for m in a.data.meta.get("members", [])])))


def compute_formations(views: Mapping[str, RunData],
                       settings: AnalysisSettings = DEFAULT_SETTINGS,
                       baseline: BaselineData | None = None) -> RunAnalysis:
    """Every metric of a run of one or several formations.

    Parameters
    ----------
    views : mapping of str to RunData
        :func:`analysis.load.run_data.load_formations` of the run.
    settings : AnalysisSettings
        Analysis choices; default :data:`~analysis.runs.settings.DEFAULT_SETTINGS`.
    baseline : BaselineData, optional
        Twin run without the formation, for the traffic comparison.

    Returns
    -------
    RunAnalysis
        One formation: its :func:`~analysis.runs.summary.compute_run`, unchanged. Several:
        the first formation's, with the members (a ``formation_id`` column first), the
        string-stability pairs and leader-age bins (``formation_id`` first) and the string
        amplification of every formation, the other formations' own issues (named by
        formation) and ``fleet`` (:class:`FleetAnalysis`).
    """
    analyses = {f: compute_run(d, settings, baseline=baseline) for f, d in views.items()}
    if len(analyses) == 1:
        return next(iter(analyses.values()))
    return _join(analyses)
