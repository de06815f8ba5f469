"""Figures of one run and of several runs overlaid (the only matplotlib import).

Figures are built with :class:`matplotlib.figure.Figure` directly (Agg canvas, no pyplot,
no global backend switch), saved as PNG and closed by dropping the reference.
"""
from __future__ import annotations

import importlib.util
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from analysis import comfort, limits, traffic
from analysis.maneuvers import maneuver_intervals
from analysis.summary import RunAnalysis
from analysis.traffic_run import member_rows, time_keys
from formation_traci.record.columns import VIRTUAL_CAR_ID

__all__ = ["MAX_POINTS", "MAX_SCATTER", "BIRDSEYE_AHEAD_M", "BIRDSEYE_BEHIND_M",
           "BIRDSEYE_STRIP_FRAMES", "BIRDSEYE_DPI", "run_figures", "compare_figures",
           "spacetime_figure", "birdseye_animation"]

MAX_POINTS = 20000
"""Lines with more samples are decimated (every k-th sample) before plotting."""

MAX_SCATTER = 250_000
"""Space-time points above this are thinned by keeping every k-th time step."""

BIRDSEYE_AHEAD_M = 80.0
"""Bird's-eye window: distance shown ahead of the virtual car [m]."""

BIRDSEYE_BEHIND_M = 80.0
"""Bird's-eye window: distance shown behind the virtual car [m]."""

BIRDSEYE_STRIP_FRAMES = 6
"""Frames in the PNG strip written instead of the GIF when pillow is not installed."""

BIRDSEYE_DPI = 80
"""Resolution of the animation frames [dots per inch]: 800 px wide."""

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


RESOLUTION = {"m": 1e-3, "rad/s": 1e-4, "m/s^2": 1e-3, "m/s^3": 1e-2}
"""Physical floor of the plotted signals by unit: values smaller in magnitude are drawn as
zero and an axis never spans less than ten times this (straight-road runs otherwise show
1e-12 m of rounding noise as an oscillation)."""


def _fl(y, unit: str):
    """``y`` with values below the unit's :data:`RESOLUTION` set to zero."""
    y = np.asarray(y, dtype=float)
    return np.where(np.abs(y) < RESOLUTION[unit], 0.0, y)


def _floor_axis(ax, unit: str) -> None:
    lo, hi = ax.get_ylim()
    span = 10 * RESOLUTION[unit]
    if hi - lo < span:
        mid = 0.0 if lo <= 0.0 <= hi else (lo + hi) / 2
        ax.set_ylim(mid - span / 2, mid + span / 2)


def _colours(ids) -> dict[str, str]:
    cyc = ["C%d" % (i % 10) for i in range(len(ids))]
    return dict(zip(ids, cyc))


def _member_groups(a: RunAnalysis):
    traj = a.data.trajectories
    ids = [m.id for m in a.data.members if (traj["vehicle_id"] == m.id).any()]
    return traj, ids, _colours(ids)


_MANEUVER_COLOURS = {"reshape": "#c6dbef", "lane_change": "#e5d8f0"}


