"""Record the trajectories of every bundled scenario as the golden fixture of tests/test_golden.py.

    python tests/golden/make_golden.py            # both sets
    python tests/golden/make_golden.py thesis     # one set

Free space (scenarios/thesis/*.toml): each scenario at its bundled duration.
SUMO (scenarios/highway/*.toml): shortened to HIGHWAY_OVERRIDES (the bundled 200 s warm-up and
120 s formation runs would cost minutes each in the suite), but for NOT_GOLDEN: scenarios too large
for the suite even when shortened (benchmarks measure them; tests/test_scale_case.py checks what
they are made of).

Every member row and the virtual car's row of trajectories.parquet: t [s], vehicle_id, x, y [m],
heading [rad, CCW from +x], v [m/s] (float64), one .npz per set. Regenerate only when a change
intentionally moves trajectories, and say so in the commit.
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
NOT_GOLDEN = {
    "motorway100": "100 km with ~4,000 vehicles: its shortened run (30 s warm-up, 20 s) takes minutes "
                   "of the suite; benchmarks/scale.py runs it",
}
"""Bundled highway scenarios left out of the golden set (and so of tests/test_sumo_runs.py's run of
every bundled scenario), with the reason."""
SETS = {
    "thesis": sorted((ROOT / "scenarios" / "thesis").glob("*.toml")),
    "highway": sorted(p for p in (ROOT / "scenarios" / "highway").glob("*.toml") if p.stem not in NOT_GOLDEN),
}
HIGHWAY_OVERRIDES = {"run.duration": 20.0, "traffic.warmup": 30.0}
COLUMNS = ("t", "x", "y", "heading", "v")


def overrides(kind: str) -> dict:
    return dict(HIGHWAY_OVERRIDES) if kind == "highway" else {}


def trajectory(path: Path, kind: str, out_dir: Path) -> pd.DataFrame:
    """Run one bundled scenario (with the set's overrides) and return its golden columns."""
    from formation_traci.scenario import load_scenario
    from formation_traci.runner import run_scenario

    sc = load_scenario(path, **overrides(kind))
    res = run_scenario(sc, out_dir, scenario_path=path, progress=False, force=True)
    if res.status not in ("completed", "completed_with_incidents"):  # the run reached its end
        raise RuntimeError(f"{path.name}: {res.status}: {res.reason}")
    df = pd.read_parquet(out_dir / "trajectories.parquet")
    return df[["vehicle_id", *COLUMNS]].sort_values(["t", "vehicle_id"], kind="stable") \
        .reset_index(drop=True)


def write_set(kind: str) -> Path:
    arrays = {}
    with tempfile.TemporaryDirectory() as tmp:
        for path in SETS[kind]:
            df = trajectory(path, kind, Path(tmp) / path.stem)
            arrays[f"{path.stem}/id"] = np.array(df.vehicle_id.astype(str).tolist(), dtype=str)
            arrays[f"{path.stem}/values"] = df[list(COLUMNS)].to_numpy(np.float64)
            print(f"{kind}/{path.stem}: {len(df)} rows")
    out = HERE / f"{kind}.npz"
    np.savez_compressed(out, **arrays)
    return out


def load_set(kind: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{scenario stem: (ids, values (rows, len(COLUMNS)))} of a stored set."""
    with np.load(HERE / f"{kind}.npz", allow_pickle=False) as z:
        stems = sorted({k.split("/")[0] for k in z.files})
        return {s: (z[f"{s}/id"], z[f"{s}/values"]) for s in stems}


if __name__ == "__main__":
    for kind in sys.argv[1:] or list(SETS):
        print(write_set(kind))
