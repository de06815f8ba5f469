"""``analyze_sweep``: metrics against swept values, as PNGs, a statistics table and one
self-contained HTML page (``sweep_report.html``, images embedded as base64)."""
from __future__ import annotations

import base64
import html
import json
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from run_contract.errors import SweepError
from run_contract.rundir import atomic_write_text

from .sweep_metrics import METRICS

FINISHED = ("completed", "completed_with_incidents")
"""Statuses of a case whose run reached its end (in the statistics and figures)."""

DEFAULT_METRICS: tuple[str, ...] = ("e_rms_m", "e_max_settled_m", "a_lat_peak_mps2",
                                    "jerk_lat_rms_mps3", "t_lat_above_comfort_s",
                                    "collisions", "min_ttc_s")
"""Plotted when no metric is named (those without any value are left out)."""
REPORT_HTML = "sweep_report.html"
STATS_CSV = "sweep_stats.csv"
FIGURES_DIR = "sweep_figures"
EFFECTS_CSV = "effects.csv"
EFFECTS_FIGURE = "effects"
MAX_TABLE_ROWS = 200


@dataclass(frozen=True)
class SweepReport:
    """What :func:`analyze_sweep` computed and wrote."""

    out_dir: Path
    stats: pd.DataFrame  # one row per combination of swept values: <metric>_{mean,std,min,max,n}
    metrics: list[str]  # plotted metrics
    files: dict[str, Path]  # "report_html", "stats_csv", "figure:<metric>"


def seed_stats(done: pd.DataFrame, swept: list[str], metrics: list[str]) -> pd.DataFrame:
    """Statistics of each metric over the seeds of each combination of swept values.

    Parameters
    ----------
    done : DataFrame
        Completed rows of ``summary.parquet``.
    swept : list of str
        Swept dotted paths (none: one group per seed).
    metrics : list of str
        Metric columns.

    Returns
    -------
    DataFrame
        One row per combination: the swept values, ``n_seeds`` and
        ``<metric>_{mean,std,min,max,n}`` (std with ddof 0).
    """
    by = swept or ["seed"]
    g = done.groupby(by, dropna=False, sort=True)
    parts = {"n_seeds": g["seed"].count()}
    for m in metrics:
        x = g[m]
        parts.update({f"{m}_mean": x.mean(), f"{m}_std": x.std(ddof=0), f"{m}_min": x.min(),
                      f"{m}_max": x.max(), f"{m}_n": x.count()})
    return pd.DataFrame(parts).reset_index()


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def _cell(x) -> str:
    if x is None or (isinstance(x, float) and x != x) or x is pd.NA:
        return "&ndash;"
    return _e(f"{x:.4g}") if isinstance(x, float) else _e(x)


def _table(df: pd.DataFrame) -> str:
    head = "".join(f"<th>{_e(c)}</th>" for c in df.columns)
    body = "".join("<tr>" + "".join(f"<td>{_cell(v)}</td>" for v in r) + "</tr>"
                   for r in df.itertuples(index=False))
    return f"<table><tr>{head}</tr>{body}</table>"


def swept_labels(meta: dict) -> dict[str, str]:
    """Name of every swept field in figures: the sweep file's [labels], else its last name.

    Parameters
    ----------
    meta : dict
        Content of ``sweep.json`` (``swept``, ``sweep.labels``).

    Returns
    -------
    dict
        Swept dotted path -> name.
    """
    given = (meta.get("sweep") or {}).get("labels") or {}
    return {k: given.get(k) or k.split(".")[-1] for k in meta.get("swept", [])}


