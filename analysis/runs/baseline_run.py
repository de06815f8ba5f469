"""The baseline twin (``run --baseline``: the same traffic without the formation): reading it
and comparing its background vehicles' travel times and speeds with this run's.

Part of the per-run traffic computation (:mod:`analysis.runs.traffic_run`). Definitions:
``docs/metrics.md``, section "Traffic interaction".
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.load.run_data import Issue, RunData, read_meta, read_table
from analysis.metrics import traffic as tr
from analysis.runs.near_formation import finite_mean, near_rows
from analysis.runs.settings import AnalysisSettings
from run_contract.columns import VIRTUAL_CAR_ID

__all__ = ["BaselineData", "load_baseline"]


@dataclass(frozen=True)
class BaselineData:
    """What is read from a baseline twin run (``run --baseline``)."""

    run_dir: Path
    meta: dict[str, Any]
    background: pd.DataFrame | None
    issues: tuple[Issue, ...] = field(default_factory=tuple)


def load_baseline(run_dir: str | Path) -> BaselineData:
    """Read the parts of a baseline twin run the comparison needs.

    Parameters
    ----------
    run_dir : str or Path
        Directory of the twin run (``run.json`` with ``"baseline": true``,
        ``background.parquet`` with every vehicle).

    Returns
    -------
    BaselineData
        Its metadata and background table (None when missing) and the problems met,
        named ``baseline:...``.
    """
    d = Path(run_dir)
    issues: list[Issue] = []
    if not d.is_dir():
        return BaselineData(d, {}, None, (Issue("error", "missing_baseline", str(d),
                                                "baseline run directory does not exist"),))
    meta, m_issues = read_meta(d)
    issues += [Issue(i.severity, i.kind, f"baseline:{i.what}", i.detail) for i in m_issues
               if i.kind in ("missing_file", "invalid_file", "run_status")]
    bg, b_issues = read_table(d / "background.parquet", "background.parquet")
    for i in b_issues:
        sev = "error" if i.kind == "missing_table" else i.severity
        issues.append(Issue(sev, i.kind, f"baseline:{i.what}", i.detail))
    if meta and meta.get("baseline") is not True:
        issues.append(Issue("warning", "baseline_mismatch", "baseline:run.json",
                            "run.json does not say \"baseline\": true; compared anyway"))
    return BaselineData(d, meta, bg, tuple(issues))


def _mismatch(bm: dict[str, Any], meta: dict[str, Any]) -> list[Issue]:
    """Warnings where the twin's seed or scenario name differ from this run's."""
    out: list[Issue] = []
    for key in ("seed",):
        if bm and meta and bm.get(key) != meta.get(key):
            out.append(Issue("warning", "baseline_mismatch", f"baseline:{key}",
                             f"{key} {bm.get(key)!r} differs from this run's "
                             f"{meta.get(key)!r}: vehicles are not the same"))
    name_b = (bm.get("scenario") or {}).get("name") if isinstance(bm.get("scenario"),
                                                                  dict) else None
    name_r = (meta.get("scenario") or {}).get("name") if isinstance(
        meta.get("scenario"), dict) else None
    if name_b and name_r and name_b != name_r:
        out.append(Issue("warning", "baseline_mismatch", "baseline:scenario",
                         f"scenario {name_b!r} differs from this run's {name_r!r}"))
    return out


def baseline_section(baseline: BaselineData, data: RunData, M: pd.DataFrame, bg_ok: bool,
                     road: bool, win: pd.DataFrame, st: AnalysisSettings, run: dict[str, Any],
                     issues: list[Issue], unavailable: dict[str, str]) -> pd.DataFrame | None:
    """Compare this run with its twin: fills the ``baseline_*`` entries of ``run``, appends to
    ``issues`` and ``unavailable``; returns the per-vehicle comparison (None when not made)."""
    meta, traj, dt = data.meta, data.trajectories, data.dt
    bg = data.tables.get("background")
    id_set = {m.id for m in data.members}
    base_tab = None
    issues += list(baseline.issues)
    run["baseline_run_dir"] = str(baseline.run_dir)
    bm = baseline.meta
    issues += _mismatch(bm, meta)
    bb = baseline.background
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, "s"].to_numpy(float)
    vc = vc[np.isfinite(vc)]
    if vc.size < 2:
        ms = M["s"].to_numpy(float) if len(M) else np.array([])
        vc = ms[np.isfinite(ms)]
    if bb is None or not {"t", "vehicle_id", "s"} <= set(bb.columns):
        unavailable["baseline"] = "the baseline run has no usable background.parquet"
    elif not bg_ok or "s" not in bg.columns:
        unavailable["baseline"] = "this run has no usable background.parquet"
    elif vc.size < 2 or not vc.max() > vc.min():
        unavailable["baseline"] = "the formation's road section is unknown (no s)"
    else:
        s_a, s_b = float(vc.min()), float(vc.max())
        run["baseline_section_m"] = [s_a, s_b]
        b_run = bg.loc[~bg["vehicle_id"].astype(str).isin(id_set)]
        run["baseline_n_common"] = len(set(b_run["vehicle_id"].astype(str))
                                       & set(bb["vehicle_id"].astype(str)))
        base_tab = tr.baseline_comparison(b_run, bb, s_a, s_b,
                                          st.baseline_min_length_m)
        ok = base_tab.dropna(subset=["tt_run_s", "tt_base_s"])
        run["baseline_n_compared"] = int(len(ok))
        run["baseline_n_full_section"] = int(ok["full_section"].sum())
        if len(ok):
            run["baseline_tt_run_mean_s"] = float(ok["tt_run_s"].mean())
            run["baseline_tt_base_mean_s"] = float(ok["tt_base_s"].mean())
            run["baseline_delta_mean_s"] = float(ok["delta_s"].mean())
            run["baseline_delta_max_s"] = float(ok["delta_s"].max())
            run["baseline_delta_total_s"] = float(ok["delta_s"].sum())
            run["baseline_v_run_mps"] = float(ok["length_m"].sum() / ok["tt_run_s"].sum())
            run["baseline_v_base_mps"] = float(ok["length_m"].sum()
                                               / ok["tt_base_s"].sum())
        else:
            issues.append(Issue("warning", "baseline_empty", "baseline",
                                "no vehicle was recorded over at least "
                                f"{st.baseline_min_length_m:g} m of the section in both "
                                "runs"))
        if road and "s" in bb.columns:
            nb = near_rows(bb, win, dt)
            run["baseline_bg_speed_mean_near_mps"] = finite_mean(nb["v"]) if len(nb) else None
            if run["baseline_bg_speed_mean_near_mps"] is not None and \
                    run["bg_speed_mean_near_mps"] is not None:
                run["baseline_bg_speed_delta_near_mps"] = (
                    run["bg_speed_mean_near_mps"] - run["baseline_bg_speed_mean_near_mps"])
    return base_tab


def twin_section(baseline: BaselineData, data: RunData, st: AnalysisSettings, run: dict[str, Any],
                 issues: list[Issue], unavailable: dict[str, str]) -> pd.DataFrame | None:
    """The comparison at the measurement sections (analysis/runs/twin_sections.py): fills the
    twin keys of ``run`` (``stretch_coverage``, ``matched_share``, ``twin_*``) and
    ``run["twin_detail"]`` (reasons, departures, sections, populations); returns the
    per-vehicle table, None when either run has no sections."""
    from analysis.runs.twin_sections import POPULATIONS, read_sections, twin_comparison

    a = read_sections(data.run_dir, data.meta)
    b = read_sections(baseline.run_dir, baseline.meta)
    secs = (data.meta.get("sections") or {}).get("sections")
    if a is None or b is None or not secs:
        unavailable["twin_sections"] = ("no measurement sections in "
                                        + ("this run" if a is None or not secs else "the twin")
                                        + " (traffic.sections off, or a run of an older version)")
        return None
    if secs != (baseline.meta.get("sections") or {}).get("sections"):
        issues.append(Issue("warning", "baseline_mismatch", "baseline:sections",
                            "the twin's sections are not this run's: compared by section index"))
    m, veh, detail = twin_comparison(a, b, secs, st.ssm_ttc_warning_s)
    run.update(m)
    run["twin_detail"] = {**detail, "populations": POPULATIONS}
    if m["stretch_coverage"] is not None and m["stretch_coverage"] < 0.9:
        issues.append(Issue("warning", "stretch_coverage", "sections",
                            f"only {100 * m['stretch_coverage']:.0f} % of the vehicles entering the "
                            "stretch are timed over it in both runs: the effects are over a partial "
                            "population"))
    return veh
