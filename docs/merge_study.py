"""The figure and table of docs/maneuvers.md "The merge study" from runs of
scenarios/studies/merge.toml (three abreast) and scenarios/studies/merge_column.toml (a 3-car
column in the merge lane):

    formation-traci sweep scenarios/studies/merge.toml --out runs/merge --workers 1
    formation-traci sweep scenarios/studies/merge_column.toml --out runs/merge_column --workers 1
    python docs/merge_study.py runs/merge runs/merge_column

and the twenty-seed studies of the speed loss at 900 veh/h (scenarios/studies/merge_seeds.toml,
merge_column_seeds.toml, no twins):

    python docs/merge_study.py --figure merge_seeds.png runs/merge_seeds runs/merge_column_seeds

Per formation shape, ramp demand and cooperation mode, over the study's seeds: the ramp
vehicles' mean speed loss (each seen ramp vehicle's first speed less its lowest while the
formation was near the join, run.json ``merges``), the same paired by seed against ``none``
(mode minus none, the same traffic), their mean wait, the share that merged before the end of
the acceleration lane, and the formation's emergency brakes and member collisions (run.json
``incidents``), as mean [Student-t 95 % interval] over the seeds; the figure shows the speed
loss and the emergency brakes."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
from scipy import stats

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLUMNS = {"ramp_speed_loss_mps": "ramp speed loss [m/s]", "loss_vs_none": "speed loss minus none [m/s]",
           "ramp_wait_s": "ramp wait [s]", "merged_share": "merged before the lane end [-]",
           "emergency_brakes": "emergency brakes [-]", "member_collisions": "member collisions [-]"}
MODES = ("none", "open_gap", "shift")
SHAPES = {"onramp_merge": "abreast", "onramp_column": "column"}
"""The studies' base scenarios -> the formation's shape."""


def interval(x: pd.Series) -> tuple[float, float, float, int]:
    """Mean, lower and upper Student-t 95 % bounds over the seeds, and their count."""
    x = x.dropna().astype(float)
    n = len(x)
    m = float(x.mean()) if n else float("nan")
    if n < 2:
        return m, float("nan"), float("nan"), n
    h = float(stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / np.sqrt(n))
    return m, m - h, m + h, n


def cases(sweep: Path) -> pd.DataFrame:
    """One sweep's finished cases with its shape, demand and mode, and the paired difference."""
    df = pd.read_parquet(sweep / "summary.parquet")
    meta = json.loads((sweep / "sweep.json").read_text())
    base = Path(meta["base"]).stem
    if "traffic.flows.1.veh_per_hour" not in df:  # one ramp demand, set in the study's [overrides]
        df["traffic.flows.1.veh_per_hour"] = float(meta["sweep"]["overrides"]["traffic.flows.1.veh_per_hour"])
    df = df[df["status"].isin(["completed", "completed_with_incidents"])].copy()
    df = df.rename(columns={"traffic.flows.1.veh_per_hour": "ramp_veh_h", "cooperation.merge": "merge"})
    df["shape"] = SHAPES.get(base, base)
    df["merged_share"] = df["ramp_merged_before_lane_end"] / df["ramp_vehicles"]
    none = df[df["merge"] == "none"].set_index(["ramp_veh_h", "seed"])["ramp_speed_loss_mps"]
    key = pd.MultiIndex.from_frame(df[["ramp_veh_h", "seed"]])
    df["loss_vs_none"] = df["ramp_speed_loss_mps"].to_numpy() - none.reindex(key).to_numpy()
    return df


def table(sweeps: list[Path]) -> pd.DataFrame:
    df = pd.concat([cases(s) for s in sweeps], ignore_index=True)
    rows = []
    for (shape, demand, mode), g in df.groupby(["shape", "ramp_veh_h", "merge"], sort=False):
        row = {"shape": shape, "ramp_veh_h": demand, "merge": mode,
               "ramp_vehicles": int(g["ramp_vehicles"].sum()), "seeds": len(g)}
        for col in COLUMNS:
            m, lo, hi, _ = interval(g[col])
            row.update({col: m, f"{col}_lo": lo, f"{col}_hi": hi})
        rows.append(row)
    t = pd.DataFrame(rows)
    t["merge"] = pd.Categorical(t["merge"], MODES)
    return t.sort_values(["shape", "ramp_veh_h", "merge"]).reset_index(drop=True)


def markdown(t: pd.DataFrame) -> str:
    """The table of docs/maneuvers.md (mean [95 % interval]; the interval left out where the
    seeds agree)."""
    def cell(r, col, fmt="{:.2f}"):
        m, lo, hi = (0.0 if abs(v) < 0.005 else v for v in (r[col], r[f"{col}_lo"], r[f"{col}_hi"]))
        if not np.isfinite(m):
            return "-"
        if not np.isfinite(lo) or np.isclose(lo, hi):
            return fmt.format(m)
        return f"{fmt.format(m)} [{fmt.format(lo)}, {fmt.format(hi)}]"
    out = ["| formation | ramp | merge | seeds | ramp vehicles | ramp speed loss [m/s] | minus none (paired) [m/s] "
           "| merged before the lane end | emergency brakes | member collisions |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for _, r in t.iterrows():
        diff = "-" if r["merge"] == "none" else cell(r, "loss_vs_none")
        out.append(f"| {r['shape']} | {int(r['ramp_veh_h'])} veh/h | {r['merge']} | {r['seeds']} | {r['ramp_vehicles']} "
                   f"| {cell(r, 'ramp_speed_loss_mps')} | {diff} | {cell(r, 'merged_share')} "
                   f"| {cell(r, 'emergency_brakes')} | {cell(r, 'member_collisions')} |")
    return "\n".join(out)


def figure(t: pd.DataFrame, out: Path) -> None:
    shapes = list(dict.fromkeys(t["shape"]))
    fig, axes = plt.subplots(len(shapes), 2, figsize=(9.5, 3.2 * len(shapes)), squeeze=False)
    w = 0.26
    for i, shape in enumerate(shapes):
        for ax, col in zip(axes[i], ("ramp_speed_loss_mps", "emergency_brakes")):
            for k, mode in enumerate(MODES):
                g = t[(t["shape"] == shape) & (t["merge"] == mode)].sort_values("ramp_veh_h")
                if g.empty:
                    continue
                x = np.arange(len(g)) + (k - 1) * w
                err = np.vstack([g[col] - g[f"{col}_lo"], g[f"{col}_hi"] - g[col]])
                ax.bar(x, g[col], w, yerr=np.nan_to_num(err), capsize=3, label=mode)
                ax.set_xticks(np.arange(len(g)), [f"ramp {int(d)} veh/h" for d in g["ramp_veh_h"]])
            ax.set_ylabel(COLUMNS[col])
            ax.set_title(f"{shape}: mean over {int(t['seeds'].min())} seeds, 95 % interval", fontsize=9)
        axes[i][0].legend(title="merge", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def main(argv: list[str]) -> int:
    name = "merge_study.png"
    if argv[:1] == ["--figure"]:  # another figure's file name under docs/img
        name, argv = argv[1], argv[2:]
    t = table([Path(a) for a in argv])
    pd.set_option("display.width", 200)
    cols = ["shape", "ramp_veh_h", "merge", "ramp_vehicles", "seeds"] + [
        c for k in COLUMNS for c in (k, f"{k}_lo", f"{k}_hi")]
    print(t[cols].round(2).to_string(index=False))
    print()
    print(markdown(t))
    figure(t, Path(__file__).parent / "img" / name)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