def _effects_html(eff: pd.DataFrame, fig: Path | None) -> str:
    """The paired effects' section: what is compared, over which vehicles, the table."""
    from analysis.runs.twin_sections import POPULATIONS

    n = int(eff["n_seeds"].max()) if len(eff) else 0
    text = (f"<h2>Paired effects: formation run minus its twin</h2><p>Each case's formation run "
            f"against its twin (same traffic and seed, no formation), paired by seed: the mean over "
            f"the seeds (up to {n}; the note names every case left out), its standard error and the 95 % confidence interval (Student t, "
            f"n - 1 degrees of freedom); <b>distinguishable</b>: the interval excludes 0. One seed "
            f"gives no confidence interval. Populations: delay, speed, spot speeds, lane changes and "
            f"conflicts are over the <i>timed</i> vehicles ({_e(POPULATIONS['timed'])}; the "
            f"<i>stretch</i> population: {_e(POPULATIONS['stretch'])}); throughput over "
            f"{_e(POPULATIONS['downstream'])}.</p>")
    if fig is not None:
        data = base64.b64encode(fig.read_bytes()).decode("ascii")
        text += f'<img alt="effects" src="data:image/png;base64,{data}">'
    return text + _table(eff.head(MAX_TABLE_ROWS))


def _html(meta: dict, df: pd.DataFrame, stats: pd.DataFrame, metrics: list[str],
          figs: dict[str, Path], fig_errors: dict[str, str], notes: list[str],
          effects: pd.DataFrame | None = None) -> str:
    raw = meta.get("sweep", {})
    counts = df["status"].value_counts().to_dict()
    n_cases = len(meta.get("cases", []))
    parts = [f"<h1>Sweep {_e(raw.get('name') or Path(meta.get('sweep_file', '')).stem)}</h1>",
             f"<p>{_e(raw.get('description', ''))}</p>",
             f"<p>Sweep file <code>{_e(meta.get('sweep_file'))}</code>, base scenario "
             f"<code>{_e(meta.get('base'))}</code>. Cases: {n_cases}; "
             + ", ".join(f"{_e(k)}: {v}" for k, v in sorted(counts.items()))
             + f"; pending: {n_cases - len(df)}.</p>",
             "<h2>Swept fields</h2><ul>"
             + "".join(f"<li><b>{_e(swept_labels(meta)[k])}</b>: <code>{_e(k)}</code> "
                       f"({'grid' if k in meta.get('grid_keys', []) else 'random'})</li>"
                       for k in meta.get("swept", []))
             + f"<li>seeds: {_e(raw.get('seeds'))}</li></ul>"]
    bad = df[~df["status"].isin(FINISHED)]
    if len(bad):
        rows = bad[["case_id", "status", "reason"]].copy()
        rows["reason"] = rows["reason"].fillna("").map(lambda r: r.strip().splitlines()[-1][:300] if r.strip() else "")
        parts.append("<h2>Cases without a completed run</h2>" + _table(rows))
    if "twin_status" in df:
        tw = df[df["twin_status"].notna() & ~df["twin_status"].isin(FINISHED)]
        if len(tw):  # their cases' paired effects are NaN: named, never averaged silently
            rows = tw[["case_id", "status", "twin_status", "twin_reason"]].copy()
            rows["twin_reason"] = rows["twin_reason"].fillna("").map(
                lambda r: r.strip().splitlines()[-1][:300] if r.strip() else "")
            parts.append(f'<h2 class="bad">Twins that did not reach their end ({len(tw)})</h2><p>These '
                         "cases have no paired effects (NaN); effects.csv's note names them where a "
                         "grid point is averaged over fewer seeds.</p>" + _table(rows))
    inc = df[df["status"] == "completed_with_incidents"]
    if len(inc):  # completed, in the statistics, and named: a sweep never hides an incident
        cols = [c for c in ("case_id", "member_collisions", "member_removed", "emergency_brakes",
                            "stranded") if c in inc.columns]
        parts.append('<h2 class="bad">Cases completed with incidents</h2>' + _table(inc[cols]))
    parts += [f"<p><em>{_e(n)}</em></p>" for n in notes]
    parts.append("<h2>Figures</h2>")
    for m in metrics:
        if m in figs:
            data = base64.b64encode(figs[m].read_bytes()).decode("ascii")
            parts.append(f'<h3>{_e(m)}</h3><p>{_e(METRICS.get(m, ("", ""))[1])}</p>'
                         f'<img alt="{_e(m)}" src="data:image/png;base64,{data}">')
        elif m in fig_errors:
            parts.append(f"<p>figure {_e(m)} failed: {_e(fig_errors[m])}</p>")
    if effects is not None:
        parts.append(_effects_html(effects, figs.get(EFFECTS_FIGURE)))
    shown = stats.head(MAX_TABLE_ROWS)
    cols = [c for c in shown.columns if not c.endswith(("_n", "_std"))]
    parts.append("<h2>Statistics over seeds (completed runs)</h2>" + _table(shown[cols])
                 + (f"<p>first {MAX_TABLE_ROWS} of {len(stats)} rows; all in {STATS_CSV}</p>"
                    if len(stats) > MAX_TABLE_ROWS else ""))
    css = ("body{font-family:system-ui,sans-serif;max-width:1200px;margin:1.5em auto;padding:0 1em}"
           "table{border-collapse:collapse;font-size:.8em}td,th{border:1px solid #ddd;padding:2px 6px}"
           "th{background:#f3f3f3}img{max-width:100%}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>sweep report</title>"
            f"<style>{css}</style></head><body>{''.join(parts)}</body></html>")


