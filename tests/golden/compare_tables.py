"""Run every bundled scenario and compare all recorded tables of two such sets of runs.

    python tests/golden/compare_tables.py run OUT [--duration S]   # every bundled scenario into OUT/<name>
    python tests/golden/compare_tables.py compare OLD NEW           # value-identical? (exit 1 if not)

A refactoring that must not change results runs ``run`` on the commit before it and on the
commit after it (``PYTHONPATH=<checkout>`` selects the code) and ``compare``s the two: every
table of every run (trajectories, comfort, events, background, ssm, fcd, ...), every column the
old run has, value for value (NaN equal to NaN); columns only the new run has are listed, not
compared. Studies (scenarios/studies) are sweeps, not scenarios, and are left out.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[2]


def bundled() -> list[Path]:
    return sorted(p for p in (ROOT / "scenarios").rglob("*.toml") if "studies" not in p.parts)


def run_all(out: Path, duration: float | None) -> None:
    from formation_traci.scenario import load_scenario
    try:
        from formation_traci.runner import run_scenario
    except ImportError:  # a checkout before issue 26 moved it above sim/ and sumo/
        from formation_traci.sim.runner import run_scenario

    out.mkdir(parents=True, exist_ok=True)
    for path in bundled():
        name = "__".join(path.relative_to(ROOT / "scenarios").with_suffix("").parts)
        sc = load_scenario(path)
        if duration is not None and duration < sc.run.duration:
            sc = load_scenario(path, **{"run.duration": duration})
        res = run_scenario(sc, out / name, scenario_path=path, force=True, progress=False)
        print(f"{name}: {getattr(res, 'status', res)}", flush=True)


def _tables(run: Path) -> dict[str, Path]:
    return {p.stem: p for p in sorted(run.glob("*.parquet"))}


def _equal(a: pd.Series, b: pd.Series) -> bool:
    if a.dtype.kind == "f" and b.dtype.kind == "f":
        x, y = a.to_numpy(), b.to_numpy()
        return x.shape == y.shape and bool(np.all((x == y) | (np.isnan(x) & np.isnan(y))))
    return a.astype(str).tolist() == b.astype(str).tolist()


def compare(old: Path, new: Path) -> int:
    bad = 0
    for run in sorted(p for p in old.iterdir() if p.is_dir()):
        other = new / run.name
        if not other.is_dir():
            print(f"{run.name}: missing in {new}")
            bad += 1
            continue
        for name, path in _tables(run).items():
            if name not in _tables(other):
                print(f"{run.name}/{name}: missing")
                bad += 1
                continue
            a, b = pd.read_parquet(path), pd.read_parquet(other / path.name)
            if len(a) != len(b):
                print(f"{run.name}/{name}: {len(a)} rows vs {len(b)}")
                bad += 1
                continue
            diff = [c for c in a.columns if c not in b.columns or not _equal(a[c], b[c])]
            extra = [c for c in b.columns if c not in a.columns]
            if diff:
                bad += 1
                print(f"{run.name}/{name}: columns differ: {diff}")
            if extra:
                print(f"{run.name}/{name}: new columns (not compared): {extra}")
    print("value-identical" if bad == 0 else f"{bad} differences")
    return 1 if bad else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out", type=Path)
    r.add_argument("--duration", type=float, default=None, help="cap every run's duration [s]")
    c = sub.add_parser("compare")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    a = ap.parse_args(argv)
    if a.cmd == "run":
        run_all(a.out, a.duration)
        return 0
    return compare(a.old, a.new)


if __name__ == "__main__":
    sys.exit(main())
