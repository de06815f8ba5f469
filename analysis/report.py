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

from analysis.load import Issue
from analysis.summary import MEMBER_METRICS, RUN_METRICS, RunAnalysis

__all__ = ["run_report", "compare_report"]

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


def _img(path: Path, alt: str) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{data}">'


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
               extra_issues: Sequence[Issue] = ()) -> str:
    """Render the report of one run as a self-contained HTML page.

    Parameters
    ----------
    analysis : RunAnalysis
        Output of :func:`analysis.summary.compute_run`.
    figures : mapping of str to Path
        Figure name to PNG file, embedded in order.
    figure_errors : mapping of str to str, optional
        Figures that could not be drawn, with the error.
    extra_issues : sequence of Issue
        Issues found after the computation (e.g. while writing outputs).

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
                 + f" &middot; {n_err} data problem(s)</p>")

    parts.append("<h2>Missing or damaged</h2>" + _issues_html(issues))

    rows = [[k, run.get(k), RUN_METRICS.get(k, "")] for k in RUN_METRICS]
    versions = meta.get("versions")
    if isinstance(versions, dict):
        rows += [[f"version {k}", v, ""] for k, v in versions.items()]
    parts.append("<h2>Run</h2>" + _table(["metric", "value", "unit"], rows, left=1))

    ids = list(a.members.index)
    if ids:
        rows = [[k, MEMBER_METRICS[k], *[a.members.loc[i, k] for i in ids]]
                for k in MEMBER_METRICS]
        parts.append("<h2>Members</h2>" + _table(["metric", "unit", *ids], rows, left=2))
    if a.unavailable:
        rows = [[mid, grp, why] for mid, d in a.unavailable.items() for grp, why in d.items()]
        parts.append("<h2>Metrics not computed or recomputed</h2>"
                     + _table(["member", "metric", "why"], rows, left=3))
    if len(a.string_stability):
        ss = a.string_stability
        parts.append("<h2>String stability (columns of members, front to back)</h2>"
                     "<p>Ratio of the error norm of a member to that of the member in front "
                     "of it; above 1 the error grows down the column.</p>"
                     + _table(list(ss.columns), [list(r) for r in ss.itertuples(index=False)],
                              left=0))
    w = a.run.get("worst") or {}
    if w:
        parts.append("<h2>Worst member per key metric</h2>"
                     + _table(["metric", "worst", "unit"],
                              [[k, v, MEMBER_METRICS.get(k, "")] for k, v in w.items()]))
    s = a.settings
    parts.append(
        "<h2>Settings</h2>" + _table(["setting", "value"], [
            ["settling band [m]", s.settle_tol_m], ["jerk window [s]", s.jerk_window_s],
            ["jerk polynomial order", s.jerk_polyorder],
            ["same-column tolerance on dy [m]", s.column_dy_tol_m],
            ["ISO 2631-1 weighting", "Wd (x = a_lon, y = a_lat), k = 1 (comfort)"],
            ["ISO 2631-1 band", run.get("iso2631_note")]]))
    if figures or figure_errors:
        parts.append("<h2>Figures</h2>")
        for name, p in figures.items():
            parts.append(f"<h3>{_e(name)}</h3>{_img(p, name)}")
        for name, err in (figure_errors or {}).items():
            parts.append(f'<p class="bad">figure {_e(name)} not drawn: {_e(err)}</p>')
    return _page(f"Run {a.data.run_dir.name}", "".join(parts))


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