def _effects(meta: dict, df: pd.DataFrame, swept: list[str], out_dir: Path, figs: dict,
             files: dict) -> pd.DataFrame:
    """A sweep with twins: ``effects.csv`` from the summary and its figure (added to
    ``figs`` and ``files``); returns the effects table."""
    from .effects import write_effects

    effects = write_effects(df, swept, out_dir / EFFECTS_CSV)
    files["effects_csv"] = out_dir / EFFECTS_CSV
    if (df["status"] == "completed").any():
        from analysis.figures.sweep_figures import effects_figure

        fig = effects_figure(effects, swept, {k: u for k, (u, _) in METRICS.items()}, swept_labels(meta))
        if fig is not None:
            (out_dir / FIGURES_DIR).mkdir(parents=True, exist_ok=True)
            figs[EFFECTS_FIGURE] = out_dir / FIGURES_DIR / f"{EFFECTS_FIGURE}.png"
            fig.savefig(figs[EFFECTS_FIGURE], dpi=100)
            files[f"figure:{EFFECTS_FIGURE}"] = figs[EFFECTS_FIGURE]
    return effects


REPORT_NAMES = (REPORT_HTML, STATS_CSV, FIGURES_DIR, EFFECTS_CSV)
"""What ``analyze_sweep`` writes into its output directory."""


def check_report_dir(out_dir: Path, sweep_dir: Path, explicit: bool) -> None:
    """SweepError (nothing written) unless ``analyze_sweep`` may write into ``out_dir``: the
    sweep directory itself, or (``--out``) a missing or empty directory or an earlier output of
    ``analyze-sweep`` holding only its names; never a symbolic link, never through one among
    the names it writes, never another run's or sweep's directory.

    Parameters
    ----------
    out_dir : Path
        Where the report would be written.
    sweep_dir : Path
        The sweep analysed.
    explicit : bool
        ``out_dir`` was given (``--out``), not the sweep directory by default.

    Returns
    -------
    None
    """
    from run_contract.rundir import LOCK_NAME, TOOL_TEMP, RunDirError, check_path, looks_like_run, refuse_links

    def refuse(why: str) -> None:
        raise SweepError(out_dir, [("--out", why + ": nothing written; choose another directory")])

    try:
        absolute = check_path(out_dir)
        if absolute.is_dir():
            refuse_links(absolute, REPORT_NAMES)
    except RunDirError as exc:
        raise SweepError(out_dir, [("--out", str(exc))]) from None
    if not explicit or absolute.resolve() == Path(sweep_dir).resolve():
        return
    if Path(out_dir).is_symlink():
        refuse("is a symbolic link; analyze-sweep never writes through one")
    if not absolute.is_dir():
        return
    if looks_like_run(absolute) or (absolute / "sweep.json").exists():
        refuse("is the directory of another run or sweep; its files would be overwritten")
    entries = [p.name for p in absolute.iterdir() if p.name != LOCK_NAME and not TOOL_TEMP.match(p.name)]
    foreign = [e for e in entries if e not in REPORT_NAMES]
    if foreign or (entries and REPORT_HTML not in entries):
        refuse(f"is not empty and not an earlier output of analyze-sweep ({', '.join((foreign or entries)[:5])})")


