"""Per step: the members' pairwise body clearances (sim/incidents.py member_clearances), the
part of the compiled step whose work grows with the square of the members.

    python benchmarks/member_pairs.py [--members 5 60 200 500]

Members in formations of three along a three-lane road, 20 m between rows and 60 m between
formations (a penetration study's layout; passenger cars), all active; microseconds per call
(a recorded step calls it once), the mean over repeated calls after one warm-up call. Also
how many pairs were close enough to need the full clearance.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from formation_traci.models.params import PASSENGER_CAR
from formation_traci.record.columns import SIGNAL_COLUMNS
from formation_traci.sim.incidents import member_clearances

COLS = tuple(SIGNAL_COLUMNS.index(c) for c in ("x", "y", "heading"))


def layout(n: int) -> np.ndarray:
    """Signal rows of ``n`` members: formations of three (one per lane, 3.2 m apart), 60 m
    from one formation to the next [m]."""
    sig = np.zeros((n, len(SIGNAL_COLUMNS)))
    k = np.arange(n)
    sig[:, COLS[0]] = -60.0 * (k // 3)
    sig[:, COLS[1]] = 3.2 * (k % 3)
    return sig


def per_call(n: int) -> tuple[float, int]:
    """(microseconds per call, pairs within reach) for ``n`` members."""
    sig = layout(n)
    car = PASSENGER_CAR
    length, width = np.full(n, car.length), np.full(n, car.width)
    shift = np.full(n, car.cog_to_front_bumper - 0.5 * car.length)
    active, out = np.ones(n, dtype=np.bool_), np.full((n, n), np.inf)
    args = (sig, *COLS, shift, length, width, active, out)
    member_clearances(*args)
    reps = max(20, int(2e5 / max(n * n, 1)))
    t0 = time.perf_counter()
    for _ in range(reps):
        member_clearances(*args)
    return 1e6 * (time.perf_counter() - t0) / reps, int(np.isfinite(out[np.triu_indices(n, 1)]).sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, nargs="*", default=[5, 60, 200, 500])
    a = ap.parse_args()
    print("members | pairs  | within reach | us per call")
    for n in a.members:
        us, near = per_call(n)
        print(f"{n:7d} | {n * (n - 1) // 2:6d} | {near:12d} | {us:11.1f}")


if __name__ == "__main__":
    main()
