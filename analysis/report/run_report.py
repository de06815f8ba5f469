"""Self-contained HTML reports (the only HTML-producing module).

Images are embedded as base64 ``data:`` URIs and the style sheet is inline, so a report
is one file that opens anywhere without network access. Every value coming from the
data is escaped.
"""
from __future__ import annotations

import base64
import html
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from analysis.load.run_data import Issue
from analysis.report.incidents_html import incidents_html
from analysis.runs.summary import FORMATION_MEMBER_METRICS, RUN_METRICS, RunAnalysis
from analysis.runs.traffic_run import TRAFFIC_MEMBER_METRICS, TRAFFIC_RUN_METRICS

__all__ = ["MAX_EMBED_BYTES", "BASELINE_ROWS", "run_report", "compare_report"]

MAX_EMBED_BYTES = 4_000_000
"""Figures larger than this (e.g. a long animation) are linked instead of embedded."""

BASELINE_ROWS = 25
"""Vehicles listed in the report's baseline table (largest delay first); all are in
``baseline.csv`` and ``metrics.json``."""

_MIME = {".png": "image/png", ".gif": "image/gif"}

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:1.5em auto;
max-width:1200px;color:#222;padding:0 1em}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:1.6em}
table{border-collapse:collapse;font-size:0.85em;margin:0.5em 0}
th,td{border:1px solid #ddd;padding:3px 7px;text-align:right}
th{background:#f3f3f3}td.l,th.l{text-align:left}
tr.error td{background:#fde2e2}tr.warning td{background:#fff4d6}tr.info td{background:#eef4fb}
img{max-width:100%;border:1px solid #eee;margin:0.5em 0}
.ok{color:#1a7f37}.bad{color:#b42318}code{background:#f5f5f5;padding:0 3px}
#summary{border:1px solid #ccc;background:#fafafa;padding:0.4em 1em;margin:1em 0}
#summary li{margin:0.2em 0}details{margin:0.4em 0}details>summary{cursor:pointer;
font-weight:600;font-size:1.05em}
"""


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _fmt(x: Any) -> str:
    if x is None:
        return "&ndash;"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float):
        if math.isnan(x):
            return "&ndash;"
        return _e(f"{x:.4g}")
    if isinstance(x, (list, tuple)):
        return ", ".join(_fmt(v) for v in x)
    return _e(x)


def _img(path: Path, alt: str, base: Path | None = None) -> str:
    path = Path(path)
    if path.stat().st_size > MAX_EMBED_BYTES:
        href = path.name
        if base is not None:
            try:
                href = path.resolve().relative_to(base.resolve()).as_posix()
            except ValueError:
                href = path.resolve().as_uri()
        return (f'<p><a href="{_e(href)}">{_e(path.name)}</a> '
                f"({path.stat().st_size / 1e6:.1f} MB, linked, not embedded)</p>")
    mime = _MIME.get(path.suffix.lower(), "image/png")
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:{mime};base64,{data}">'


def _traffic_html(analysis: RunAnalysis) -> str:
    t = analysis.traffic
    if t is None:
        return ""
    run = t.run
    have = [k for k in TRAFFIC_RUN_METRICS if run.get(k) not in (None, {}, [])]
    if not have or have == ["member_footprint"]:
        why = "; ".join(f"{k}: {v}" for k, v in t.unavailable.items())
        return ("<h2>Traffic interaction</h2><p>No traffic data in this run"
                + (f" ({_e(why)})" if why else "") + ".</p>")
    parts = ["<h2>Traffic interaction</h2>",
             "<p>SSM: SUMO's conflicts (duplicates for ego and foe merged, warm-up "
             "conflicts left out). Clearance, lateral gap, 2-D TTC and headways: our "
             "measures from the recorded outlines (docs/metrics.md).</p>"]
    rows = []
    for k, u in TRAFFIC_RUN_METRICS.items():
        v = run.get(k)
        if isinstance(v, dict):
            v = ", ".join(f"lane {a}: {b:.4g}" for a, b in v.items()) if v else None
        rows.append([k, v, u])
    parts.append(_table(["metric", "value", "unit"], rows, left=1))
    ids = list(analysis.members.index)
    if ids:
        rows = [[k, u, *[analysis.members.loc[i, k] for i in ids]]
                for k, u in TRAFFIC_MEMBER_METRICS.items()]
        parts.append("<h3>Per member</h3>" + _table(["metric", "unit", *ids], rows, left=2))
    if len(t.member_conflicts):
        mc = t.member_conflicts
        cols = [c for c in ("begin", "end", "ego", "foe", "min_ttc", "min_ttc_time",
                            "max_drac", "max_drac_time", "pet") if c in mc.columns]
        parts.append("<h3>SSM conflicts involving a member</h3>"
                     + _table(cols, mc[cols].values.tolist(), left=0))
    if t.baseline is not None:
        b = t.baseline.reset_index()
        n = len(b)
        parts.append("<h3>Against the baseline twin (largest delay first, "
                     f"{min(n, BASELINE_ROWS)} of {n} vehicles; all in baseline.csv)</h3>"
                     + _table(list(b.columns), b.head(BASELINE_ROWS).values.tolist(), left=1))
    detail = run.get("twin_detail")
    if detail:
        pops = "".join(f"<li><b>{_e(k)}</b>: {_e(v)}</li>" for k, v in detail["populations"].items())
        why = [[f"not matched: {k}", v] for k, v in detail["unmatched_reasons"].items()]
        why += [[f"not timed: {k}", v] for k, v in detail["untimed_reasons"].items()]
        parts.append("<h3>Against the twin at the measurement sections (twin_* metrics; "
                     "all vehicles in twin.csv)</h3><p>Formation run minus twin, over these "
                     f"populations:</p><ul>{pops}</ul>"
                     + _table(["vehicles left out", "count"], why or [["none", 0]], left=1)
                     + _table(["departures", "count"], list(map(list, detail["departures"].items())), left=1))
    if t.unavailable:
        parts.append("<h3>Traffic metrics not computed</h3>"
                     + _table(["group", "why"], [[k, v] for k, v in t.unavailable.items()],
                              left=2))
    return "".join(parts)


def _energy_html(analysis: RunAnalysis) -> str:
    en = analysis.energy
    if en is None or not len(en.members):
        return ""
    from analysis.runs.energy import ENERGY_RUN_METRICS, energy_rows

    parts = ["<h2>Energy</h2>",
             "<p>Traction energy at the wheels per distance, and the saving against the same "
             "member driving the same speed profile alone (docs/energy.md).</p>",
             _table(["metric", "value", "unit"],
                    [[k, en.run.get(k), u] for k, u in ENERGY_RUN_METRICS.items()], left=1)]
    header, rows = energy_rows(en)
    parts.append("<h3>Per member</h3>" + _table(header, rows, left=2))
    if en.unavailable:
        parts.append(_table(["member", "why"], [[k, v] for k, v in en.unavailable.items()], left=2))
    return "".join(parts)


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]], row_class=None,
           left: int = 1) -> str:
    th = "".join(f'<th class="{"l" if i < left else ""}">{_e(h)}</th>'
                 for i, h in enumerate(header))
    body = []
    for k, r in enumerate(rows):
        cls = f' class="{_e(row_class[k])}"' if row_class else ""
        tds = "".join(f'<td class="{"l" if i < left else ""}">{_fmt(v)}</td>'
                      for i, v in enumerate(r))
        body.append(f"<tr{cls}>{tds}</tr>")
    return f"<table><tr>{th}</tr>{''.join(body)}</table>"


def _issues_html(issues: Sequence[Issue]) -> str:
    if not issues:
        return '<p class="ok">Nothing missing or damaged.</p>'
    order = {"error": 0, "warning": 1, "info": 2}
    iss = sorted(issues, key=lambda i: order.get(i.severity, 3))
    return _table(["severity", "kind", "what", "detail"],
                  [[i.severity, i.kind, i.what, i.detail] for i in iss],
                  row_class=[i.severity for i in iss], left=4)


def _page(title: str, body: str) -> str:
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
            f"<title>{_e(title)}</title><style>{_CSS}</style></head>"
            f"<body>{body}</body></html>")


def run_report(analysis: RunAnalysis, figures: Mapping[str, Path],
               figure_errors: Mapping[str, str] | None = None,
               extra_issues: Sequence[Issue] = (), report_dir: Path | None = None) -> str:
    """Render the report of one run as a self-contained HTML page.

    Parameters
    ----------
    analysis : RunAnalysis
        Output of :func:`analysis.runs.summary.compute_run`.
    figures : mapping of str to Path
        Figure name to PNG or GIF file, embedded in order (linked when large).
    figure_errors : mapping of str to str, optional
        Figures that could not be drawn, with the error.
    extra_issues : sequence of Issue
        Issues found after the computation (e.g. while writing outputs).
    report_dir : Path, optional
        Directory the report is written to; figures too large to embed are linked
        relative to it.

    Returns
    -------
    str
        The HTML document.
    """
    a = analysis
    run, meta = a.run, a.data.meta
    issues = list(a.issues) + list(extra_issues)
    n_err = sum(i.severity == "error" for i in issues)
    parts = [f"<h1>Formation run analysis: {_e(a.data.run_dir.name)}</h1>",
             f"<p><code>{_e(a.data.run_dir)}</code></p>"]
    status = run.get("status")
    cls = "ok" if status == "completed" and n_err == 0 else "bad"
    parts.append(f'<p class="{cls}">status: <b>{_fmt(status)}</b>'
                 + (f" &mdash; reason: {_fmt(run.get('reason'))}" if run.get("reason") else "")
                 + f" &middot; {n_err} data error(s)</p>")

    parts.append(_summary_html(a, issues))
    parts.append(incidents_html(meta, _table))
    parts.append(_formations_html(a))
    if figures or figure_errors:
        parts.append("<h2>Figures</h2>")
        for name, p in figures.items():
            parts.append(f"<h3>{_e(name)}</h3>{_img(p, name, base=report_dir)}")
        for name, err in (figure_errors or {}).items():
            parts.append(f'<p class="bad">figure {_e(name)} not drawn: {_e(err)}</p>')
    parts.append(_tables_html(a, issues, n_err))
    return _page(f"Run {a.data.run_dir.name}", "".join(parts))


def _tables_html(a: RunAnalysis, issues, n_err: int) -> str:
    """The report's tables, each collapsed (<details>), after the figures."""
    run, meta = a.run, a.data.meta
    parts = []
    parts.append("<h2>Tables</h2>")
    parts.append(_details("Missing or damaged data", _issues_html(issues), open_=n_err > 0))
    ids = list(a.members.index)
    if ids:
        rows = [[k, FORMATION_MEMBER_METRICS[k], *[a.members.loc[i, k] for i in ids]]
                for k in FORMATION_MEMBER_METRICS]
        parts.append(_details("Members: every metric", _table(["metric", "unit", *ids], rows, left=2)))
    prop = _propagation_table(a)
    if prop:
        parts.append(_details("Disturbance propagation across the formation", prop))
    if len(a.string_stability):
        ss = a.string_stability
        parts.append(_details(
            "String stability (columns of members, front to back)",
            "<p>Ratio of the error norm of a member to that of the member in front "
            "of it; above 1 the error grows down the column.</p>"
            + _table(list(ss.columns), [list(r) for r in ss.itertuples(index=False)], left=0)))
    w = a.run.get("worst") or {}
    if w:
        parts.append(_details("Worst member per key metric",
                              _table(["metric", "worst", "unit"],
                                     [[k, v, FORMATION_MEMBER_METRICS.get(k, "")]
                                      for k, v in w.items()])))
    traffic_html = _traffic_html(a)
    if traffic_html:
        parts.append(_details("Traffic interaction", traffic_html))
    parts.append(_energy_html(a))  # shown open: energy per member and the formation's saving
    if a.unavailable:
        rows = [[mid, grp, why] for mid, d in a.unavailable.items() for grp, why in d.items()]
        parts.append(_details("Metrics not computed or recomputed",
                              _table(["member", "metric", "why"], rows, left=3)))
    rows = [[k, run.get(k), RUN_METRICS.get(k, "")] for k in RUN_METRICS]
    parts.append(_details("Run", _table(["metric", "value", "unit"], rows, left=1)))
    parts.append(_details("Settings", _settings_table(a)))
    versions = meta.get("versions")
    if isinstance(versions, dict):
        parts.append(_details("Versions", _table(["package", "version"],
                                                 [[k, v] for k, v in versions.items()], left=2)))
    return "".join(parts)


_FORMATION_COLUMNS = ("n_members", "shape_error_rms_m", "shape_error_max_m", "string_stable",
                      "string_amplification", "energy_kwh_per_100km")
_FORMATION_WORST = ("e_rms_m", "e_max_m", "a_lat_peak_mps2", "jerk_lat_peak_mps3", "aw_lat_mps2")


def _formations_html(a: RunAnalysis) -> str:
    """Several formations: one row per formation, the fleet's totals, mean and worst."""
    if a.fleet is None:
        return ""
    f = a.fleet.fleet
    worst = [f"worst {k}" for k in _FORMATION_WORST]

    def row(label, rec, n_members):
        return [label, n_members, *[rec.get(k) for k in _FORMATION_COLUMNS[1:]],
                *[(rec.get("worst") or {}).get(k) for k in _FORMATION_WORST]]

    rows = [row(fid, r, r.get("n_members")) for fid, r in a.fleet.formations.items()]
    rows += [row(f"fleet: mean of {f['n_formations']}", f["mean"], f["n_members"]),
             row("fleet: worst", f["worst"], f["n_members"])]
    return ("<h2>Formations</h2><p>Each formation analysed as if it had run alone; "
            "the fleet's mean and worst over the formations (members: the fleet's total; "
            "worst member metrics: the largest over the formation's members).</p>"
            + _table(["formation", *_FORMATION_COLUMNS, *worst], rows, left=1))


def _details(title: str, body: str, open_: bool = False) -> str:
    """A collapsed section (HTML <details>): tables stay out of the way of the figures."""
    return f"<details{' open' if open_ else ''}><summary>{_e(title)}</summary>{body}</details>"


def _summary_html(a: RunAnalysis, issues) -> str:
    from analysis.report.headline import verdicts

    items = []
    for text, ok in verdicts(a.members, a.run, issues, None if a.fleet is None else a.fleet.fleet):
        mark = {True: '<span class="ok">&#10003;</span> ', False: '<span class="bad">&#10007;</span> ',
                None: ""}[ok]
        items.append(f"<li>{mark}{_e(text)}</li>")
    return f'<div id="summary"><h2>Summary</h2><ul>{"".join(items)}</ul></div>'


def _propagation_table(a: RunAnalysis) -> str:
    from analysis.metrics.propagation import propagation

    off = {m.id: m.offset for m in a.data.members
           if m.id in a.members.index and all(math.isfinite(v) for v in m.offset)}
    col = {k: pd.to_numeric(a.members[k], errors="coerce").to_dict() for k in ("e_max_m", "e_rms_m")}
    df = propagation(off, col["e_max_m"], col["e_rms_m"])
    if not len(df):
        return ""
    return ("<p>Peak and RMS formation error of a member over that of its neighbour on the "
            "side the disturbance comes from: columns front to back, rows outwards from the "
            "member with the largest peak error. Above 1 the disturbance grows.</p>"
            + _table(list(df.columns), df.values.tolist(), left=4))


def _settings_table(a: RunAnalysis) -> str:
    s, run = a.settings, a.run
    return _table(["setting", "value"], [
        ["settling band [m]", s.settle_tol_m], ["jerk window [s]", s.jerk_window_s],
        ["jerk polynomial order", s.jerk_polyorder],
        ["same-column tolerance on dy [m]", s.column_dy_tol_m],
        ["ISO 2631-1 weighting", "Wd (x = a_lon, y = a_lat), k = 1 (comfort)"],
        ["ISO 2631-1 band", run.get("iso2631_note")],
        ["interaction range [m]", s.interaction_range_m],
        ["clearance threshold [m]", s.clearance_threshold_m],
        ["lateral gap threshold [m]", s.lateral_gap_threshold_m],
        ["2-D TTC threshold / horizon [s]", f"{s.ttc2d_threshold_s:g} / {s.ttc2d_horizon_s:g}"],
        ["time headway threshold [s]", s.headway_threshold_s],
        ["SSM TTC warning / critical [s]", f"{s.ssm_ttc_warning_s:g} / {s.ssm_ttc_critical_s:g}"],
        ["SSM DRAC high [m/s^2]", s.ssm_drac_high_mps2],
        ["baseline: shortest common section [m]", s.baseline_min_length_m],
        ["animation: duration [s], fps, start [s]",
         f"{s.anim_duration_s:g}, {s.anim_fps:g}, "
         + ("auto (closest approach)" if s.anim_start_s is None else f"{s.anim_start_s:g}")]])


def compare_report(table: pd.DataFrame, figures: Mapping[str, Path],
                   run_dirs: Mapping[str, Path], issues: Mapping[str, Sequence[Issue]],
                   figure_errors: Mapping[str, str] | None = None) -> str:
    """Render the comparison of several runs as a self-contained HTML page.

    Parameters
    ----------
    table : DataFrame
        Key metrics, one row per metric (index), one column per run label, plus a
        ``unit`` column.
    figures : mapping of str to Path
        Figure name to PNG file, embedded in order.
    run_dirs : mapping of str to Path
        Run label to its directory.
    issues : mapping of str to sequence of Issue
        Run label to the problems found in that run (a run that could not be analysed
        at all appears here only).
    figure_errors : mapping of str to str, optional
        Figures that could not be drawn, with the error.

    Returns
    -------
    str
        The HTML document.
    """
    parts = ["<h1>Formation runs compared</h1>",
             _table(["run", "directory"], [[k, str(v)] for k, v in run_dirs.items()], left=2)]
    labels = [c for c in table.columns if c != "unit"]
    rows = [[idx, table.loc[idx, "unit"], *[table.loc[idx, c] for c in labels]]
            for idx in table.index]
    parts.append("<h2>Key metrics (worst member of each run)</h2>"
                 + _table(["metric", "unit", *labels], rows, left=2))
    for name, p in figures.items():
        parts.append(f"<h2>{_e(name)}</h2>{_img(p, name)}")
    for name, err in (figure_errors or {}).items():
        parts.append(f'<p class="bad">figure {_e(name)} not drawn: {_e(err)}</p>')
    parts.append("<h2>Missing or damaged, per run</h2>")
    for label, iss in issues.items():
        parts.append(f"<h3>{_e(label)}</h3>" + _issues_html(list(iss)))
    return _page("Runs compared", "".join(parts))
