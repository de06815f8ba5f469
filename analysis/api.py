"""Entry points called by the CLI: ``analyze_run`` and ``compare_runs``.

``formation-traci analyze RUN_DIR`` -> :func:`analyze_run`; ``formation-traci compare
RUN_A RUN_B ... --out DIR`` -> :func:`compare_runs`. Both read only recorded files; a
damaged run is analysed as far as possible and its problems are listed in the outputs.
Only a run without any trajectory row raises (:class:`~analysis.load.run_data.NoTrajectoryData`).
"""
from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from analysis.load.run_data import Issue, NoTrajectoryData, load_formations, load_run
from analysis.metrics.platoon import COMPARE_ROWS, compare_value
from analysis.report.metrics_doc import SCHEMA, issues_frame, jsonable, metrics_doc
from analysis.runs.fleet import compute_formations
from analysis.runs.traffic_only import no_formation_entered, traffic_only_doc
from analysis.runs.summary import (DEFAULT_SETTINGS, KEY_METRICS, MEMBER_METRICS, RUN_METRICS,
                                   AnalysisSettings, RunAnalysis, compute_run, settings_dict)
from analysis.runs.traffic_run import TRAFFIC_COMPARE_METRICS, TRAFFIC_RUN_METRICS, load_baseline
from run_contract.rundir import looks_like_run, open_report_dir, require_run_dir
from run_contract.rundir import atomic_write_text

__all__ = [
    "SCHEMA", "METRICS_JSON", "METRICS_CSV", "REPORT_HTML", "BASELINE_CSV", "COMM_AGE_CSV",
    "FIGURES_DIR", "AnalysisResult", "CompareResult", "NoTrajectoryData", "analyze_run",
    "compare_runs",
]

METRICS_JSON = "metrics.json"
METRICS_CSV = "metrics.csv"
REPORT_HTML = "report.html"
BASELINE_CSV = "baseline.csv"
TWIN_CSV = "twin.csv"
COMM_AGE_CSV = "comm_age.csv"
"""Error and comfort per leader-age bin and member (analysis/metrics/comm.py)."""
FIGURES_DIR = "figures"

_COMPARE_RUN_ROWS = ("status", "model", "mu", "duration_s", "sample_rate_hz",
                     "n_members_with_data", "shape_error_rms_m", "shape_error_max_m",
                     "string_stable", "string_peak_ratio_max", *COMPARE_ROWS)


@dataclass(frozen=True)
class AnalysisResult:
    """What :func:`analyze_run` computed and wrote."""

    run_dir: Path
    out_dir: Path  # where the files were written
    run: dict[str, Any]  # run-level metrics (JSON-ready), including "worst"
    members: pd.DataFrame  # one row per member, index "id"
    string_stability: pd.DataFrame  # one row per (leader, follower) pair
    issues: pd.DataFrame  # columns severity, kind, what, detail
    files: dict[str, Path]  # "metrics_json", "metrics_csv", "report_html", "figure:<name>"
    traffic: dict[str, Any] | None = None  # run-level traffic metrics (TRAFFIC_RUN_METRICS)
    baseline: pd.DataFrame | None = None  # per-vehicle comparison with the baseline twin


@dataclass(frozen=True)
class CompareResult:
    """What :func:`compare_runs` computed and wrote."""

    out_dir: Path
    table: pd.DataFrame  # index metric, one column per run label, plus "unit"
    runs: dict[str, Path]  # run label -> run directory (analysed runs only)
    issues: pd.DataFrame  # columns run, severity, kind, what, detail
    files: dict[str, Path]  # "compare_csv", "compare_json", "report_html", "figure:<name>"


def _figure_module():
    from analysis.figures import run_figures as figures  # lazy: matplotlib is heavy
    return figures


