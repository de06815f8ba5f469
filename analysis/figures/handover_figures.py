"""The hand-over figure (docs/maneuvers.md): a vehicle's speed, lateral offset and formation
error across the switch between our controller and SUMO's driver (analysis/metrics/handover.py),
with the switch marked, the maneuver intervals shaded and the edges it reached off the
formation's route (an exit) named."""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from analysis.figures.figure_kit import save_png
from analysis.metrics.handover import handover_track
from analysis.metrics.maneuvers import maneuver_intervals

__all__ = ["handover_figure"]

ERROR_AXIS_MIN = 0.01
"""The formation-error axis spans at least 0 .. this [m]."""
OFFSET_AXIS_MIN = 1.0
"""The lateral-offset axis spans at least this [m] (a lane keeper's 1e-11 m are not news)."""


def handover_figure(run_dir: str | Path, member: str, path: str | Path,
                    title: str | None = None) -> Path:
    """Speed, lateral offset and formation error of ``member``'s vehicle across its
    hand-over (module docstring) as a PNG.

    Parameters
    ----------
    run_dir : str or Path
        The recorded run (events, trajectories, background parquet files and run.json).
    member : str
        The member that left or joined.
    path : str or Path
        The PNG to write.
    title : str, optional
        Figure title (default: the event and its time).

    Returns
    -------
    Path
        ``path``.
    """
    run = Path(run_dir)
    ev, traj, bg = (pd.read_parquet(run / f"{n}.parquet")
                    for n in ("events", "trajectories", "background"))
    track, t_sw, kind = handover_track(ev, traj, bg, member)
    fig = Figure(figsize=(10.0, 7.0), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 1, sharex=True)
    iv = maneuver_intervals(ev, float(traj["t"].max()))
    for ax in axes:
        for name, t0, t1 in zip(iv["name"], iv["start_s"], iv["end_s"]):
            ax.axvspan(t0, max(t1, t0 + 0.1), color="#dde8f3", zorder=0)
        ax.axvline(t_sw, color="k", lw=0.8, ls=":")
        ax.grid(alpha=0.3)
    styles = {"formation": dict(color="C0", lw=1.6, label="driven by the formation controller"),
              "sumo": dict(color="C3", lw=1.2, ls="--", label="driven by SUMO")}
    for driver, g in track.groupby("driver", sort=False):
        axes[0].plot(g["t"], g["v"], **styles[driver])
        axes[1].plot(g["t"], g["d"], **styles[driver])
        if driver == "formation":
            axes[2].plot(g["t"], g["e"], **styles[driver])
    edge = track["lane"].str.rsplit("_", n=1).str[0]
    route = set(json.loads((run / "run.json").read_text()).get("sumo", {}).get("route", []))
    for e in sorted(set(edge) - route - {""}):
        t_in = float(track["t"][edge == e].min())
        if e.startswith(":"):
            continue
        axes[1].axvline(t_in, color="C2", lw=1.0)
        axes[1].annotate(f"on {e}", (t_in, float(track["d"][edge == e].iloc[0])), fontsize=8,
                         color="C2", xytext=(4, -12), textcoords="offset points")
    axes[0].set(ylabel="v [m/s]", title=title or f"{kind} of {member!r} at t = {t_sw:.2f} s "
                "(dotted; shaded: maneuver intervals)")
    axes[0].legend(loc="best", fontsize=8)
    axes[1].set(ylabel="d [m] (left of the reference lane)")
    lo, hi = axes[1].get_ylim()
    if hi - lo < OFFSET_AXIS_MIN:
        mid = (lo + hi) / 2
        axes[1].set_ylim(mid - OFFSET_AXIS_MIN / 2, mid + OFFSET_AXIS_MIN / 2)
    axes[2].set(ylabel="|formation error| [m]", xlabel="t [s]")
    lo, hi = axes[2].get_ylim()
    axes[2].set_ylim(min(lo, 0.0), max(hi, ERROR_AXIS_MIN))  # not 1e-12 m of rounding noise
    return save_png(fig, path)