def analyze_sweep(sweep_dir: str | Path, metrics: list[str] | None = None,
                  out: str | Path | None = None, spread: str = "minmax") -> SweepReport:
    """Plot metrics of a sweep against its swept values and write an HTML summary.

    Parameters
    ----------
    sweep_dir : str or Path
        Directory written by :func:`~formation_traci.sweep.run_sweep` (``sweep.json``,
        ``summary.parquet``).
    metrics : list of str, optional
        Summary columns to plot; default :data:`DEFAULT_METRICS` that have values.
    out : str or Path, optional
        Where to write; default ``sweep_dir``: ``sweep_report.html``, ``sweep_stats.csv``,
        ``sweep_figures/<metric>.png``.
    spread : {"minmax", "std"}
        Error bars over the seeds: min to max, or mean +- 1 standard deviation (ddof 0).

    Returns
    -------
    SweepReport
        The statistics table, the plotted metrics and the written files.

    Raises
    ------
    SweepError
        If ``sweep.json`` or ``summary.parquet`` is missing, a metric is not a numeric
        summary column, or ``spread`` is unknown.
    """
    d = Path(sweep_dir)
    out_dir = Path(out) if out is not None else d
    try:
        meta = json.loads((d / "sweep.json").read_text(encoding="utf-8"))
        df = pd.read_parquet(d / "summary.parquet")
    except (OSError, ValueError) as exc:
        raise SweepError(d, [("(directory)", f"not a sweep directory: {exc}")]) from None
    if spread not in ("minmax", "std"):
        raise SweepError(d, [("spread", f"expected 'minmax' or 'std' (got {spread!r})")])
    swept = list(meta.get("swept", []))
    done = df[df["status"].isin(FINISHED)]
    numeric = [c for c in df.columns if c not in swept and c not in ("case_index", "pid", "seed")
               and pd.api.types.is_numeric_dtype(df[c])]
    notes = []
    if metrics:
        unknown = [m for m in metrics if m not in numeric]
        if unknown:
            raise SweepError(d, [("metrics", f"not a numeric summary column: {unknown}; "
                                             f"choose from {numeric}")])
        chosen = list(dict.fromkeys(metrics))
    else:
        chosen = [m for m in DEFAULT_METRICS if m in done and done[m].notna().any()]
        skipped = [m for m in DEFAULT_METRICS if m not in chosen]
        if skipped:
            notes.append(f"not plotted (no values in completed runs): {', '.join(skipped)}")
    done = done.astype({m: "float64" for m in chosen})
    stats = seed_stats(done, swept, chosen)
    check_report_dir(out_dir, d, explicit=out is not None)
    out_dir.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    figs, fig_errors = {}, {}
    if len(done) and chosen:
        from analysis.figures.sweep_figures import sweep_figures

        labels = swept_labels(meta)
        figs, fig_errors = sweep_figures(done, swept, meta.get("grid_keys", []), chosen,
                                         {k: u for k, (u, _) in METRICS.items()},
                                         out_dir / FIGURES_DIR, spread, labels)
        files.update({f"figure:{k}": p for k, p in figs.items()})
    elif not len(done):
        notes.append("no completed case: nothing to plot")
    atomic_write_text(out_dir / STATS_CSV, stats.to_csv(index=False))
    files["stats_csv"] = out_dir / STATS_CSV
    effects = _effects(meta, df, swept, out_dir, figs, files) if meta.get("baseline") else None
    page = _html(meta, df, stats, chosen, figs, fig_errors, notes, effects)
    atomic_write_text(out_dir / REPORT_HTML, page)
    files["report_html"] = out_dir / REPORT_HTML
    return SweepReport(out_dir=out_dir, stats=stats, metrics=chosen, files=files)