def analyze_run(run_dir: str | Path, out_dir: str | Path | None = None, *,
                settings: AnalysisSettings = DEFAULT_SETTINGS,
                figures: bool = True,
                baseline: str | Path | None = None) -> AnalysisResult:
    """Analyse one recorded run and write its metrics, figures and report.

    Parameters
    ----------
    run_dir : str or Path
        Run directory (``run.json``, ``trajectories.parquet``, ...).
    out_dir : str or Path, optional
        Where to write; default ``run_dir``. Receives ``metrics.json``, ``metrics.csv``,
        ``figures/*.png`` and ``report.html``.
    settings : AnalysisSettings
        Analysis choices (settling band, jerk window, ...).
    figures : bool
        Draw the figures (PNG; for road runs also the traffic space-time diagram and the
        bird's-eye animation) and embed them in the report.
    baseline : str or Path, optional
        Directory of the twin run with the same traffic and seed but no formation
        (``formation-traci run SCENARIO --out DIR --baseline``). Adds the per-vehicle
        travel-time comparison (``traffic.baseline_vehicles`` in ``metrics.json``,
        ``baseline.csv``) and the ``baseline_*`` traffic metrics. A missing or damaged
        baseline is listed in the issues; the rest is still computed.

    Returns
    -------
    AnalysisResult
        The run-level metrics, per-member and string-stability tables, the issues, the
        written files, the run-level traffic metrics and the baseline comparison.

    Raises
    ------
    NoTrajectoryData
        If the run has no readable trajectory row at all.
    """
    run_dir = require_run_dir(Path(run_dir))
    out = Path(out_dir) if out_dir is not None else run_dir
    if not looks_like_run(run_dir):  # nothing to analyse: nothing created there either
        raise NoTrajectoryData(f"{run_dir}: not a run directory (no run.json and no "
                               "trajectories.parquet): nothing written")
    with open_report_dir(out, METRICS_JSON, own_run=run_dir):  # one writer at a time
        return _analyze_into(run_dir, out, settings, figures, baseline)


def _analyze_into(run_dir: Path, out: Path, settings: AnalysisSettings, figures: bool,
                  baseline: str | Path | None) -> AnalysisResult:
    base = load_baseline(baseline) if baseline is not None else None
    try:
        a = compute_formations(load_formations(run_dir), settings, baseline=base)
    except NoTrajectoryData:
        meta = _run_json(run_dir)
        if not no_formation_entered(meta):
            raise
        return _traffic_only_into(run_dir, out, meta, baseline)
    files: dict[str, Path] = {}
    fig_paths: dict[str, Path] = {}
    fig_errors: dict[str, str] = {}
    extra: list[Issue] = []
    if figures:
        fig_paths, fig_errors = _figure_module().run_figures(a, out / FIGURES_DIR)
        extra += [Issue("warning", "figure_failed", name, err) for name, err in fig_errors.items()]
        files.update({f"figure:{k}": p for k, p in fig_paths.items()})
    issues = list(a.issues) + extra

    doc = metrics_doc(a, run_dir, issues, fig_paths, out)
    p_json = out / METRICS_JSON
    atomic_write_text(p_json, json.dumps(jsonable(doc), indent=2, allow_nan=False))
    files["metrics_json"] = p_json
    p_csv = out / METRICS_CSV
    atomic_write_text(p_csv, a.members.reset_index().to_csv(index=False))
    files["metrics_csv"] = p_csv
    if a.comm_age is not None and len(a.comm_age):
        p_comm = out / COMM_AGE_CSV
        atomic_write_text(p_comm, a.comm_age.to_csv(index=False))
        files["comm_age_csv"] = p_comm
    else:
        (out / COMM_AGE_CSV).unlink(missing_ok=True)
    twin_tab = a.traffic.twin if a.traffic is not None else None
    p_twin = out / TWIN_CSV
    if twin_tab is not None:
        twin_tab.to_csv(p_twin, index=False)
        files["twin_csv"] = p_twin
    else:
        p_twin.unlink(missing_ok=True)
    base_tab = a.traffic.baseline if a.traffic is not None else None
    p_base = out / BASELINE_CSV
    if base_tab is not None:
        atomic_write_text(p_base, base_tab.reset_index().to_csv(index=False))
        files["baseline_csv"] = p_base
    else:
        p_base.unlink(missing_ok=True)

    from analysis.report import run_report as report  # lazy, like figures

    p_html = out / REPORT_HTML
    atomic_write_text(p_html, report.run_report(a, fig_paths, fig_errors, extra, report_dir=out))
    files["report_html"] = p_html
    return AnalysisResult(run_dir=run_dir, out_dir=out, run=jsonable(a.run), members=a.members,
                          string_stability=a.string_stability, issues=issues_frame(issues),
                          files=files,
                          traffic=jsonable(a.traffic.run) if a.traffic is not None else None,
                          baseline=base_tab)