def _mark_maneuvers(a: RunAnalysis, axes) -> None:
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
                ax.plot(*_dec(g["t"], _fl(g[name], "m")), color=col[mid], lw=1, label=mid)
        if _has(s, "e_norm"):
            axes[2].plot(*_dec(s["t"], _fl(s["e_norm"], "m")), color=col[mid], lw=1, label=mid)
        ts = a.members.loc[mid, "settling_time_s"]
        if ts is not None and np.isfinite(ts):
            axes[2].axvline(g["t"].iloc[0] + ts, color=col[mid], ls=":", lw=1)
    axes[2].axhspan(0, tol, color="#d9f2d9", zorder=0, label=f"settling band {tol:g} m")
    for ax, lab in zip(axes[:3], ("e_lon [m]", "e_lat [m]", "|e| [m]")):
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
        _floor_axis(ax, "m")
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(loc="upper right", fontsize=8, ncols=4)
    axes[0].set_title("Formation error in the virtual-car frame (dotted: settling time; "
                      f"below {RESOLUTION['m'] * 1e3:g} mm drawn as 0)")
    if len(a.shape):
        axes[3].plot(*_dec(a.shape["t"], a.shape["shape_error"]), color="k", lw=1)
    else:
        _not_recorded(axes[3], "shape error")
    axes[3].set(ylabel="shape error [m]", xlabel="t [s]")
    axes[3].grid(alpha=0.3)
    _mark_maneuvers(a, axes)
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
                y = g[act] if act == "v" else _fl(g[act], "rad/s")
                ax.plot(*_dec(g["t"], y), color=col[mid], lw=1.2, label=mid)
    axes[0].set(ylabel="v [m/s]", title="References (dashed, eqs 2.6, 2.8) vs response (solid)")
    axes[1].set(ylabel="yaw rate [rad/s]", xlabel="t [s]")
    _floor_axis(axes[1], "rad/s")
    for ax in axes:
        ax.grid(alpha=0.3)
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(loc="best", fontsize=8, ncols=4)
    _mark_maneuvers(a, axes)
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
            axes[1].plot(*_dec(g["t"], _fl(g["a_lon"], "m/s^2")), color=col[mid], lw=1, label=mid)
        if _has(s, "jerk_lat"):
            axes[2].plot(*_dec(s["t"], _fl(s["jerk_lat"], "m/s^3")), color=col[mid], lw=1)
        if _has(s, "jerk_lon"):
            axes[3].plot(*_dec(s["t"], _fl(s["jerk_lon"], "m/s^3")), color=col[mid], lw=1)
    lim = comfort.LON_ACC_COMFORT
    for y in (lim, -lim):
        axes[1].axhline(y, color="r", ls="--", lw=1)
    axes[0].set(ylabel="a_lat [m/s^2]",
                title="Lateral acceleration and the seed's comfort bands (section 3.1.2)")
    axes[0].legend(loc="upper right", fontsize=7, ncols=4)
    axes[1].set(ylabel="a_lon [m/s^2]",
                title=f"Longitudinal acceleration, comfort limit +/-{lim:g} m/s^2 (section 3.1.5)")
    axes[2].set(ylabel="jerk lat [m/s^3]")
    _floor_axis(axes[2], "m/s^3")
    _floor_axis(axes[3], "m/s^3")
    w = a.settings
    axes[3].set(ylabel="jerk lon [m/s^3]", xlabel="t [s]")
    axes[2].set_title(f"Jerk: Savitzky-Golay derivative, {w.jerk_window_s:g} s window, "
                      f"order {w.jerk_polyorder}")
    for ax in axes:
        ax.grid(alpha=0.3)
    _mark_maneuvers(a, axes)
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


def _background(a: RunAnalysis) -> pd.DataFrame | None:
    bg = a.data.tables.get("background")
    need = ("t", "vehicle_id", "x", "y", "heading", "v", "length", "width")
    if bg is None or not all(c in bg.columns for c in need):
        return None
    ids = {m.id for m in a.data.members}
    bg = bg.loc[~bg["vehicle_id"].astype(str).isin(ids)]
    num = ["t", "x", "y", "heading", "v", "length", "width", "s", "d", "lane_index"]
    out = pd.DataFrame({c: pd.to_numeric(bg[c], errors="coerce") for c in num
                        if c in bg.columns})
    out["vehicle_id"] = bg["vehicle_id"].astype(str).to_numpy()
    return out.dropna(subset=["t", "x", "y", "heading"])


def _is_road_run(a: RunAnalysis) -> bool:
    traj = a.data.trajectories
    ids = {m.id for m in a.data.members} | {VIRTUAL_CAR_ID}
    has_s = bool(np.isfinite(traj.loc[traj["vehicle_id"].isin(ids), "s"].to_numpy(float)).any())
    return has_s or _background(a) is not None


