"""Regenerate docs/img/platoon_string_amplification.png and the table of docs/platoon_laws.md
from real runs of the bundled string-stability scenarios (scenarios/platoon/, free space, about
half a minute in all):

    python docs/platoon_figures.py

Each scenario runs at full length into a temporary directory; the ratio is metrics.json's
formation-level ``string_amplification`` (analysis/metrics/platoon.py), the smallest gap is taken
from the recorded positions (bumper to bumper, 4.6 m cars).
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from analysis.api import analyze_run  # noqa: E402
from formation_traci.scenario import load_scenario  # noqa: E402
from formation_traci.runner import run_scenario  # noqa: E402

CASES = [f"{kind}_{law}" for kind in ("sinusoid", "braking")
         for law in ("virtual_structure", "acc", "cacc_path", "cacc_ploeg")] + ["sinusoid_acc_short_gap"]
LENGTH_M = 4.6


def measure(name: str, tmp: Path) -> dict:
    out = tmp / name
    res = run_scenario(load_scenario(ROOT / "scenarios" / "platoon" / f"{name}.toml"), out,
                       force=True, progress=False)
    doc = json.loads(analyze_run(out, tmp / f"{name}.a", figures=False)
                     .files["metrics_json"].read_text())
    x = pd.read_parquet(out / "trajectories.parquet").pivot(index="t", columns="vehicle_id",
                                                            values="x")
    ids = [f"p{i}" for i in range(8)]
    gap = min(float((x[ids[i - 1]] - x[ids[i]]).min()) - LENGTH_M for i in range(1, 8))
    return {"case": name, "status": res.status,
            "string_amplification": doc["formations"][0]["string_amplification"],
            "min_gap_m": gap}


def main() -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    with tempfile.TemporaryDirectory() as d:
        rows = [measure(c, Path(d)) for c in CASES]
    df = pd.DataFrame(rows)
    print(df.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    fig, ax = plt.subplots(figsize=(8, 3.6))
    colors = ["C0" if r <= 1.0 else "C3" for r in df.string_amplification]
    ax.barh(df.case, df.string_amplification, color=colors)
    ax.axvline(1.0, color="k", lw=1, ls="--")
    ax.set_xscale("log")
    ax.set_xlabel("string amplification: peak |v_8 - v_7| / peak |v_2 - v_1|  [-]  (<= 1: string stable)")
    ax.invert_yaxis()
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "img" / "platoon_string_amplification.png", dpi=120)


if __name__ == "__main__":
    main()
