"""Figures of one run and of several runs overlaid (the only matplotlib import).

Figures are built with :class:`matplotlib.figure.Figure` directly (Agg canvas, no pyplot,
no global backend switch), saved as PNG and closed by dropping the reference.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from analysis import comfort, limits
from analysis.summary import RunAnalysis
from formation_traci.record.columns import VIRTUAL_CAR_ID

__all__ = ["MAX_POINTS", "run_figures", "compare_figures"]

MAX_POINTS = 20000
"""Lines with more samples are decimated (every k-th sample) before plotting."""

_BAND_COLOURS = ("#d9f2d9", "#fff2b3", "#ffd9b3", "#ffb3b3")
_LINESTYLES = ("-", "--", ":", "-.")


def _new(nrows: int, ncols: int = 1, h: float = 2.6, w: float = 10.0, sharex: bool = True):
    fig = Figure(figsize=(w, 0.6 + h * nrows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, sharex=sharex, squeeze=False)
    return fig, axes[:, 0] if ncols == 1 else axes


def _dec(*arrays):
    n = len(arrays[0])
    k = max(1, math.ceil(n / MAX_POINTS))
    return [np.asarray(a)[::k] for a in arrays]


def _has(df: pd.DataFrame, *cols: str) -> bool:
    return all(c in df.columns and df[c].notna().any() for c in cols)


def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    return path


def _colours(ids) -> dict[str, str]:
    cyc = ["C%d" % (i % 10) for i in range(len(ids))]
    return dict(zip(ids, cyc))


def _member_groups(a: RunAnalysis):
    traj = a.data.trajectories
    ids = [m.id for m in a.data.members if (traj["vehicle_id"] == m.id).any()]
    return traj, ids, _colours(ids)


def _not_recorded(ax, what: str) -> None:
    ax.text(0.5, 0.5, f"{what}: not recorded", transform=ax.transAxes, ha="center",
            va="center", color="0.4")


def _vc_frame(traj: pd.DataFrame, mid: str) -> tuple[np.ndarray, np.ndarray] | None:
    """Member position in the virtual-car frame (along, left of its heading) [m]."""
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, ["t", "x", "y", "heading"]]
    if not _has(vc, "x", "y", "heading"):
        return None
    vc = vc.rename(columns={"x": "x_vc", "y": "y_vc"})
    g = traj.loc[traj["vehicle_id"] == mid, ["t", "x", "y"]].merge(vc, on="t").dropna()
    if g.empty:
        return None
    c, s = np.cos(g["heading"].to_numpy()), np.sin(g["heading"].to_numpy())
    dx, dy = (g["x"] - g["x_vc"]).to_numpy(), (g["y"] - g["y_vc"]).to_numpy()
    return c * dx + s * dy, -s * dx + c * dy


def _paths(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = _member_groups(a)
    fig, axes = _new(2, h=3.4, sharex=False)
    ax = axes[0]
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID]
    if _has(vc, "x", "y"):
        ax.plot(*_dec(vc["x"], vc["y"]), color="k", lw=1.2, label="virtual car")
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        if _has(g, "x_des", "y_des"):
            ax.plot(*_dec(g["x_des"], g["y_des"]), color=col[mid], ls="--", lw=0.9)
        if _has(g, "x", "y"):
            ax.plot(*_dec(g["x"], g["y"]), color=col[mid], lw=1.4, label=f"{mid}")
    ax.set(xlabel="x [m]", ylabel="y [m]",
           title="Paths: actual (solid) vs desired x_des, y_des (dashed); axes not to scale")
    ax.legend(loc="best", fontsize=8, ncols=4)
    ax.grid(alpha=0.3)
    ax = axes[1]
    drawn = False
    for mid in ids:
        rel = _vc_frame(traj, mid)
        if rel is None:
            continue
        lon, lat = rel
        drawn = True
        ax.plot(*_dec(lon, lat), color=col[mid], lw=1.0)
        ax.plot(lon[0], lat[0], "o", color=col[mid], ms=4)
        off = next(m.offset for m in a.data.members if m.id == mid)
        if np.isfinite(off).all():
            ax.plot(*off, "x", color=col[mid], ms=9, mew=2)
        ax.annotate(mid, (lon[-1], lat[-1]), fontsize=8, color=col[mid])
    if drawn:
        ax.set_aspect("equal", adjustable="datalim")
        ax.set(title="Members in the virtual-car frame (o start, x desired offset)",
               xlabel="along the virtual-car heading [m]", ylabel="left of it [m]")
        ax.grid(alpha=0.3)
    else:
        _not_recorded(ax, "virtual-car pose")
    return _save(fig, path)


def _errors(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = _member_groups(a)
    fig, axes = _new(4)
    tol = a.settings.settle_tol_m
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        s = a.signals.loc[a.signals["vehicle_id"] == mid]
        for ax, name in ((axes[0], "e_lon"), (axes[1], "e_lat")):
            if _has(g, name):
                ax.plot(*_dec(g["t"], g[name]), color=col[mid], lw=1, label=mid)
        if _has(s, "e_norm"):
            axes[2].plot(*_dec(s["t"], s["e_norm"]), color=col[mid], lw=1, label=mid)
        ts = a.members.loc[mid, "settling_time_s"]
        if ts is not None and np.isfinite(ts):
            axes[2].axvline(g["t"].iloc[0] + ts, color=col[mid], ls=":", lw=1)
    axes[2].axhspan(0, tol, color="#d9f2d9", zorder=0, label=f"settling band {tol:g} m")
    for ax, lab in zip(axes[:3], ("e_lon [m]", "e_lat [m]", "|e| [m]")):
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncols=4)
    axes[0].set_title("Formation error in the virtual-car frame (dotted: settling time)")
    if len(a.shape):
        axes[3].plot(*_dec(a.shape["t"], a.shape["shape_error"]), color="k", lw=1)
    else:
        _not_recorded(axes[3], "shape error")
    axes[3].set(ylabel="shape error [m]", xlabel="t [s]")
    axes[3].grid(alpha=0.3)
    return _save(fig, path)


def _tracking(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = _member_groups(a)
    fig, axes = _new(2)
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        for ax, ref, act in ((axes[0], "v_ref", "v"), (axes[1], "omega_ref", "yaw_rate")):
            if _has(g, ref):
                ax.plot(*_dec(g["t"], g[ref]), color=col[mid], ls="--", lw=0.9)
            if _has(g, act):
                ax.plot(*_dec(g["t"], g[act]), color=col[mid], lw=1.2, label=mid)
    axes[0].set(ylabel="v [m/s]", title="References (dashed, eqs 2.6, 2.8) vs response (solid)")
    axes[1].set(ylabel="yaw rate [rad/s]", xlabel="t [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8, ncols=4)
    return _save(fig, path)


def _comfort(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = _member_groups(a)
    fig, axes = _new(4)
    edges = comfort.LAT_BAND_EDGES
    peak = max([3.0] + [float(np.nanmax(np.abs(traj.loc[traj["vehicle_id"] == m, "a_lat"])))
                        for m in ids if _has(traj.loc[traj["vehicle_id"] == m], "a_lat")])
    top = 1.1 * max(peak, edges[2])
    for k, name in enumerate(comfort.LAT_BAND_NAMES):
        lo, hi = edges[k], min(edges[k + 1], top)
        if lo >= top:
            break
        for sgn in (1, -1):
            axes[0].axhspan(sgn * lo, sgn * hi, color=_BAND_COLOURS[k], zorder=0,
                            label=name if sgn == 1 else None)
    axes[0].set_ylim(-top, top)
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        s = a.signals.loc[a.signals["vehicle_id"] == mid]
        if _has(g, "a_lat"):
            axes[0].plot(*_dec(g["t"], g["a_lat"]), color=col[mid], lw=1, label=mid)
        if _has(g, "a_lon"):
            axes[1].plot(*_dec(g["t"], g["a_lon"]), color=col[mid], lw=1, label=mid)
        if _has(s, "jerk_lat"):
            axes[2].plot(*_dec(s["t"], s["jerk_lat"]), color=col[mid], lw=1)
        if _has(s, "jerk_lon"):
            axes[3].plot(*_dec(s["t"], s["jerk_lon"]), color=col[mid], lw=1)
    lim = comfort.LON_ACC_COMFORT
    for y in (lim, -lim):
        axes[1].axhline(y, color="r", ls="--", lw=1)
    axes[0].set(ylabel="a_lat [m/s^2]",
                title="Lateral acceleration and the seed's comfort bands (section 3.1.2)")
    axes[0].legend(loc="upper right", fontsize=7, ncols=4)
    axes[1].set(ylabel="a_lon [m/s^2]",
                title=f"Longitudinal acceleration, comfort limit +/-{lim:g} m/s^2 (section 3.1.5)")
    axes[2].set(ylabel="jerk lat [m/s^3]")
    w = a.settings
    axes[3].set(ylabel="jerk lon [m/s^3]", xlabel="t [s]")
    axes[2].set_title(f"Jerk: Savitzky-Golay derivative, {w.jerk_window_s:g} s window, "
                      f"order {w.jerk_polyorder}")
    for ax in axes:
        ax.grid(alpha=0.3)
    return _save(fig, path)


def _limits(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = _member_groups(a)
    fig, axes = _new(3)
    drawn = [False, False, False]
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        if _has(g, "slip_front"):
            axes[0].plot(*_dec(g["t"], np.degrees(g["slip_front"])), color=col[mid], lw=1,
                         label=f"{mid} front")
            drawn[0] = True
        if _has(g, "slip_rear"):
            axes[0].plot(*_dec(g["t"], np.degrees(g["slip_rear"])), color=col[mid], lw=1,
                         ls="--", label=f"{mid} rear")
            drawn[0] = True
        if _has(g, "friction_usage"):
            axes[1].plot(*_dec(g["t"], g["friction_usage"]), color=col[mid], lw=1, label=mid)
            drawn[1] = True
        if _has(g, "traction_force"):
            axes[2].plot(*_dec(g["t"], g["traction_force"]), color=col[mid], lw=1, label=mid)
            drawn[2] = True
        if _has(g, "traction_force_max"):
            axes[2].plot(*_dec(g["t"], g["traction_force_max"]), color=col[mid], lw=0.8,
                         ls="--")
            drawn[2] = True
    lim = math.degrees(limits.SLIP_ANGLE_LIMIT)
    for y in (lim, -lim):
        axes[0].axhline(y, color="r", ls="--", lw=1)
    axes[1].axhline(limits.FRICTION_USAGE_LIMIT, color="r", ls="--", lw=1)
    labels = ("slip angle [deg]", "friction usage [-]", "traction force [N]")
    whats = ("tire slip angles", "friction usage", "traction force")
    for ax, lab, ok, what in zip(axes, labels, drawn, whats):
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
        if not ok:
            _not_recorded(ax, what)
        elif ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=7, ncols=4)
    axes[0].set_title(f"Limits of section 3.3.1: |slip| < {lim:g} deg, friction circle "
                      "(eq 3.16), F_lf < F_lf,max (dashed, eq 3.14)")
    axes[2].set_xlabel("t [s]")
    return _save(fig, path)


_RUN_FIGURES = (("paths", _paths), ("errors", _errors), ("tracking", _tracking),
                ("comfort", _comfort), ("limits", _limits))


def run_figures(analysis: RunAnalysis, out_dir: str | Path) -> tuple[dict[str, Path], dict[str, str]]:
    """Draw the figures of one run as PNG files.

    Parameters
    ----------
    analysis : RunAnalysis
        Output of :func:`analysis.summary.compute_run`.
    out_dir : str or Path
        Directory for the PNG files (created if needed).

    Returns
    -------
    (dict, dict)
        Figure name to written path (``paths``, ``errors``, ``tracking``, ``comfort``,
        ``limits``), and figure name to error message for figures that could not be
        drawn (damaged data never stops the others).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written, failed = {}, {}
    for name, _ in _RUN_FIGURES:  # never leave a stale figure from an earlier analysis
        (out / f"{name}.png").unlink(missing_ok=True)
    for name, fn in _RUN_FIGURES:
        try:
            written[name] = fn(analysis, out / f"{name}.png")
        except Exception as exc:  # noqa: BLE001 - report, keep drawing the others
            failed[name] = f"{type(exc).__name__}: {exc}"
    return written, failed


