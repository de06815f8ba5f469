"""A sweep with the shared warm-up against the same sweep where every case simulates its own.

    python benchmarks/sweep_warmup.py [--quick] [--workers N] [--keep DIR]

Runs ``scenarios/studies/comm.toml`` (18 cases: 3 delays x 3 losses x 2 seeds, 60 s warm-up,
60 s of formation) twice on the local pool, one sweep after the other on the same machine:
``--no-shared-warmup`` (every case simulates its 60 s of traffic) and the default (each of
the two warm-up keys, one per seed, simulated once: sumo/warm_state.py). Before them one case
runs untimed so that both find numba's and the road's caches warm. ``--quick``: the corner
cases only (delay 0 and 0.3 s, loss none and bursty, both seeds: 8 cases).

Prints each sweep's wall time (from the call to the summary written), then the summaries
compared value for value except the columns that depend on the machine and the clock
(formation_traci/sweep/row.py WALL_COLUMNS), and ends with the two fixed lines

    sweep wall ratio: X.XX          (shared / unshared wall time)
    summaries identical: yes|no

With SUMO 1.28 and the sublane model the answer is "no": a run from SUMO's saved state starts
the lane-change model's memory from zero (docs/sweeps.md, "The shared warm-up"); the lines
before say how many metric columns differ and by how much.
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "scenarios" / "studies" / "comm.toml"


def _sweep_file(tmp: Path, quick: bool, prime: bool = False) -> Path:
    """comm.toml with its base made absolute; ``quick``: the corner cases; ``prime``: one case."""
    text = STUDY.read_text(encoding="utf-8")
    base = (STUDY.parent / tomllib.loads(text)["base"]).resolve()
    text = text.replace('base = "../highway/straight_3lane_light.toml"', f'base = "{base}"')
    if quick or prime:
        text = text.replace('"comm.delay_s" = [0.0, 0.1, 0.3]', '"comm.delay_s" = [0.0]' if prime
                            else '"comm.delay_s" = [0.0, 0.3]')
        text = text.replace('"comm.loss" = ["none", "independent", "bursty"]', '"comm.loss" = ["none"]' if prime
                            else '"comm.loss" = ["none", "bursty"]')
        if prime:
            text = text.replace("seeds = [1, 2]", "seeds = [1]")
    path = tmp / ("prime.toml" if prime else "comm.toml")
    path.write_text(text, encoding="utf-8")
    return path


def _timed_sweep(path: Path, out: Path, workers: int | None, shared: bool):
    from formation_traci.sweep import run_sweep

    t0 = time.perf_counter()
    res = run_sweep(path, out, workers=workers, progress=False, shared_warmup=shared)
    return time.perf_counter() - t0, res


def compare(a, b) -> tuple[bool, list[str]]:
    """(value-identical, lines describing the differences) of two summaries."""
    from formation_traci.sweep.row import WALL_COLUMNS

    a = a.drop(columns=list(WALL_COLUMNS)).reset_index(drop=True)
    b = b.drop(columns=list(WALL_COLUMNS)).reset_index(drop=True)
    if a.shape != b.shape or list(a.columns) != list(b.columns):
        return False, [f"shapes differ: {a.shape} vs {b.shape}"]
    lines, same = [], True
    for c in a.columns:
        x, y = a[c], b[c]
        if x.equals(y):
            continue
        same = False
        if pd.api.types.is_numeric_dtype(x.dtype) and not pd.api.types.is_bool_dtype(x.dtype):
            xv, yv = x.astype("float64").to_numpy(float, na_value=np.nan), y.astype("float64").to_numpy(float, na_value=np.nan)
            rel = np.abs(xv - yv) / np.maximum(np.maximum(np.abs(xv), np.abs(yv)), 1e-12)
            rel = rel[np.isfinite(rel)]
            lines.append(f"  {c}: median relative difference {np.median(rel) if len(rel) else float('nan'):.3g}, "
                         f"max {rel.max() if len(rel) else float('nan'):.3g}")
        else:
            lines.append(f"  {c}: {int((x.astype(str) != y.astype(str)).sum())} of {len(x)} values differ")
    return same, lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="8 corner cases instead of 18")
    ap.add_argument("--workers", type=int, default=None, help="cases at once (default: cores)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the sweep directories here")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="sweep-warmup-"))
    root = args.keep or tmp
    try:
        _timed_sweep(_sweep_file(tmp, False, prime=True), root / "prime", args.workers, False)
        path = _sweep_file(tmp, args.quick)
        t_u, r_u = _timed_sweep(path, root / "unshared", args.workers, False)
        print(f"unshared: {r_u.n_cases} cases ({r_u.n_completed} completed) in {t_u:.1f} s")
        t_s, r_s = _timed_sweep(path, root / "shared", args.workers, True)
        n_keys = len([p for p in (root / "shared" / "warmups").iterdir() if p.is_dir()])
        print(f"shared:   {r_s.n_cases} cases ({r_s.n_completed} completed) in {t_s:.1f} s, "
              f"{n_keys} warm-ups simulated")
        same, lines = compare(r_u.summary, r_s.summary)
        if lines:
            print(f"{len(lines)} summary columns differ (shared against unshared):")
            print("\n".join(lines))
        print(f"sweep wall ratio: {t_s / t_u:.2f}")
        print(f"summaries identical: {'yes' if same else 'no'}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
