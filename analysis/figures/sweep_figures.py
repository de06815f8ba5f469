"""Sweep figures: one PNG per metric, one panel per swept field (matplotlib, imported lazily).

A metric whose positive values span more than LOG_SPAN is drawn on a logarithmic axis.

Each point is the mean over the seeds of one combination of swept values; the error bar
spans the spread (min-max or +-1 std) over those seeds. With other swept fields, one line
per combination of them (up to :data:`MAX_LINES`; beyond that the others are pooled).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.figures.figure_kit import save_png

MAX_LINES = 8
"""More combinations of the other swept fields than this are pooled into one line."""
LOG_SPAN = 100.0
"""A metric whose positive values span more than this factor is drawn on a log axis."""


def _agg(df: pd.DataFrame, by: list[str], metric: str, spread: str) -> pd.DataFrame:
    g = df.groupby(by, dropna=False, sort=True)[metric]
    s = pd.DataFrame({"mean": g.mean(), "lo": g.min(), "hi": g.max(), "std": g.std(ddof=0)})
    if spread == "std":
        s["lo"], s["hi"] = s["mean"] - s["std"], s["mean"] + s["std"]
    return s.reset_index()


def _xpos(values: pd.Series) -> tuple[np.ndarray, list | None]:
    if pd.api.types.is_numeric_dtype(values) and not pd.api.types.is_bool_dtype(values):
        return values.to_numpy(dtype=float), None
    cats = sorted(values.astype(str).unique())
    return np.array([cats.index(v) for v in values.astype(str)], dtype=float), cats


def _panel(ax, df: pd.DataFrame, param: str, others: list[str], metric: str, spread: str,
           connect: bool, labels: dict[str, str]) -> None:
    groups: list = [(None, df)]
    if others:
        split = list(df.groupby(others, dropna=False, sort=True))
        if len(split) > MAX_LINES:
            groups = [("other fields pooled", df)]
        else:
            groups = [(", ".join(f"{labels.get(k, k)}={v}" for k, v in zip(others, key)), sub)
                      for key, sub in split]
    cats_all = None
    for label, sub in groups:
        s = _agg(sub, [param], metric, spread).dropna(subset=["mean"])
        if s.empty:
            continue
        x, cats = _xpos(s[param])
        cats_all = cats or cats_all
        order = np.argsort(x)
        x, m = x[order], s["mean"].to_numpy()[order]
        yerr = np.vstack([m - s["lo"].to_numpy()[order], s["hi"].to_numpy()[order] - m])
        ax.errorbar(x, m, yerr=np.nan_to_num(np.clip(yerr, 0, None)), marker="o", ms=4,
                    capsize=3, linestyle="-" if connect else "none", label=label)
    if cats_all:
        ax.set_xticks(range(len(cats_all)))
        ax.set_xticklabels([c[:14] for c in cats_all], rotation=30, ha="right")
    ax.set_xlabel(labels.get(param, param))
    ax.grid(True, alpha=0.3)
    if len(groups) > 1 or groups[0][0]:
        ax.legend(fontsize=7)


def sweep_figures(done: pd.DataFrame, swept: list[str], grid_keys: list[str], metrics: list[str],
                  units: dict[str, str], out_dir: Path, spread: str = "minmax",
                  labels: dict[str, str] | None = None) -> tuple[dict[str, Path], dict[str, str]]:
    """Draw one PNG per metric against every swept field.

    Parameters
    ----------
    done : DataFrame
        Completed rows of ``summary.parquet``.
    swept : list of str
        Swept dotted paths (panels); none: the metric against the seed.
    grid_keys : list of str
        Swept paths from [grid] (points joined by lines); the others are random samples.
    metrics : list of str
        Columns to plot.
    units : dict
        Metric -> unit, for the axis labels.
    out_dir : Path
        Directory for ``<metric>.png`` (created).
    spread : {"minmax", "std"}
        Error bars over the seeds.
    labels : dict, optional
        Swept path -> short name for legends.

    Returns
    -------
    (dict, dict)
        Metric -> written PNG, and metric -> error message for figures that failed.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    paths, errors = {}, {}
    for metric in metrics:
        try:
            fig = metric_figure(done, swept, grid_keys, metric, units.get(metric, ""), spread, labels)
            path = out_dir / f"{metric}.png"
            save_png(fig, path, dpi=100)
            paths[metric] = path
        except Exception as exc:  # one bad figure must not lose the others
            errors[metric] = f"{type(exc).__name__}: {exc}"
    return paths, errors


