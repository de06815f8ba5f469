"""The table of docs/platoon_laws.md "On a curved motorway" from a run of
scenarios/studies/laws.toml:

    formation-traci sweep scenarios/studies/laws.toml --out runs/laws --workers 2
    python docs/laws_study.py runs/laws

Per law and head profile, over the study's seeds: the formation's string_amplification (None
where the first follower's peak speed error is below the floor: counted apart), the smallest
bumper-to-bumper gap of the column, the followers' worst longitudinal jerk (peak of the 1 s
mean, ISO 15622's 2.5 m/s^3 reference) and the worst ISO 2631-1 weighted rms (a_w, longitudinal
and lateral), as mean [Student-t 95 % interval] over the seeds, and the runs' incidents (run.json
counts: their sum over the seeds, and how many runs had any). Checks that the virtual car's rows
are equal bit for bit across the laws of each profile and seed."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

LAWS = ("virtual_structure", "acc", "cacc_path", "cacc_ploeg", "sumo_cacc")
VERDICT = ("member_collisions", "member_removed", "emergency_brakes", "stranded",
           "sumo_emergency_brakes", "lane_departures")


def case_row(case: Path) -> dict:
    meta = json.loads((case / "run.json").read_text())
    doc = json.loads((case / "metrics.json").read_text())
    rec = doc["formations"][0]
    followers = [m for m in doc["members"] if m["id"] != rec["column"][0]]
    inc = meta.get("incidents") or {}
    return {"amp": rec["string_amplification"], "min_gap": rec["min_gap_m"],
            "jerk": max(m["jerk_lon_1s_peak_mps3"] for m in followers),
            "aw_lon": max(m["aw_lon_mps2"] for m in followers),
            "aw_lat": max(m["aw_lat_mps2"] for m in followers),
            "incidents": sum(int(inc.get(k, 0)) for k in VERDICT),
            "kinds": {k: int(inc.get(k, 0)) for k in VERDICT if inc.get(k, 0)}}


def interval(x) -> str:
    x = np.asarray([v for v in x if v is not None], dtype=float)
    if len(x) == 0:
        return "-"
    m = float(x.mean())
    if len(x) < 2:
        return f"{m:.3g}"
    h = float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x)))
    return f"{m:.3g} [{m - h:.3g}, {m + h:.3g}]"


def vc_rows(case: Path) -> pd.DataFrame:
    t = pd.read_parquet(case / "trajectories.parquet")
    return t[t.vehicle_id == "vc"][["t", "x", "y", "heading", "v"]].reset_index(drop=True)


def main(study: Path) -> None:
    summary = pd.read_parquet(study / "summary.parquet")
    profiles = {p: ("braking" if "6.75" in str(p) or "6.75" in repr(p) else "wave")
                for p in summary["leader.speed"].astype(str).unique()}
    summary["head"] = summary["leader.speed"].astype(str).map(profiles)
    rows = []
    for (head, law), g in summary.groupby(["head", "controller.law"], sort=False):
        cases = [case_row(study / "cases" / c) for c in g.case_id]
        n_none = sum(c["amp"] is None for c in cases)
        kinds = {}
        for c in cases:
            for k, v in c["kinds"].items():
                kinds[k] = kinds.get(k, 0) + v
        rows.append({"head": head, "law": law, "seeds": len(cases),
                     "string_amplification": interval([c["amp"] for c in cases])
                     + (f" ({n_none} below the floor)" if n_none else ""),
                     "smallest gap [m]": interval([c["min_gap"] for c in cases]),
                     "jerk 1 s peak [m/s^3]": interval([c["jerk"] for c in cases]),
                     "a_w lon [m/s^2]": interval([c["aw_lon"] for c in cases]),
                     "a_w lat [m/s^2]": interval([c["aw_lat"] for c in cases]),
                     "incidents (runs)": f"{sum(c['incidents'] for c in cases)} "
                                         f"({sum(c['incidents'] > 0 for c in cases)})"
                                         + (f": {', '.join(f'{v} {k}' for k, v in kinds.items())}"
                                            if kinds else "")})
    table = pd.DataFrame(rows)
    order = {law: i for i, law in enumerate(LAWS)}
    table = table.sort_values(["head", "law"], key=lambda s: s.map(order) if s.name == "law" else s)
    cols = list(table.columns)
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for _, r in table.iterrows():
        print("| " + " | ".join(str(r[c]) for c in cols) + " |")
    for (head, seed), g in summary.groupby(["head", "seed"]):
        ref = None
        for c in g.case_id:
            rows_vc = vc_rows(study / "cases" / c)
            if ref is None:
                ref = rows_vc
            else:
                pd.testing.assert_frame_equal(rows_vc, ref, check_exact=True)
        print(f"{head}, seed {seed}: the virtual car's rows are equal bit for bit across "
              f"{len(g)} laws")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
