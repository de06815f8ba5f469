"""Traffic figures of a road run: the space-time diagram per lane and the bird's-eye
animation of the formation among the background vehicles.
"""
from __future__ import annotations

import importlib.util
import io
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from analysis.figures.figure_kit import (decimate, has_values, mark_not_recorded, member_groups,
                                         new_figure, save_png)
from analysis.metrics import traffic
from analysis.runs.summary import RunAnalysis
from analysis.runs.traffic_run import member_rows, time_keys
from run_contract.columns import VIRTUAL_CAR_ID
from run_contract.rundir import atomic_write_bytes

__all__ = ["MAX_SCATTER", "BIRDSEYE_AHEAD_M", "BIRDSEYE_BEHIND_M", "BIRDSEYE_STRIP_FRAMES",
           "BIRDSEYE_DPI", "spacetime_figure", "birdseye_animation"]

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


def is_road_run(a: RunAnalysis) -> bool:
    """True when the members or the virtual car have Frenet ``s`` or the run has background
    vehicles (a road run in SUMO)."""
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
        Output of :func:`analysis.runs.summary.compute_run` for a road run.
    path : str or Path
        PNG file to write.

    Returns
    -------
    Path
        The written file.
    """
    a = analysis
    traj, ids, col = member_groups(a)
    bg = _background(a)
    lanes: list[float] = []
    if bg is not None and "lane_index" in bg.columns:
        lanes += [float(v) for v in bg["lane_index"].dropna().unique()]
    m_lane = traj.loc[traj["vehicle_id"].isin(ids), "lane_index"].to_numpy(float)
    lanes += [float(v) for v in np.unique(m_lane[np.isfinite(m_lane)])]
    lanes = sorted(set(lanes), reverse=True)[:6] or [math.nan]
    fig, axes = new_figure(len(lanes), h=2.3 if len(lanes) > 1 else 4.0)
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
        mark_not_recorded(axes[0], "background vehicles")
    for mid in ids:
        g = traj.loc[traj["vehicle_id"] == mid]
        if not has_values(g, "s"):
            continue
        t, s = g["t"].to_numpy(float), g["s"].to_numpy(float)
        li = g["lane_index"].ffill().bfill().to_numpy(float)
        for k, (ax, lane) in enumerate(zip(axes, lanes)):
            on = np.ones(t.size, bool) if not math.isfinite(lane) or not np.isfinite(li).any() \
                else li == lane
            ax.plot(*decimate(t, np.where(on, s, np.nan)), color=col[mid], lw=2.0,
                    label=mid if k == 0 else None)
            if len(lanes) > 1:
                ax.plot(*decimate(t, s), color=col[mid], lw=0.7, ls=":")
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
    return save_png(fig, Path(path))


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
        Output of :func:`analysis.runs.summary.compute_run` (virtual-car rows needed).
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
    path = Path(path)
    d = _birdseye_data(analysis)
    fps = float(analysis.settings.anim_fps) if analysis.settings.anim_fps and \
        analysis.settings.anim_fps > 0 else 5.0
    render = _birdseye_renderer(d)
    if importlib.util.find_spec("PIL") is None:
        return _birdseye_strip(render, d.frame_keys, path.with_suffix(".png"))
    from PIL import Image  # pillow: matplotlib's PillowWriter backend, imported lazily

    frames = [Image.fromarray(render(int(k))).quantize(colors=64,
                                                       method=Image.Quantize.FASTOCTREE)
              for k in d.frame_keys]
    buf = io.BytesIO()
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], duration=int(1000 / fps),
                   loop=0, optimize=False)
    atomic_write_bytes(path, buf.getvalue())  # never a truncated GIF, never through a link
    return path


class _Birdseye(NamedTuple):
    """What the bird's-eye frames show: virtual-car poses by time key, the frames' keys,
    members' and background rows per key, members and colours, lane lines and y range."""

    vc: pd.DataFrame  # index key, columns t, x, y, heading
    frame_keys: np.ndarray
    m_by: dict
    b_by: dict
    ids: list
    col: dict
    lane_d: list  # m, lane lines across the road
    y_lo: float  # m
    y_hi: float  # m


def _birdseye_data(a: RunAnalysis) -> _Birdseye:
    """Rows of the animation window: the frames, the vehicles in them, the lanes."""
    st = a.settings
    traj, ids, col = member_groups(a)
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
    meta = a.data.meta
    fp = (traffic.member_footprints(meta.get("scenario"), meta.get("members"))
          or traffic.member_footprint(meta.get("scenario"), meta.get("members"))[0])
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
    lane_d, y_lo, y_hi = _lane_lines(a, ids, M, B)
    return _Birdseye(vc, frame_keys, m_by, b_by, ids, col, lane_d, y_lo, y_hi)


def _lane_lines(a: RunAnalysis, ids: list, M: pd.DataFrame,
                B: pd.DataFrame) -> tuple[list, float, float]:
    """Lane lines halfway between the median ``d`` of the lanes seen [m], and the y range
    shown [m] (the members' slots and the lanes, with a margin)."""
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
    return lane_d, y_lo, y_hi


def _birdseye_renderer(d: _Birdseye):
    """The static figure (drawn once) and a function drawing frame ``k`` over it to RGB."""
    ids, col = d.ids, d.col
    span = BIRDSEYE_AHEAD_M + BIRDSEYE_BEHIND_M
    fig = Figure(figsize=(10.0, max(1.6, 10.0 * (d.y_hi - d.y_lo) / span) + 0.5))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.06, 0.18, 0.92, 0.70))
    ax.set_xlim(-BIRDSEYE_BEHIND_M, BIRDSEYE_AHEAD_M)
    ax.set_ylim(d.y_lo, d.y_hi)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("along the virtual car [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    for yl in d.lane_d:
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
    vc_x, vc_y, vc_h, vc_t = (d.vc[c].to_dict() for c in ("x", "y", "heading", "t"))
    m_by, b_by = d.m_by, d.b_by

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
    return render


def _birdseye_strip(render, frame_keys: np.ndarray, strip: Path) -> Path:
    """PNG strip of :data:`BIRDSEYE_STRIP_FRAMES` frames (without pillow)."""
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
    return save_png(sfig, strip)
