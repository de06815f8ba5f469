"""Shared drawing helpers of the analysis figures: new Agg figures, decimation, the
physical floor of plotted signals, member colours, maneuver shading, the virtual-car frame.

Figures are built with :class:`matplotlib.figure.Figure` directly (Agg canvas, no pyplot,
no global backend switch), saved as PNG and closed by dropping the reference. Used by
:mod:`analysis.figures.run_figures`, :mod:`analysis.figures.traffic_figures` and
:mod:`analysis.figures.compare_figures`.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from analysis.metrics.maneuvers import maneuver_intervals
from analysis.runs.summary import RunAnalysis
from run_contract.columns import VIRTUAL_CAR_ID

MAX_POINTS = 20000
"""Lines with more samples are decimated (every k-th sample) before plotting."""


BAND_COLOURS = ("#d9f2d9", "#fff2b3", "#ffd9b3", "#ffb3b3")
LINESTYLES = ("-", "--", ":", "-.")


def new_figure(nrows: int, ncols: int = 1, h: float = 2.6, w: float = 10.0, sharex: bool = True):
    """A constrained-layout Agg figure with ``nrows`` x ``ncols`` axes (a column of axes
    when ``ncols`` is 1), ``h`` [in] per row and ``w`` [in] wide."""
    fig = Figure(figsize=(w, 0.6 + h * nrows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, sharex=sharex, squeeze=False)
    return fig, axes[:, 0] if ncols == 1 else axes


def decimate(*arrays):
    """Every k-th sample of each array, k chosen so no line has more than MAX_POINTS."""
    n = len(arrays[0])
    k = max(1, math.ceil(n / MAX_POINTS))
    return [np.asarray(a)[::k] for a in arrays]


def has_values(df: pd.DataFrame, *cols: str) -> bool:
    """True when every column of ``cols`` is in ``df`` with at least one non-NaN value."""
    return all(c in df.columns and df[c].notna().any() for c in cols)


def save_png(fig: Figure, path: Path, dpi: int = 110) -> Path:
    """Write ``fig`` as PNG to ``path`` through a temporary file and a rename: never a
    truncated figure (disk full), never through a symbolic link."""
    import io

    from run_contract.rundir import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)


RESOLUTION = {"m": 1e-3, "rad/s": 1e-4, "m/s^2": 1e-3, "m/s^3": 1e-2}
"""Physical floor of the plotted signals by unit: values smaller in magnitude are drawn as
zero and an axis never spans less than ten times this (straight-road runs otherwise show
1e-12 m of rounding noise as an oscillation)."""


def floor_values(y, unit: str):
    """``y`` with values below the unit's :data:`RESOLUTION` set to zero."""
    y = np.asarray(y, dtype=float)
    return np.where(np.abs(y) < RESOLUTION[unit], 0.0, y)


def floor_axis(ax, unit: str) -> None:
    """Widen the y axis of ``ax`` to at least ten times the unit's :data:`RESOLUTION`."""
    lo, hi = ax.get_ylim()
    span = 10 * RESOLUTION[unit]
    if hi - lo < span:
        mid = 0.0 if lo <= 0.0 <= hi else (lo + hi) / 2
        ax.set_ylim(mid - span / 2, mid + span / 2)


def member_colours(ids) -> dict[str, str]:
    """One matplotlib cycle colour per id, in order."""
    cyc = ["C%d" % (i % 10) for i in range(len(ids))]
    return dict(zip(ids, cyc))


def member_groups(a: RunAnalysis):
    """The trajectories, the ids of the members that have rows, and their colours."""
    traj = a.data.trajectories
    ids = [m.id for m in a.data.members if (traj["vehicle_id"] == m.id).any()]
    return traj, ids, member_colours(ids)


_MANEUVER_COLOURS = {"reshape": "#c6dbef", "lane_change": "#e5d8f0"}


def mark_maneuvers(a: RunAnalysis, axes) -> None:
    """Shade every maneuver interval (events.parquet) on time plots, labelled once."""
    traj = a.data.trajectories
    t_end = float(traj["t"].max()) if len(traj) else 0.0
    iv = maneuver_intervals(a.data.tables.get("events"), t_end)
    seen = set()
    for name, t0, t1 in zip(iv["name"], iv["start_s"], iv["end_s"]):
        for ax in axes:
            ax.axvspan(t0, t1, color=_MANEUVER_COLOURS.get(name, "#eeeeee"), alpha=0.6, zorder=0,
                       label=None if name in seen or ax is not axes[-1] else f"maneuver: {name}")
        seen.add(name)
    if seen:
        axes[-1].legend(loc="upper right", fontsize=7)


def mark_not_recorded(ax, what: str) -> None:
    """Write '<what>: not recorded' in the middle of an empty panel."""
    ax.text(0.5, 0.5, f"{what}: not recorded", transform=ax.transAxes, ha="center",
            va="center", color="0.4")


def vc_frame_position(traj: pd.DataFrame, mid: str) -> tuple[np.ndarray, np.ndarray] | None:
    """Member position in the virtual-car frame (along, left of its heading) [m]."""
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, ["t", "x", "y", "heading"]]
    if not has_values(vc, "x", "y", "heading"):
        return None
    vc = vc.rename(columns={"x": "x_vc", "y": "y_vc"})
    g = traj.loc[traj["vehicle_id"] == mid, ["t", "x", "y"]].merge(vc, on="t").dropna()
    if g.empty:
        return None
    c, s = np.cos(g["heading"].to_numpy()), np.sin(g["heading"].to_numpy())
    dx, dy = (g["x"] - g["x_vc"]).to_numpy(), (g["y"] - g["y_vc"]).to_numpy()
    return c * dx + s * dy, -s * dx + c * dy
