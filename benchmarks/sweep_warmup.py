"""The comm study as a sweep today (issue 33's reference) against the same sweep the ways
that make it cheaper: case processes forked from the preloaded server, and the shared warm-up.

    python benchmarks/sweep_warmup.py [--quick] [--workers N] [--keep DIR] [--rounds N]

Runs ``scenarios/studies/comm.toml`` (18 cases: 3 delays x 3 losses x 2 seeds, 60 s warm-up,
60 s of formation) on the local pool, one sweep after the other on the same machine:

- ``today``: every case a new interpreter (``FORMATION_TRACI_CASE_START=exec``, as before issue
  33) simulating its own 60 s of traffic (``--no-shared-warmup``);
- ``forked``: every case forked from the server that has imported what a case imports
  (sweep/forked.py, the default now), each simulating its own warm-up;
- ``shared``: forked, and each of the two warm-up keys (one per seed) simulated once
  (sumo/warm_state.py, ``--shared-warmup``).

Before them one case runs untimed so that all find numba's and the road's caches warm;
``--rounds`` repeats the three in turn (medians). ``--quick``: the corner cases only (delay 0
and 0.3 s, loss none and bursty, both seeds: 8 cases). Each sweep's wall time is from the
call to the summary written (the forked sweeps include starting their server). The
summaries are compared with today's value for value except the columns that depend on the
machine and the clock (formation_traci/sweep/row.py WALL_COLUMNS). It ends with the two fixed
lines for ``shared`` (the study the cheapest way) against ``today``:

    sweep wall ratio: X.XX
    summaries identical: yes|no

With SUMO 1.28 and the sublane model the second is "no" for ``shared``: a run from SUMO's saved
state starts the lane-change model's memory from zero (docs/sweeps.md, "The shared warm-up");
the lines before say how many metric columns differ and by how much, and give ``forked``
against ``today`` (value-identical: the same processes' work, started another way).
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
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


WAYS = {"today": ("exec", False), "forked": ("fork", False), "shared": ("fork", True)}
"""Each way's case start (FORMATION_TRACI_CASE_START) and shared warm-up."""


def _timed_sweep(path: Path, out: Path, workers: int | None, way: str):
    from formation_traci.sweep import forked, run_sweep

    start, shared = WAYS[way]
    os.environ[forked.ENV] = start
    try:
        t0 = time.perf_counter()
        res = run_sweep(path, out, workers=workers, progress=False, shared_warmup=shared)
        return time.perf_counter() - t0, res
    finally:
        del os.environ[forked.ENV]


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
    ap.add_argument("--rounds", type=int, default=1, help="the three sweeps this many times in turn")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="sweep-warmup-"))
    root = args.keep or tmp
    try:
        _timed_sweep(_sweep_file(tmp, False, prime=True), root / "prime", args.workers, "today")
        path = _sweep_file(tmp, args.quick)
        walls: dict[str, list[float]] = {w: [] for w in WAYS}
        results = {}
        for r in range(args.rounds):
            for way in (WAYS if r % 2 == 0 else list(WAYS)[::-1]):
                t, results[way] = _timed_sweep(path, root / f"{way}{r}", args.workers, way)
                walls[way].append(t)
                print(f"round {r + 1} {way:6s}: {results[way].n_cases} cases "
                      f"({results[way].n_completed} completed) in {t:.1f} s", flush=True)
        wall = {w: statistics.median(v) for w, v in walls.items()}
        for way in ("forked", "shared"):
            same, lines = compare(results["today"].summary, results[way].summary)
            print(f"{way} / today: wall {wall[way] / wall['today']:.2f}, summaries "
                  f"{'value-identical' if same else f'differ in {len(lines)} columns'}")
            if lines:
                print("\n".join(lines))
        print(f"sweep wall ratio: {wall['shared'] / wall['today']:.2f}")
        print(f"summaries identical: {'yes' if same else 'no'}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
