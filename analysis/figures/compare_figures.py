"""Several runs overlaid on the same axes, one colour per run: member paths (world and
virtual-car frame) and the main signals.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from analysis.figures.figure_kit import (LINESTYLES, decimate, has_values, member_colours,
                                         member_groups, new_figure, save_png, vc_frame_position)
from analysis.metrics import comfort
from analysis.runs.summary import RunAnalysis
from run_contract.columns import VIRTUAL_CAR_ID

__all__ = ["compare_figures"]


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
    colours = member_colours(list(analyses))
    for name, draw in (("compare_paths", _compare_paths), ("compare_signals", _compare_signals)):
        try:
            written[name] = draw(analyses, colours, out / f"{name}.png")
        except Exception as exc:  # noqa: BLE001 - report, keep drawing the others
            failed[name] = f"{type(exc).__name__}: {exc}"
    return written, failed


def _compare_paths(analyses: Mapping[str, RunAnalysis], colours: dict[str, str],
                   path: Path) -> Path:
    """Member paths per run, in the world and in the virtual-car frame."""
    fig, axes = new_figure(2, h=3.6, sharex=False)
    ax = axes[0]
    for r, (label, a) in enumerate(analyses.items()):
        traj, ids, _ = member_groups(a)
        lw = max(0.8, 2.4 - 0.6 * r)  # earlier runs wider: overlapping runs stay visible
        for k, mid in enumerate(ids):
            g = traj.loc[traj["vehicle_id"] == mid]
            if has_values(g, "x", "y"):
                ax.plot(*decimate(g["x"], g["y"]), color=colours[label], lw=lw,
                        ls=LINESTYLES[k % len(LINESTYLES)],
                        label=label if k == 0 else None)
            rel = vc_frame_position(traj, mid)
            if rel is not None:
                axes[1].plot(*decimate(*rel), color=colours[label], lw=lw,
                             ls=LINESTYLES[k % len(LINESTYLES)],
                             label=label if k == 0 else None)
                axes[1].annotate(mid, (rel[0][-1], rel[1][-1]), fontsize=8)
        vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID]
        if has_values(vc, "x", "y"):
            ax.plot(*decimate(vc["x"], vc["y"]), color=colours[label], lw=0.6, alpha=0.6)
    ax.set(xlabel="x [m]", ylabel="y [m]",
           title="Member paths per run (line style = member, thin = virtual car); "
                 "axes not to scale")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    axes[1].set_aspect("equal", adjustable="datalim")
    axes[1].set(title="Members in the virtual-car frame",
                xlabel="along the virtual-car heading [m]", ylabel="left of it [m]")
    axes[1].grid(alpha=0.3)
    return save_png(fig, path)


def _compare_signals(analyses: Mapping[str, RunAnalysis], colours: dict[str, str],
                     path: Path) -> Path:
    """Formation error, speed, yaw rate and lateral acceleration of every run overlaid."""
    fig, axes = new_figure(4)
    rows = (("e_norm", "|e| [m]", True), ("v", "v [m/s]", False),
            ("yaw_rate", "yaw rate [rad/s]", False), ("a_lat", "a_lat [m/s^2]", False))
    for label, a in analyses.items():
        traj, ids, _ = member_groups(a)
        for k, mid in enumerate(ids):
            g = traj.loc[traj["vehicle_id"] == mid]
            s = a.signals.loc[a.signals["vehicle_id"] == mid]
            for ax, (name, _, from_signals) in zip(axes, rows):
                src = s if from_signals else g
                if has_values(src, name):
                    ax.plot(*decimate(src["t"], src[name]), color=colours[label], lw=1,
                            ls=LINESTYLES[k % len(LINESTYLES)],
                            label=label if k == 0 else None)
    for ax, (_, lab, _) in zip(axes, rows):
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    for y in (comfort.LAT_ACC_MEDIUM, -comfort.LAT_ACC_MEDIUM):
        axes[3].axhline(y, color="r", ls="--", lw=0.8)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title("Runs overlaid (colour = run, line style = member)")
    axes[3].set_xlabel("t [s]")
    return save_png(fig, path)