def compare_figures(analyses: Mapping[str, RunAnalysis],
                    out_dir: str | Path) -> tuple[dict[str, Path], dict[str, str]]:
    """Overlay several runs on the same axes, one colour per run.

    Parameters
    ----------
    analyses : mapping of str to RunAnalysis
        Run label (e.g. the run directory name) to its analysis.
    out_dir : str or Path
        Directory for the PNG files (created if needed).

    Returns
    -------
    (dict, dict)
        Figure name to written path (``compare_paths``, ``compare_signals``), and figure
        name to error message for figures that could not be drawn.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written, failed = {}, {}
    colours = _colours(list(analyses))
    try:
        fig, axes = _new(2, h=3.6, sharex=False)
        ax = axes[0]
        for r, (label, a) in enumerate(analyses.items()):
            traj, ids, _ = _member_groups(a)
            lw = max(0.8, 2.4 - 0.6 * r)  # earlier runs wider: overlapping runs stay visible
            for k, mid in enumerate(ids):
                g = traj.loc[traj["vehicle_id"] == mid]
                if _has(g, "x", "y"):
                    ax.plot(*_dec(g["x"], g["y"]), color=colours[label], lw=lw,
                            ls=_LINESTYLES[k % len(_LINESTYLES)],
                            label=label if k == 0 else None)
                rel = _vc_frame(traj, mid)
                if rel is not None:
                    axes[1].plot(*_dec(*rel), color=colours[label], lw=lw,
                                 ls=_LINESTYLES[k % len(_LINESTYLES)],
                                 label=label if k == 0 else None)
                    axes[1].annotate(mid, (rel[0][-1], rel[1][-1]), fontsize=8)
            vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID]
            if _has(vc, "x", "y"):
                ax.plot(*_dec(vc["x"], vc["y"]), color=colours[label], lw=0.6, alpha=0.6)
        ax.set(xlabel="x [m]", ylabel="y [m]",
               title="Member paths per run (line style = member, thin = virtual car); "
                     "axes not to scale")
        ax.legend(loc="best", fontsize=8)
        ax.grid(alpha=0.3)
        axes[1].set_aspect("equal", adjustable="datalim")
        axes[1].set(title="Members in the virtual-car frame",
                    xlabel="along the virtual-car heading [m]", ylabel="left of it [m]")
        axes[1].grid(alpha=0.3)
        written["compare_paths"] = _save(fig, out / "compare_paths.png")
    except Exception as exc:  # noqa: BLE001
        failed["compare_paths"] = f"{type(exc).__name__}: {exc}"
    try:
        fig, axes = _new(4)
        rows = (("e_norm", "|e| [m]", True), ("v", "v [m/s]", False),
                ("yaw_rate", "yaw rate [rad/s]", False), ("a_lat", "a_lat [m/s^2]", False))
        for label, a in analyses.items():
            traj, ids, _ = _member_groups(a)
            for k, mid in enumerate(ids):
                g = traj.loc[traj["vehicle_id"] == mid]
                s = a.signals.loc[a.signals["vehicle_id"] == mid]
                for ax, (name, _, from_signals) in zip(axes, rows):
                    src = s if from_signals else g
                    if _has(src, name):
                        ax.plot(*_dec(src["t"], src[name]), color=colours[label], lw=1,
                                ls=_LINESTYLES[k % len(_LINESTYLES)],
                                label=label if k == 0 else None)
        for ax, (_, lab, _) in zip(axes, rows):
            ax.set_ylabel(lab)
            ax.grid(alpha=0.3)
        for y in (comfort.LAT_ACC_MEDIUM, -comfort.LAT_ACC_MEDIUM):
            axes[3].axhline(y, color="r", ls="--", lw=0.8)
        axes[0].legend(loc="upper right", fontsize=8)
        axes[0].set_title("Runs overlaid (colour = run, line style = member)")
        axes[3].set_xlabel("t [s]")
        written["compare_signals"] = _save(fig, out / "compare_signals.png")
    except Exception as exc:  # noqa: BLE001
        failed["compare_signals"] = f"{type(exc).__name__}: {exc}"
    return written, failed