def spacetime_figure(analysis: RunAnalysis, path: str | Path) -> Path:
    """Traffic space-time diagram around the formation, one panel per lane.

    Background vehicles are points ``(t, s)`` coloured by speed; members are lines in
    their colours, drawn in the panel of the lane SUMO has them on (dotted elsewhere).

    Parameters
    ----------
    analysis : RunAnalysis
        Output of :func:`analysis.summary.compute_run` for a road run.
    path : str or Path
        PNG file to write.

    Returns
    -------
    Path
        The written file.
    """
    a = analysis
    traj, ids, col = _member_groups(a)
    bg = _background(a)
    lanes: list[float] = []
    if bg is not None and "lane_index" in bg.columns:
        lanes += [float(v) for v in bg["lane_index"].dropna().unique()]
    m_lane = traj.loc[traj["vehicle_id"].isin(ids), "lane_index"].to_numpy(float)
    lanes += [float(v) for v in np.unique(m_lane[np.isfinite(m_lane)])]
    lanes = sorted(set(lanes), reverse=True)[:6] or [math.nan]
    fig, axes = _new(len(lanes), h=2.3 if len(lanes) > 1 else 4.0)
    sc = None
    vmax = 1.0
    if bg is not None and "s" in bg.columns and bg["s"].notna().any():
        b = bg.dropna(subset=["s"])
        if len(b) > MAX_SCATTER:
            step = np.unique(b["t"].to_numpy())
            keep = step[::math.ceil(len(b) / MAX_SCATTER)]
            b = b.loc[b["t"].isin(keep)]
        vmax = max(1.0, float(np.nanmax(b["v"]))) if b["v"].notna().any() else 1.0
        for ax, lane in zip(axes, lanes):
            sub = b if not math.isfinite(lane) or "lane_index" not in b.columns \
                else b.loc[b["lane_index"] == lane]
            sc = ax.scatter(sub["t"], sub["s"], c=sub["v"], s=1.5, cmap="RdYlGn", vmin=0,
                            vmax=vmax, rasterized=True, linewidths=0)
    else:
        _not_recorded(axes[0], "background vehicles")
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        if not _has(g, "s"):
            continue
        t, s = g["t"].to_numpy(float), g["s"].to_numpy(float)
        li = g["lane_index"].ffill().bfill().to_numpy(float)
        for k, (ax, lane) in enumerate(zip(axes, lanes)):
            on = np.ones(t.size, bool) if not math.isfinite(lane) or not np.isfinite(li).any() \
                else li == lane
            ax.plot(*_dec(t, np.where(on, s, np.nan)), color=col[mid], lw=2.0,
                    label=mid if k == 0 else None)
            if len(lanes) > 1:
                ax.plot(*_dec(t, s), color=col[mid], lw=0.7, ls=":")
    for ax, lane in zip(axes, lanes):
        ax.set_ylabel("s [m]" if not math.isfinite(lane) else f"lane {int(lane)}\ns [m]")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    axes[0].set_title("Space-time diagram: background vehicles coloured by speed, members "
                      "as lines (solid in their lane, dotted elsewhere)")
    if ids:
        axes[0].legend(loc="upper left", fontsize=8, ncols=4)
    if sc is not None:
        fig.colorbar(sc, ax=list(axes), label="v [m/s]", shrink=0.9)
    return _save(fig, Path(path))


def _anim_window(a: RunAnalysis, t_all: np.ndarray) -> tuple[float, float]:
    st = a.settings
    t0, t1 = float(t_all.min()), float(t_all.max())
    dur = max(0.0, float(st.anim_duration_s))
    if st.anim_start_s is not None:
        start = float(st.anim_start_s)
    else:
        start = t0
        s = a.traffic.series if a.traffic is not None else None
        for col in ("clearance_bg_m", "clearance_m"):  # background first: the interaction
            if s is not None and len(s) and s[col].notna().any():
                start = float(s.loc[s[col].idxmin(), "t"]) - dur / 2
                break
    start = min(max(start, t0), max(t0, t1 - dur))
    return start, min(t1, start + dur)


def _polys(x, y, h, length, width):
    return traffic.rectangle_corners(x, y, h, length, width)


