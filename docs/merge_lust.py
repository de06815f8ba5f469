"""The LuST table of docs/maneuvers.md "The merge study": the scenario of tests/test_merge_lust.py
(the LuST motorway's on-ramp joining -31622#4, ../shared/realnet; 1,200 veh/h/lane, the
formation from s = 1,400 m at 26 m/s, 40 s after 30 s of warm-up) for both shapes, 600 and 900
veh/h on the ramp, merge "none", "open_gap" and "shift", seeds 1-3 (36 runs of ~5 s):

    python docs/merge_lust.py runs/merge_lust

Runs already in the directory are read, not run again. Over the ramp vehicles seen near the
join (run.json ``merges``) and the formation's incidents (run.json ``incidents``): mean
[Student-t 95 % interval] over the seeds, the speed loss also paired by seed against none."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent / "tests")]
from merge_study import interval  # noqa: E402
from test_merge_lust import scenario  # noqa: E402

MODES = ("none", "open_gap", "shift")


def run_all(out: Path) -> pd.DataFrame:
    from formation_traci.runner import run_scenario
    from formation_traci.scenario import load_scenario

    rows = []
    for shape in ("abreast", "column"):
        for ramp in (600, 900):
            for mode in MODES:
                for seed in (1, 2, 3):
                    d = out / f"{shape}-{ramp}-{mode}-s{seed}"
                    if not (d / "run" / "run.json").is_file():
                        d.mkdir(parents=True, exist_ok=True)
                        text = scenario(shape, mode, seed).replace("veh_per_hour = 900", f"veh_per_hour = {ramp}")
                        (d / "s.toml").write_text(text)
                        run_scenario(load_scenario(d / "s.toml"), d / "run", scenario_path=d / "s.toml",
                                     progress=False, force=True)
                    meta = json.loads((d / "run" / "run.json").read_text())
                    seen, inc = meta["merges"]["by_formation"]["f0"], meta["incidents"]
                    rows.append({"shape": shape, "ramp": ramp, "merge": mode, "seed": seed,
                                 "ramp_vehicles": seen["ramp_vehicles"], "loss": seen["ramp_speed_loss_mps"],
                                 "emergency_brakes": inc["emergency_brakes"],
                                 "member_collisions": inc["member_collisions"],
                                 "member_removed": inc["member_removed"]})
    df = pd.DataFrame(rows)
    none = df[df["merge"] == "none"].set_index(["shape", "ramp", "seed"])["loss"]
    df["loss_vs_none"] = df["loss"].to_numpy() - none.reindex(
        pd.MultiIndex.from_frame(df[["shape", "ramp", "seed"]])).to_numpy()
    return df


def cell(x: pd.Series) -> str:
    m, lo, hi, _ = (0.0 if isinstance(v, float) and abs(v) < 0.005 else v for v in interval(x))
    return f"{m:.2f}" if not np.isfinite(lo) or np.isclose(lo, hi) else f"{m:.2f} [{lo:.2f}, {hi:.2f}]"


def markdown(df: pd.DataFrame) -> str:
    out = ["| formation | ramp | merge | ramp vehicles | ramp speed loss [m/s] | minus none (paired) [m/s] "
           "| emergency brakes | member collisions | runs with incidents |",
           "|---|---|---|---|---|---|---|---|---|"]
    for (shape, ramp), g0 in df.groupby(["shape", "ramp"]):
        for mode in MODES:
            g = g0[g0["merge"] == mode]
            bad = int(((g["emergency_brakes"] > 0) | (g["member_collisions"] > 0)).sum())
            diff = "-" if mode == "none" else cell(g["loss_vs_none"])
            out.append(f"| {shape} | {ramp} veh/h | {mode} | {int(g['ramp_vehicles'].sum())} | {cell(g['loss'])} "
                       f"| {diff} | {cell(g['emergency_brakes'])} | {cell(g['member_collisions'])} "
                       f"| {bad} of {len(g)} |")
    return "\n".join(out)


def main(argv: list[str]) -> int:
    df = run_all(Path(argv[0]))
    pd.set_option("display.width", 200)
    print(df.round(3).to_string(index=False))
    print()
    print(markdown(df))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