def _run_json(run_dir: Path) -> dict:
    try:
        return json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def _traffic_only_into(run_dir: Path, out: Path, meta: dict,
                       baseline: str | Path | None) -> AnalysisResult:
    """A road run no formation entered: the traffic's metrics, the formation's marked absent
    (analysis/runs/traffic_only.py)."""
    from analysis.report.traffic_only_report import traffic_only_report

    doc = jsonable(traffic_only_doc(run_dir, meta, None if baseline is None else Path(baseline)))
    files = {"metrics_json": out / METRICS_JSON, "metrics_csv": out / METRICS_CSV,
             "report_html": out / REPORT_HTML}
    atomic_write_text(files["metrics_json"], json.dumps(doc, indent=2, allow_nan=False))
    atomic_write_text(files["metrics_csv"], "id\n")
    for stale in (COMM_AGE_CSV, TWIN_CSV, BASELINE_CSV):
        (out / stale).unlink(missing_ok=True)
    atomic_write_text(files["report_html"], traffic_only_report(run_dir.name, doc))
    issues = [Issue(i["severity"], i["kind"], i["what"], i["detail"]) for i in doc["issues"]]
    return AnalysisResult(run_dir=run_dir, out_dir=out, run=doc["run"],
                          members=pd.DataFrame(index=pd.Index([], name="id")),
                          string_stability=pd.DataFrame(), issues=issues_frame(issues), files=files,
                          traffic=doc["traffic"]["run"])


def _labels(run_dirs: Sequence[Path]) -> list[str]:
    names = [p.name or str(p) for p in run_dirs]
    labels = [f"{p.parent.name}/{n}" if names.count(n) > 1 else n
              for p, n in zip(run_dirs, names)]
    seen: dict[str, int] = {}
    for k, lab in enumerate(labels):
        if lab in seen:
            seen[lab] += 1
            labels[k] = f"{lab}#{seen[lab]}"
        else:
            seen[lab] = 1
    return labels


def compare_runs(run_dirs: Sequence[str | Path], out_dir: str | Path, *,
                 settings: AnalysisSettings = DEFAULT_SETTINGS,
                 baselines: Sequence[str | Path | None] | None = None) -> CompareResult:
    """Compare several runs side by side (e.g. kinematic vs dynamic model).

    Parameters
    ----------
    run_dirs : sequence of str or Path
        Run directories; each is labelled by its directory name (parent added when
        names repeat).
    out_dir : str or Path
        Output directory (created): ``compare.csv``, ``compare.json``,
        ``figures/compare_*.png`` and ``report.html``. The run directories are not
        written to.
    settings : AnalysisSettings
        Analysis choices, the same for every run.
    baselines : sequence of (str, Path or None), optional
        Baseline twin of each run (same order as ``run_dirs``, None where there is
        none) for the ``traffic baseline_*`` rows.

    Returns
    -------
    CompareResult
        Key metrics side by side (worst member of each run, then the traffic metrics),
        the issues of every run and the written files. A run without trajectory data is
        listed in the issues and left out of the table.

    Raises
    ------
    NoTrajectoryData
        If none of the runs has trajectory data.
    ValueError
        If ``run_dirs`` is empty, or ``baselines`` does not have one entry per run.
    """
    dirs = [Path(p) for p in run_dirs]
    if not dirs:
        raise ValueError("run_dirs is empty: give at least one run directory")
    bases = list(baselines) if baselines is not None else [None] * len(dirs)
    if len(bases) != len(dirs):
        raise ValueError(f"baselines has {len(bases)} entries, run_dirs {len(dirs)}: give "
                         "one per run (None where there is none)")
    for d in dirs:
        require_run_dir(d)
    with open_report_dir(Path(out_dir), "compare.json"):  # never into a run: its report stays
        return _compare_into(dirs, bases, Path(out_dir), settings)