def birdseye_animation(analysis: RunAnalysis, path: str | Path) -> Path:
    """Bird's-eye animation of the formation among the background vehicles.

    The window moves with the virtual car (its frame: x ahead, y to the left;
    :data:`BIRDSEYE_BEHIND_M` to :data:`BIRDSEYE_AHEAD_M`); vehicles are their outline
    rectangles with heading, members coloured, background grey (trucks darker). Length,
    frame rate and start come from the settings (``anim_duration_s``, ``anim_fps``,
    ``anim_start_s``; by default the window is centred on the members' closest approach
    to a background vehicle, or to each other without background). Dashed lane lines
    lie halfway between the median ``d`` of the lanes seen in the window (members and
    background; exact on straight roads).

    Parameters
    ----------
    analysis : RunAnalysis
        Output of :func:`analysis.summary.compute_run` (virtual-car rows needed).
    path : str or Path
        Target file ending in ``.gif``. Without pillow a strip of
        :data:`BIRDSEYE_STRIP_FRAMES` frames is written as a PNG next to it instead
        (same name, ``.png``).

    Returns
    -------
    Path
        The written file (GIF, or the PNG strip).

    Raises
    ------
    ValueError
        Without virtual-car poses (the window cannot follow it).
    """
    a = analysis
    path = Path(path)
    st = a.settings
    traj, ids, col = _member_groups(a)
    dt = a.data.dt
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, ["t", "x", "y", "heading"]].dropna()
    if vc.empty:
        raise ValueError("no virtual-car pose: the bird's-eye window cannot follow it")
    vc = vc.assign(key=time_keys(vc["t"], dt)).drop_duplicates("key").set_index("key")
    start, stop = _anim_window(a, vc["t"].to_numpy(float))
    fps = float(st.anim_fps) if st.anim_fps and st.anim_fps > 0 else 5.0
    n_frames = max(1, int(math.floor((stop - start) * fps + 1e-9)) + 1)
    frame_keys = np.unique(time_keys(start + np.arange(n_frames) / fps, dt))
    frame_keys = frame_keys[np.isin(frame_keys, vc.index.to_numpy())]
    if frame_keys.size == 0:
        raise ValueError("no virtual-car pose in the animation window")
    fp = traffic.member_footprint(a.data.meta.get("scenario"), a.data.meta.get("members"))[0]
    M = member_rows(a.data, fp, dt)
    M = M.loc[M["key"].isin(frame_keys)]
    bg = _background(a)
    B = pd.DataFrame(columns=["key", "x", "y", "heading", "length", "width"])
    if bg is not None:
        bg = bg.assign(key=time_keys(bg["t"], dt))
        B = bg.loc[bg["key"].isin(frame_keys)]
        xv, yv, hv = (vc[c].reindex(B["key"].to_numpy()).to_numpy(float)
                      for c in ("x", "y", "heading"))
        along = np.cos(hv) * (B["x"].to_numpy(float) - xv) + np.sin(hv) * (
            B["y"].to_numpy(float) - yv)
        B = B.loc[np.abs(along) <= max(BIRDSEYE_AHEAD_M, BIRDSEYE_BEHIND_M) + 15.0]
    m_by, b_by = dict(list(M.groupby("key"))), dict(list(B.groupby("key")))
    lat_m = []
    for mid in ids:
        off = next((m.offset[1] for m in a.data.members if m.id == mid), math.nan)
        if math.isfinite(off):
            lat_m.append(off)
    lo, hi = (min(lat_m), max(lat_m)) if lat_m else (0.0, 0.0)
    y_lo, y_hi = lo - 7.0, hi + 7.0
    lane_d: list[float] = []
    seen = pd.concat([B[["d", "lane_index"]] if {"d", "lane_index"} <= set(B.columns)
                      else None, M[["d", "lane_index"]]])
    if len(seen):
        med = seen.dropna().groupby("lane_index")["d"].median()
        centres = np.sort(med.to_numpy(float))
        if centres.size:
            w = float(np.median(np.diff(centres))) if centres.size > 1 else 3.5
            lane_d = list(np.concatenate(([centres[0] - w / 2], (centres[1:] + centres[:-1])
                                          / 2, [centres[-1] + w / 2])))
            y_lo, y_hi = min(y_lo, lane_d[0] - 1.0), max(y_hi, lane_d[-1] + 1.0)
    span = BIRDSEYE_AHEAD_M + BIRDSEYE_BEHIND_M
    fig = Figure(figsize=(10.0, max(1.6, 10.0 * (y_hi - y_lo) / span) + 0.5))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.06, 0.18, 0.92, 0.70))
    ax.set_xlim(-BIRDSEYE_BEHIND_M, BIRDSEYE_AHEAD_M)
    ax.set_ylim(y_lo, y_hi)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("along the virtual car [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    for yl in lane_d:
        ax.axhline(yl, color="0.6", lw=0.8, ls="--", zorder=0)
    ax.plot([0], [0], "k+", ms=8, zorder=3)
    bg_pc = PolyCollection([], facecolors="0.75", edgecolors="0.35", linewidths=0.6, zorder=1)
    m_pc = PolyCollection([], edgecolors="k", linewidths=0.8, zorder=2)
    ax.add_collection(bg_pc)
    ax.add_collection(m_pc)
    ax.set_title("virtual car +, window moving with it; trucks dark grey", fontsize=8,
                 loc="right")
    title = ax.text(0.5, 1.02, "", transform=ax.transAxes, fontsize=9, ha="center",
                    va="bottom")
    if ids:
        from matplotlib.patches import Patch

        ax.legend(handles=[Patch(facecolor=col[m], edgecolor="k", label=m) for m in ids],
                  loc="lower left", bbox_to_anchor=(0.0, 1.0), ncols=min(len(ids), 8),
                  fontsize=7, frameon=False, borderaxespad=0.1, handlelength=1.2)
    vc_x, vc_y, vc_h, vc_t = (vc[c].to_dict() for c in ("x", "y", "heading", "t"))

    def draw(k: int) -> None:
        xv, yv, hv, tv = vc_x[k], vc_y[k], vc_h[k], vc_t[k]
        c, s = math.cos(hv), math.sin(hv)

        def local(df: pd.DataFrame) -> np.ndarray:
            if df is None or df.empty:
                return np.zeros((0, 4, 2))
            cr = _polys(df["x"], df["y"], df["heading"], df["length"], df["width"])
            dx, dy = cr[..., 0] - xv, cr[..., 1] - yv
            return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)

        b = b_by.get(k)
        bg_pc.set_verts(list(local(b)))
        bg_pc.set_facecolor(["0.55" if ln > 7.0 else "0.8" for ln in
                             (b["length"] if b is not None else [])])
        m = m_by.get(k)
        mv = local(m)
        m_pc.set_verts(list(mv))
        m_pc.set_facecolor([col[i] for i in (m["vehicle_id"] if m is not None else [])])
        title.set_text(f"t = {tv:.2f} s")

    for art in (bg_pc, m_pc, title):
        art.set_animated(True)  # drawn per frame over the cached static background

    def render(k: int) -> np.ndarray:
        fig.canvas.restore_region(static)
        draw(k)
        for art in (bg_pc, m_pc, title):
            ax.draw_artist(art)
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()

    fig.set_dpi(BIRDSEYE_DPI)
    fig.canvas.draw()
    static = fig.canvas.copy_from_bbox(fig.bbox)
    if importlib.util.find_spec("PIL") is None:
        strip = path.with_suffix(".png")
        picks = frame_keys[np.linspace(0, frame_keys.size - 1,
                                       min(BIRDSEYE_STRIP_FRAMES, frame_keys.size)).astype(int)]
        images = [render(int(k)) for k in picks]
        sfig = Figure(figsize=(10.0, 10.0 * sum(i.shape[0] for i in images)
                               / images[0].shape[1] + 0.4))
        FigureCanvasAgg(sfig)
        sax = sfig.add_axes((0, 0, 1, 0.97))
        sax.imshow(np.concatenate(images, axis=0))
        sax.set_axis_off()
        sfig.suptitle("pillow not installed: frames of the animation instead", fontsize=9)
        return _save(sfig, strip)
    from PIL import Image  # pillow: matplotlib's PillowWriter backend, imported lazily

    frames = [Image.fromarray(render(int(k))).quantize(colors=64,
                                                       method=Image.Quantize.FASTOCTREE)
              for k in frame_keys]
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=int(1000 / fps),
                   loop=0, optimize=False)
    return path


