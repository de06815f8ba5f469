"""Per-call time of one 10 ms physics step: numpy integrate() vs the numba kernels.

    /work/venv/bin/python benchmarks/kernel_speed.py

dt = 0.01 s, n_sub = 1 (one RK4 step, as fleet.advance with the default physics step).
Parameters are packed once outside the timed loop, as the fleet would. Times are the
median over repeats of the mean over a batch of calls (time.perf_counter).
"""
from __future__ import annotations

import statistics
import time

import numpy as np

from formation_traci.models import bicycle, bicycle_fast, kinematic
from formation_traci.models.params import PASSENGER_CAR, SMALL_TRUCK, bicycle_params, make_tires, stack
from formation_traci.sim.integrate import integrate

DT, N_SUB = 0.01, 1
SIZES = (1, 5, 20, 50)
REPEATS = 7


def per_call(fn, min_time=0.2):
    """Median over REPEATS of the mean time per call [s] of fn()."""
    fn()
    batch, t = 1, 0.0
    while t < min_time / REPEATS:  # batch size so that one repeat takes ~min_time / REPEATS
        batch *= 2
        t0 = time.perf_counter()
        for _ in range(batch):
            fn()
        t = time.perf_counter() - t0
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        for _ in range(batch):
            fn()
        times.append((time.perf_counter() - t0) / batch)
    return statistics.median(times)


def states(n, rng):
    x = np.zeros((n, bicycle.N_STATES))
    x[:, bicycle.S.PSI] = rng.uniform(-np.pi, np.pi, n)
    x[:, bicycle.S.V] = rng.uniform(0.0, 35.0, n)
    x[:, bicycle.S.DELTA] = rng.uniform(-0.05, 0.05, n)
    u = np.column_stack([rng.uniform(-3, 2, n), rng.uniform(-0.2, 0.2, n)])
    return x, u


def main():
    t0 = time.perf_counter()
    bicycle_fast.warmup()
    print(f"warmup (compile or load from cache): {1e3 * (time.perf_counter() - t0):.0f} ms")
    rng = np.random.default_rng(0)
    car = bicycle_params(PASSENGER_CAR, 1.0, make_tires(PASSENGER_CAR, 1.0))
    truck = bicycle_params(SMALL_TRUCK, 1.0, make_tires(SMALL_TRUCK, 1.0))
    print(f"per call, dt={DT} s, n_sub={N_SUB}; times in microseconds")
    print(f"{'model':<22}{'n':>4}{'numpy':>11}{'kernel':>10}{'speed-up':>10}")
    for n in SIZES:
        x, u = states(n, rng)
        for label, p in (("bicycle (car)", car),
                         ("bicycle (car+truck)", stack([(car, truck)[i % 2] for i in range(n)]))):
            P = bicycle_fast.pack_params(p, n)
            t_np = per_call(lambda: integrate(bicycle.rhs, x, u, p, DT, DT, bicycle.project))
            t_nb = per_call(lambda: bicycle_fast.integrate_bicycle(x, u, P, DT, N_SUB))
            print(f"{label:<22}{n:>4}{1e6 * t_np:>11.1f}{1e6 * t_nb:>10.2f}{t_np / t_nb:>9.0f}x")
        xk = x[:, :3].copy()
        uk = np.column_stack([rng.uniform(0, 35, n), rng.uniform(-0.2, 0.2, n)])
        t_np = per_call(lambda: integrate(kinematic.rhs, xk, uk, None, DT, DT))
        t_nb = per_call(lambda: bicycle_fast.integrate_unicycle(xk, uk, DT, N_SUB))
        print(f"{'unicycle':<22}{n:>4}{1e6 * t_np:>11.1f}{1e6 * t_nb:>10.2f}{t_np / t_nb:>9.0f}x")


if __name__ == "__main__":
    main()
