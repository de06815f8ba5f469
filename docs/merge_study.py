"""The figure and table of docs/maneuvers.md "The merge study" from a run of
scenarios/studies/merge.toml:

    formation-traci sweep scenarios/studies/merge.toml --out runs/merge --workers 2
    python docs/merge_study.py runs/merge

Per ramp demand and cooperation mode, over the study's seeds: the ramp vehicles' mean speed loss
and wait, the share that merged before the end of the acceleration lane (run.json ``merges``),
and the formation's emergency brakes (run.json ``incidents``), as mean [Student-t 95 % interval]
over the seeds; the figure shows the speed loss and the emergency brakes."""
from __future__ import annotations

import sys
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
from scipy import stats

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLUMNS = {"ramp_speed_loss_mps": "ramp speed loss [m/s]", "ramp_wait_s": "ramp wait [s]",
           "merged_share": "merged before the lane end [-]", "emergency_brakes": "emergency brakes [-]"}


def interval(x: pd.Series) -> tuple[float, float, float, int]:
    """Mean, lower and upper Student-t 95 % bounds over the seeds, and their count."""
    x = x.dropna().astype(float)
    n = len(x)
    m = float(x.mean()) if n else float("nan")
    if n < 2:
        return m, float("nan"), float("nan"), n
    h = float(stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / np.sqrt(n))
    return m, m - h, m + h, n


def table(sweep: Path) -> pd.DataFrame:
    df = pd.read_parquet(sweep / "summary.parquet")
    df = df[df["status"].isin(["completed", "completed_with_incidents"])].copy()
    df = df.rename(columns={"traffic.flows.1.veh_per_hour": "ramp_veh_h", "cooperation.merge": "merge"})
    df["merged_share"] = df["ramp_merged_before_lane_end"] / df["ramp_vehicles"]
    rows = []
    for (demand, mode), g in df.groupby(["ramp_veh_h", "merge"]):
        row = {"ramp_veh_h": demand, "merge": mode}
        for col in COLUMNS:
            m, lo, hi, n = interval(g[col])
            row.update({col: m, f"{col}_lo": lo, f"{col}_hi": hi})
        row["seeds"] = n
        rows.append(row)
    return pd.DataFrame(rows)


def figure(t: pd.DataFrame, out: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    for ax, col in zip(axes, ("ramp_speed_loss_mps", "emergency_brakes")):
        for k, mode in enumerate(("none", "open_gap")):
            g = t[t["merge"] == mode].sort_values("ramp_veh_h")
            x = np.arange(len(g)) + (k - 0.5) * 0.35
            err = np.vstack([g[col] - g[f"{col}_lo"], g[f"{col}_hi"] - g[col]])
            ax.bar(x, g[col], 0.35, yerr=np.nan_to_num(err), capsize=3, label=mode)
            ax.set_xticks(np.arange(len(g)), [f"{int(d)} veh/h" for d in g["ramp_veh_h"]])
        ax.set_ylabel(COLUMNS[col])
        ax.set_title(f"mean over {int(t['seeds'].min())} seeds, 95 % interval", fontsize=9)
    axes[0].legend(title="merge")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def main(argv: list[str]) -> int:
    sweep = Path(argv[0])
    t = table(sweep)
    pd.set_option("display.width", 160)
    print(t.round(2).to_string(index=False))
    figure(t, Path(__file__).parent / "img" / "merge_study.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
