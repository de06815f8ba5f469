"""Figures of one run (and the entry points for several runs overlaid).

The traffic figures are in :mod:`analysis.figures.traffic_figures`, the overlay of several runs in
:mod:`analysis.figures.compare_figures`, shared helpers in :mod:`analysis.figures.figure_kit`.
Figures are built with :class:`matplotlib.figure.Figure` directly (Agg canvas, no pyplot,
no global backend switch), saved as PNG and closed by dropping the reference.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.figures.compare_figures import compare_figures
from analysis.figures.figure_kit import (BAND_COLOURS, MAX_POINTS, RESOLUTION, decimate, floor_axis,
                                         floor_values, has_values, mark_maneuvers,
                                         mark_not_recorded, member_groups, new_figure, save_png,
                                         vc_frame_position)
from analysis.figures.traffic_figures import (BIRDSEYE_AHEAD_M, BIRDSEYE_BEHIND_M, BIRDSEYE_DPI,
                                              BIRDSEYE_STRIP_FRAMES, MAX_SCATTER,
                                              birdseye_animation, is_road_run, spacetime_figure)
from analysis.metrics import comfort, limits
from analysis.runs.member_columns import to_float
from analysis.runs.summary import RunAnalysis
from run_contract.columns import VIRTUAL_CAR_ID

__all__ = ["MAX_POINTS", "MAX_SCATTER", "BIRDSEYE_AHEAD_M", "BIRDSEYE_BEHIND_M",
           "BIRDSEYE_STRIP_FRAMES", "BIRDSEYE_DPI", "run_figures", "compare_figures",
           "spacetime_figure", "birdseye_animation"]


def _paths(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = member_groups(a)
    fig, axes = new_figure(2, h=3.4, sharex=False)
    ax = axes[0]
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID]
    if has_values(vc, "x", "y"):
        ax.plot(*decimate(vc["x"], vc["y"]), color="k", lw=1.2, label="virtual car")
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        if has_values(g, "x_des", "y_des"):
            ax.plot(*decimate(g["x_des"], g["y_des"]), color=col[mid], ls="--", lw=0.9)
        if has_values(g, "x", "y"):
            ax.plot(*decimate(g["x"], g["y"]), color=col[mid], lw=1.4, label=f"{mid}")
    ax.set(xlabel="x [m]", ylabel="y [m]",
           title="Paths: actual (solid) vs desired x_des, y_des (dashed); axes not to scale")
    ax.legend(loc="best", fontsize=8, ncols=4)
    ax.grid(alpha=0.3)
    ax = axes[1]
    drawn = False
    for mid in ids:
        rel = vc_frame_position(traj, mid)
        if rel is None:
            continue
        lon, lat = rel
        drawn = True
        ax.plot(*decimate(lon, lat), color=col[mid], lw=1.0)
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
        mark_not_recorded(ax, "virtual-car pose")
    return save_png(fig, path)


def _errors(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = member_groups(a)
    fig, axes = new_figure(4)
    tol = a.settings.settle_tol_m
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        s = a.signals.loc[a.signals["vehicle_id"] == mid]
        for ax, name in ((axes[0], "e_lon"), (axes[1], "e_lat")):
            if has_values(g, name):
                ax.plot(*decimate(g["t"], floor_values(g[name], "m")),
                        color=col[mid], lw=1, label=mid)
        if has_values(s, "e_norm"):
            axes[2].plot(*decimate(s["t"], floor_values(s["e_norm"], "m")),
                         color=col[mid], lw=1, label=mid)
        ts = a.members.loc[mid, "settling_time_s"]
        if ts is not None and np.isfinite(ts):
            axes[2].axvline(g["t"].iloc[0] + ts, color=col[mid], ls=":", lw=1)
    axes[2].axhspan(0, tol, color="#d9f2d9", zorder=0, label=f"settling band {tol:g} m")
    for ax, lab in zip(axes[:3], ("e_lon [m]", "e_lat [m]", "|e| [m]")):
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
        floor_axis(ax, "m")
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(loc="upper right", fontsize=8, ncols=4)
    axes[0].set_title("Formation error in the virtual-car frame (dotted: settling time; "
                      f"below {RESOLUTION['m'] * 1e3:g} mm drawn as 0)")
    if len(a.shape):
        axes[3].plot(*decimate(a.shape["t"], a.shape["shape_error"]), color="k", lw=1)
    else:
        mark_not_recorded(axes[3], "shape error")
    axes[3].set(ylabel="shape error [m]", xlabel="t [s]")
    axes[3].grid(alpha=0.3)
    mark_maneuvers(a, axes)
    return save_png(fig, path)


def _tracking(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = member_groups(a)
    fig, axes = new_figure(2)
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        for ax, ref, act in ((axes[0], "v_ref", "v"), (axes[1], "omega_ref", "yaw_rate")):
            if has_values(g, ref):
                ax.plot(*decimate(g["t"], g[ref]), color=col[mid], ls="--", lw=0.9)
            if has_values(g, act):
                y = g[act] if act == "v" else floor_values(g[act], "rad/s")
                ax.plot(*decimate(g["t"], y), color=col[mid], lw=1.2, label=mid)
    axes[0].set(ylabel="v [m/s]", title="References (dashed, eqs 2.6, 2.8) vs response (solid)")
    axes[1].set(ylabel="yaw rate [rad/s]", xlabel="t [s]")
    floor_axis(axes[1], "rad/s")
    for ax in axes:
        ax.grid(alpha=0.3)
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(loc="best", fontsize=8, ncols=4)
    mark_maneuvers(a, axes)
    return save_png(fig, path)


def _comfort(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = member_groups(a)
    fig, axes = new_figure(4)
    edges = comfort.LAT_BAND_EDGES
    peak = max([3.0] + [float(np.nanmax(np.abs(traj.loc[traj["vehicle_id"] == m, "a_lat"])))
                        for m in ids if has_values(traj.loc[traj["vehicle_id"] == m], "a_lat")])
    top = 1.1 * max(peak, edges[2])
    for k, name in enumerate(comfort.LAT_BAND_NAMES):
        lo, hi = edges[k], min(edges[k + 1], top)
        if lo >= top:
            break
        for sgn in (1, -1):
            axes[0].axhspan(sgn * lo, sgn * hi, color=BAND_COLOURS[k], zorder=0,
                            label=name if sgn == 1 else None)
    axes[0].set_ylim(-top, top)
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        s = a.signals.loc[a.signals["vehicle_id"] == mid]
        if has_values(g, "a_lat"):
            axes[0].plot(*decimate(g["t"], g["a_lat"]), color=col[mid], lw=1, label=mid)
        if has_values(g, "a_lon"):
            axes[1].plot(*decimate(g["t"], floor_values(g["a_lon"], "m/s^2")),
                         color=col[mid], lw=1, label=mid)
        if has_values(s, "jerk_lat"):
            axes[2].plot(*decimate(s["t"], floor_values(s["jerk_lat"], "m/s^3")),
                         color=col[mid], lw=1)
        if has_values(s, "jerk_lon"):
            axes[3].plot(*decimate(s["t"], floor_values(s["jerk_lon"], "m/s^3")),
                         color=col[mid], lw=1)
    lim = comfort.LON_ACC_COMFORT
    for y in (lim, -lim):
        axes[1].axhline(y, color="r", ls="--", lw=1)
    axes[0].set(ylabel="a_lat [m/s^2]",
                title="Lateral acceleration and the seed's comfort bands (section 3.1.2)")
    axes[0].legend(loc="upper right", fontsize=7, ncols=4)
    axes[1].set(ylabel="a_lon [m/s^2]",
                title=f"Longitudinal acceleration, comfort limit +/-{lim:g} m/s^2 (section 3.1.5)")
    axes[2].set(ylabel="jerk lat [m/s^3]")
    floor_axis(axes[2], "m/s^3")
    floor_axis(axes[3], "m/s^3")
    w = a.settings
    axes[3].set(ylabel="jerk lon [m/s^3]", xlabel="t [s]")
    axes[2].set_title(f"Jerk: Savitzky-Golay derivative, {w.jerk_window_s:g} s window, "
                      f"order {w.jerk_polyorder}")
    for ax in axes:
        ax.grid(alpha=0.3)
    mark_maneuvers(a, axes)
    return save_png(fig, path)


def _limits(a: RunAnalysis, path: Path) -> Path:
    traj, ids, col = member_groups(a)
    fig, axes = new_figure(3)
    drawn = [False, False, False]
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        if has_values(g, "slip_front"):
            axes[0].plot(*decimate(g["t"], np.degrees(g["slip_front"])), color=col[mid], lw=1,
                         label=f"{mid} front")
            drawn[0] = True
        if has_values(g, "slip_rear"):
            axes[0].plot(*decimate(g["t"], np.degrees(g["slip_rear"])), color=col[mid], lw=1,
                         ls="--", label=f"{mid} rear")
            drawn[0] = True
        if has_values(g, "friction_usage"):
            axes[1].plot(*decimate(g["t"], g["friction_usage"]), color=col[mid], lw=1, label=mid)
            drawn[1] = True
        if has_values(g, "traction_force"):
            axes[2].plot(*decimate(g["t"], g["traction_force"]), color=col[mid], lw=1, label=mid)
            drawn[2] = True
        if has_values(g, "traction_force_max"):
            axes[2].plot(*decimate(g["t"], g["traction_force_max"]), color=col[mid], lw=0.8,
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
            mark_not_recorded(ax, what)
        elif ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=7, ncols=4)
    axes[0].set_title(f"Limits of section 3.3.1: |slip| < {lim:g} deg, friction circle "
                      "(eq 3.16), F_lf < F_lf,max (dashed, eq 3.14)")
    axes[2].set_xlabel("t [s]")
    return save_png(fig, path)


def _has_comm(a: RunAnalysis) -> bool:
    """A run whose members held virtual-car states of more than one age ([comm])."""
    age = pd.to_numeric(a.data.trajectories.get("leader_age_s"), errors="coerce")
    return age is not None and bool((age.fillna(0.0) > 0.0).any())


def comm_figure(a: RunAnalysis, path: Path) -> Path:
    """Age of the virtual-car state each member held over time, and the r.m.s. formation
    error and longitudinal acceleration per age bin (analysis/metrics/comm.py)."""
    traj, ids, col = member_groups(a)
    fig, axes = new_figure(3, sharex=False)
    bins = a.comm_age if a.comm_age is not None else pd.DataFrame()
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        axes[0].plot(*decimate(g["t"], g["leader_age_s"]), color=col[mid], lw=1, label=mid)
        b = bins[bins["id"] == mid] if len(bins) else bins
        if len(b):
            mid_age = np.where(np.isfinite(b["age_hi_s"]), (b["age_lo_s"] + b["age_hi_s"]) / 2,
                               b["age_lo_s"] * 1.5)
            axes[1].plot(mid_age, b["e_rms_m"], "o-", color=col[mid], label=mid)
            axes[2].plot(mid_age, b["a_lon_rms_mps2"], "o-", color=col[mid], label=mid)
    axes[0].set(xlabel="t [s]", ylabel="leader age [s]",
                title="Age of the newest virtual-car state each member holds")
    axes[1].set(ylabel="r.m.s. |e| [m]", title="Formation error and comfort per age bin")
    axes[2].set(xlabel="leader age (bin centre) [s]", ylabel="r.m.s. a_lon [m/s²]")
    for ax in axes:
        ax.grid(alpha=0.3)
    if ids:
        axes[0].legend(loc="upper right", fontsize=8, ncols=4)
    return save_png(fig, path)


def _propagation(a: RunAnalysis, path: Path) -> Path:
    """Members at their slots, coloured by peak error, with the neighbour-to-neighbour peak
    error ratios along columns (front to back) and rows (outwards from the most disturbed)."""
    from analysis.metrics.propagation import propagation

    off = {m.id: m.offset for m in a.data.members if np.isfinite(m.offset).all()
           and m.id in a.members.index}
    peak = {m: to_float(a.members.loc[m, "e_max_m"]) for m in off}
    rms = {m: to_float(a.members.loc[m, "e_rms_m"]) for m in off}
    fig, axes = new_figure(1, h=4.2, w=7.0)
    ax = axes[0]
    if not off:
        mark_not_recorded(ax, "member offsets")
        return save_png(fig, path)
    xy = {m: (-o[1], o[0]) for m, o in off.items()}  # across (left to the left), along up
    vals = np.array([peak[m] for m in off])
    sc = ax.scatter([xy[m][0] for m in off], [xy[m][1] for m in off], c=vals, cmap="viridis_r",
                    s=400, edgecolors="k", zorder=3)
    fig.colorbar(sc, ax=ax, label="peak formation error e_max [m]")
    for m in off:
        ax.annotate(f"{m}\n{peak[m]:.3g} m", xy[m], xytext=(0, -26), textcoords="offset points",
                    ha="center", fontsize=8)
    for r in propagation(off, peak, rms).itertuples():
        (x0, y0), (x1, y1) = xy[r.source], xy[r.target]
        colour = "#b42318" if r.grows else "#1a7f37"
        ax.annotate("", (x1, y1), (x0, y0), arrowprops=dict(arrowstyle="->", color=colour,
                                                            shrinkA=14, shrinkB=14, lw=1.5))
        ax.text((x0 + x1) / 2, (y0 + y1) / 2, f"x{r.peak_ratio:.2f}", color=colour, fontsize=8,
                ha="center", va="bottom", zorder=4)
    ax.set(xlabel="right of the reference [m]  (left <- -> right)", ylabel="ahead [m]",
           title="Disturbance propagation: peak-error ratio to the neighbour\n"
                 "(red > 1: grows, green: decays)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.3)
    ax.grid(alpha=0.3)
    return save_png(fig, path)


_RUN_FIGURES = (("paths", _paths), ("errors", _errors), ("propagation", _propagation),
                ("tracking", _tracking), ("comfort", _comfort), ("limits", _limits))
_TRAFFIC_FIGURES = (("traffic_spacetime", spacetime_figure, ".png"),
                    ("traffic_birdseye", birdseye_animation, ".gif"))


def run_figures(analysis: RunAnalysis, out_dir: str | Path) -> tuple[dict[str, Path], dict[str, str]]:
    """Draw the figures of one run as PNG files.

    Parameters
    ----------
    analysis : RunAnalysis
        Output of :func:`analysis.runs.summary.compute_run`.
    out_dir : str or Path
        Directory for the PNG files (created if needed).

    Returns
    -------
    (dict, dict)
        Figure name to written path (``paths``, ``errors``, ``tracking``, ``comfort``,
        ``limits``; ``comm`` when the members held states of varying age; for road runs
        also ``traffic_spacetime`` (PNG) and
        ``traffic_birdseye`` (GIF, or a PNG strip without pillow)), and figure name to
        error message for figures that could not be drawn (damaged data never stops the
        others).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written, failed = {}, {}
    for name in [n for n, _ in _RUN_FIGURES] + [n for n, _, _ in _TRAFFIC_FIGURES]:
        for ext in (".png", ".gif"):  # never leave a stale figure from an earlier analysis
            (out / f"{name}{ext}").unlink(missing_ok=True)
    for name, fn in _RUN_FIGURES:
        try:
            written[name] = fn(analysis, out / f"{name}.png")
        except Exception as exc:  # noqa: BLE001 - report, keep drawing the others
            failed[name] = f"{type(exc).__name__}: {exc}"
    (out / "comm.png").unlink(missing_ok=True)
    if _has_comm(analysis):
        try:
            written["comm"] = comm_figure(analysis, out / "comm.png")
        except Exception as exc:  # noqa: BLE001
            failed["comm"] = f"{type(exc).__name__}: {exc}"
    if is_road_run(analysis):
        for name, fn, ext in _TRAFFIC_FIGURES:
            try:
                written[name] = fn(analysis, out / f"{name}{ext}")
            except Exception as exc:  # noqa: BLE001
                failed[name] = f"{type(exc).__name__}: {exc}"
    return written, failed
