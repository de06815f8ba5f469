"""A road run that no formation entered (its formations depart after the run, its formation
flows inserted none: a penetration study's 0 %): no member row, by design. Its analysis is the
traffic's alone (the section measures, and against a twin the paired comparison at the
sections); every formation metric is marked absent (docs/metrics.md, "Runs without a
formation").
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from analysis.runs.section_measures import SECTION_METRICS, TTC_S, section_measures
from analysis.runs.twin_sections import read_sections, twin_comparison

ABSENT = "no formation entered the road during the run: every formation metric is absent"
"""Why a traffic-only run has no formation metric (metrics.json ``run.formation_metrics``)."""


def no_formation_entered(meta: dict) -> bool:
    """A road run where no formation ever entered the road (run.json ``formations``: none
    entered; or its only formation departs after the run and no formation flow inserted one).

    Parameters
    ----------
    meta : dict
        ``run.json`` content.

    Returns
    -------
    bool
    """
    sc = meta.get("scenario") or {}
    if sc.get("road") is None:
        return False
    forms = meta.get("formations")
    if forms:
        return all(f.get("entered_s") is None for f in forms.values())
    flows = meta.get("formation_flows") or {}
    return (float(sc.get("depart") or 0.0) >= float(meta.get("t_end") or 0.0)
            and not sc.get("formations") and not any(f.get("inserted") for f in flows.values()))


def twin_keys(run_dir: Path, meta: dict, twin_dir: Path) -> dict[str, Any]:
    """The comparison with the twin at the sections (analysis/runs/twin_sections.py
    ``TWIN_METRICS``); {} when either run has no sections or the twin cannot be read."""
    try:
        twin_meta = json.loads((Path(twin_dir) / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    a, b = read_sections(run_dir, meta), read_sections(Path(twin_dir), twin_meta)
    secs = (meta.get("sections") or {}).get("sections")
    if a is None or b is None or not secs:
        return {}
    return twin_comparison(a, b, secs, TTC_S)[0]


def traffic_only_doc(run_dir: Path, meta: dict, twin_dir: Path | None = None) -> dict[str, Any]:
    """metrics.json of a run no formation entered: ``run`` (status, why the formation metrics
    are absent), ``members`` (none), ``traffic.run`` (the section measures; with a twin, its
    comparison too) and ``meta``.

    Parameters
    ----------
    run_dir : Path
        The run's directory.
    meta : dict
        Its ``run.json``.
    twin_dir : Path, optional
        Its twin's directory.

    Returns
    -------
    dict
        The document (JSON-ready but for NaN, which the writer turns into null).
    """
    traffic = dict(section_measures(run_dir, meta))
    if twin_dir is not None:
        traffic.update(twin_keys(run_dir, meta, twin_dir))
    run = {"status": meta.get("status"), "reason": meta.get("reason"), "t_end_s": meta.get("t_end"),
           "formations_entered": 0, "formation_metrics": ABSENT,
           "formation_flows": meta.get("formation_flows")}
    return {"run": run, "members": [], "formations": [], "traffic": {
        "run": traffic, "units": {k: u for k, (u, _) in SECTION_METRICS.items()}},
        "issues": [{"severity": "info", "kind": "no_formation", "what": "trajectories.parquet",
                    "detail": ABSENT}], "damaged": False, "meta": meta}