def _has_comm(a: RunAnalysis) -> bool:
    """A run whose members held virtual-car states of more than one age ([comm])."""
    age = pd.to_numeric(a.data.trajectories.get("leader_age_s"), errors="coerce")
    return age is not None and bool((age.fillna(0.0) > 0.0).any())


def comm_figure(a: RunAnalysis, path: Path) -> Path:
    """Age of the virtual-car state each member held over time, and the r.m.s. formation
    error and longitudinal acceleration per age bin (analysis/comm.py)."""
    traj, ids, col = _member_groups(a)
    fig, axes = _new(3, sharex=False)
    bins = a.comm_age if a.comm_age is not None else pd.DataFrame()
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        axes[0].plot(*_dec(g["t"], g["leader_age_s"]), color=col[mid], lw=1, label=mid)
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
    return _save(fig, path)


def _propagation(a: RunAnalysis, path: Path) -> Path:
    """Members at their slots, coloured by peak error, with the neighbour-to-neighbour peak
    error ratios along columns (front to back) and rows (outwards from the most disturbed)."""
    from analysis.propagation import propagation

    off = {m.id: m.offset for m in a.data.members if np.isfinite(m.offset).all()
           and m.id in a.members.index}
    peak = {m: _num(a.members.loc[m, "e_max_m"]) for m in off}
    rms = {m: _num(a.members.loc[m, "e_rms_m"]) for m in off}
    fig, axes = _new(1, h=4.2, w=7.0)
    ax = axes[0]
    if not off:
        _not_recorded(ax, "member offsets")
        return _save(fig, path)
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
    return _save(fig, path)


def _num(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


_RUN_FIGURES = (("paths", _paths), ("errors", _errors), ("propagation", _propagation),
                ("tracking", _tracking), ("comfort", _comfort), ("limits", _limits))
_TRAFFIC_FIGURES = (("traffic_spacetime", spacetime_figure, ".png"),
                    ("traffic_birdseye", birdseye_animation, ".gif"))


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
    if _is_road_run(analysis):
        for name, fn, ext in _TRAFFIC_FIGURES:
            try:
                written[name] = fn(analysis, out / f"{name}{ext}")
            except Exception as exc:  # noqa: BLE001
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