def metric_figure(done: pd.DataFrame, swept: list[str], grid_keys: list[str], metric: str,
                  unit: str, spread: str = "minmax", labels: dict[str, str] | None = None):
    """The matplotlib Figure of one metric (one panel per swept field), not saved.

    Parameters
    ----------
    done : the finished cases' rows of summary.parquet
    swept : the swept fields (one panel each; none: one panel over the seeds)
    grid_keys : the swept fields that form a grid (drawn as lines)
    metric : the column to plot
    unit : its unit (axis label)
    spread : "minmax" or "std" bars over seeds
    labels : field -> axis label (the study's [labels])

    Returns
    -------
    matplotlib.figure.Figure, not saved
    """
    from matplotlib.figure import Figure  # lazy: heavy, and only the figures need it

    params = swept or ["seed"]
    fig = Figure(figsize=(4.2 * len(params), 3.4), layout="constrained")
    axes = fig.subplots(1, len(params), squeeze=False)[0]
    for ax, p in zip(axes, params):
        others = [k for k in swept if k != p]
        _panel(ax, done, p, others, metric, spread, p in grid_keys or p == "seed", labels or {})
    vals = pd.to_numeric(done[metric], errors="coerce").to_numpy(dtype=float)
    vals = vals[np.isfinite(vals)]
    if vals.size and vals.min() > 0 and vals.max() > LOG_SPAN * vals.min():
        for ax in axes:
            ax.set_yscale("log")
    axes[0].set_ylabel(f"{metric} [{unit}]" if unit and unit != "-" else metric)
    fig.suptitle(f"{metric}: mean over seeds, bars {'min-max' if spread == 'minmax' else '±1 std'}",
                 fontsize=10)
    return fig


EFFECT_PANELS: tuple[str, ...] = ("fx_delay_mean_s", "fx_speed_mps", "fx_spot_speed_mps",
                                  "fx_throughput_veh_h")
"""The paired effects drawn by :func:`effects_figure` (those with values)."""


def effects_figure(eff: pd.DataFrame, swept: list[str], units: dict[str, str],
                   labels: dict[str, str] | None = None):
    """Paired effects (formation run minus its twin) against the first swept field: the mean
    over the seeds with its 95 % confidence interval as the bar (one seed: the point alone),
    the zero line drawn; one panel per effect of :data:`EFFECT_PANELS` with a value.

    Parameters
    ----------
    eff : effects.csv as a DataFrame (analysis/report/effects.py)
    swept : the swept fields (the first is the x axis; the others one line each)
    units : effect -> unit
    labels : field -> axis label

    Returns
    -------
    matplotlib.figure.Figure or None (no effect with a value), not saved
    """
    from matplotlib.figure import Figure

    panels = [m for m in EFFECT_PANELS if eff.loc[eff["metric"] == m, "mean"].notna().any()]
    if not panels:
        return None
    labels = labels or {}
    x_key = swept[0] if swept else None
    others = swept[1:]
    fig = Figure(figsize=(3.6 * len(panels), 3.2), layout="constrained")
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, m in zip(axes, panels):
        e = eff[eff["metric"] == m]
        groups = list(e.groupby(others, sort=True)) if others else [(None, e)]
        for key, g in groups[:MAX_LINES]:
            g = g.sort_values(x_key) if x_key else g
            x = g[x_key].to_numpy(float) if x_key else np.arange(len(g), dtype=float)
            y = g["mean"].to_numpy(float)
            lo, hi = g["ci95_lo"].to_numpy(float), g["ci95_hi"].to_numpy(float)
            err = np.vstack([np.where(np.isfinite(lo), y - lo, 0.0), np.where(np.isfinite(hi), hi - y, 0.0)])
            ax.errorbar(x, y, yerr=err, marker="o", capsize=3,
                        label=None if key is None else f"{', '.join(map(str, np.atleast_1d(key)))}")
        ax.axhline(0.0, color="0.5", lw=0.8)
        unit = units.get(m, "")
        ax.set_title(m, fontsize=9)
        ax.set_ylabel(f"[{unit}]" if unit and unit != "-" else "")
        if x_key:
            ax.set_xlabel(labels.get(x_key, x_key))
        if others:
            ax.legend(fontsize=7)
    n = int(eff["n_seeds"].max()) if len(eff) else 0
    fig.suptitle(f"formation minus twin: mean over {n} seeds, bars 95 % confidence interval", fontsize=10)
    return fig