def _compare_into(dirs: list[Path], bases: list, out: Path, settings: AnalysisSettings) -> CompareResult:
    analyses: dict[str, RunAnalysis] = {}
    issues: dict[str, list[Issue]] = {}
    runs: dict[str, Path] = {}
    for label, d, b in zip(_labels(dirs), dirs, bases):
        try:
            a = compute_run(load_run(d), settings,
                            baseline=load_baseline(b) if b is not None else None)
        except NoTrajectoryData as exc:
            issues[label] = [Issue("error", "no_trajectory_data", str(d), str(exc))]
            continue
        analyses[label], issues[label], runs[label] = a, list(a.issues), d
    if not analyses:
        raise NoTrajectoryData("none of the runs has trajectory data: "
                               + "; ".join(i.detail for v in issues.values() for i in v))

    units = {**RUN_METRICS, **MEMBER_METRICS, **dict.fromkeys(COMPARE_ROWS, "-")}
    index = (list(_COMPARE_RUN_ROWS) + [f"worst {k}" for k in KEY_METRICS]
             + [f"traffic {k}" for k in TRAFFIC_COMPARE_METRICS] + ["data problems"])
    table = pd.DataFrame(index=index, columns=["unit", *analyses], dtype=object)
    table.index.name = "metric"
    for k in _COMPARE_RUN_ROWS:
        table.loc[k, "unit"] = units.get(k, "")
    for k in KEY_METRICS:
        table.loc[f"worst {k}", "unit"] = units.get(k, "")
    for k in TRAFFIC_COMPARE_METRICS:
        table.loc[f"traffic {k}", "unit"] = TRAFFIC_RUN_METRICS[k]
    table.loc["data problems", "unit"] = "-"
    for label, a in analyses.items():
        for k in _COMPARE_RUN_ROWS:
            table.loc[k, label] = jsonable(compare_value(a, k))
        for k in KEY_METRICS:
            table.loc[f"worst {k}", label] = a.run["worst"].get(k)
        for k in TRAFFIC_COMPARE_METRICS:
            table.loc[f"traffic {k}", label] = jsonable(
                a.traffic.run.get(k) if a.traffic is not None else None)
        table.loc["data problems", label] = sum(i.severity == "error" for i in issues[label])

    files: dict[str, Path] = {}
    fig_paths, fig_errors = _figure_module().compare_figures(analyses, out / FIGURES_DIR)
    files.update({f"figure:{k}": p for k, p in fig_paths.items()})
    p_csv = out / "compare.csv"
    atomic_write_text(p_csv, table.to_csv())
    files["compare_csv"] = p_csv
    p_json = out / "compare.json"
    doc = {"schema": SCHEMA, "runs": {k: str(v) for k, v in runs.items()},
           "metrics": {idx: {"unit": table.loc[idx, "unit"],
                             **{lab: table.loc[idx, lab] for lab in analyses}}
                       for idx in table.index},
           "issues": {lab: [i.as_dict() for i in iss] for lab, iss in issues.items()},
           "settings": settings_dict(settings),
           "figures": {k: str(p.relative_to(out)) for k, p in fig_paths.items()}}
    atomic_write_text(p_json, json.dumps(jsonable(doc), indent=2, allow_nan=False))
    files["compare_json"] = p_json

    from analysis.report import run_report as report

    p_html = out / REPORT_HTML
    atomic_write_text(p_html, report.compare_report(table, fig_paths, {**runs, **{
        lab: Path(iss[0].what) for lab, iss in issues.items() if lab not in runs}},
        issues, fig_errors))
    files["report_html"] = p_html
    all_issues = pd.concat([issues_frame(v, run=k) for k, v in issues.items()], ignore_index=True)
    return CompareResult(out_dir=out, table=table, runs=runs, issues=all_issues, files=files)
