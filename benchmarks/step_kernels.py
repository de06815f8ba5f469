"""Per step: the compiled formation layer (reference, recorded signals, controllers and models).

    python benchmarks/step_kernels.py

For the dynamic and kinematic models and 1, 5, 20, 50 members on the curved bundled net
(road slots, 0.05 s step of five 10 ms control periods): the road reference generator's
virtual-car rows, ``Fleet.signals`` and ``Fleet.step`` (sim/fleet.py), microseconds per step.
"""
from __future__ import annotations

import time

import numpy as np

from formation_traci.control.reference_road import road_vc_rows
from formation_traci.control.reference import FRAME_ROAD, Reference, constant_slots
from formation_traci.control.schedule import SPEED_GAINS_CAR, YAW_GAINS_RETUNED
from formation_traci.models.params import PASSENGER_CAR, bicycle_params, make_tires, stack
from formation_traci.record.columns import SIGNAL_COLUMNS
from formation_traci.road.line_pack import packed
from formation_traci.road.geometry import reference_line_from_net
from formation_traci.road.targets import road_targets
from formation_traci.sim.fleet import Fleet, FleetConfig, initial_state
from sumo_nets import net_path

N_CTRL, DT_C = 5, 0.01


def per_call(fn, reps: int = 2000) -> float:
    """Mean time of one call [s] over ``reps`` calls after one warm-up call."""
    fn()
    t0 = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t0) / reps


def main() -> None:
    line = reference_line_from_net(net_path("curved3"), ["entry", "main"], 1)
    G = packed(line)
    print("per step (reference rows + signals + 5 control periods), microseconds:")
    for model in ("dynamic", "kinematic"):
        for n in (1, 5, 20, 50):
            p = stack([bicycle_params(PASSENGER_CAR, 1.0, make_tires(PASSENGER_CAR, 1.0))] * n)
            cfg = FleetConfig(tuple(f"m{i}" for i in range(n)), model,
                              p if model == "dynamic" else None, np.full(n, 3.0),
                              np.full(n, 2.0), SPEED_GAINS_CAR, YAW_GAINS_RETUNED, 0.01)
            fleet = Fleet(cfg)
            offs = np.c_[-10.0 * (np.arange(n) // 3), 3.5 * (np.arange(n) % 3 - 1)]
            tg = road_targets(line, 900.0, 25.0, 0.0, offs)
            st = initial_state(cfg, tg.p + 0.5, np.arctan2(tg.v[:, 1], tg.v[:, 0]),
                               np.full(n, 24.0), np.zeros(n), np.zeros(n), tg)
            vc = np.empty((N_CTRL, n, 8))
            road_vc_rows(G, 900.0, 25.0, 0.3, 0.3, DT_C, vc)
            ref = Reference(0.0, DT_C, vc, constant_slots(offs, N_CTRL),
                            np.full(n, FRAME_ROAD), np.ones(n, bool), np.full(n, np.inf),
                            np.full(n, np.inf), line=G, truth=vc[0, 0])
            out = np.full((n, len(SIGNAL_COLUMNS)), np.nan)
            t_vc = per_call(lambda: road_vc_rows(G, 900.0, 25.0, 0.3, 0.3, DT_C, vc))
            t_sig = per_call(lambda: fleet.signals(st, ref, out))
            t_step = per_call(lambda: fleet.step(st, ref))
            print(f"  {model:9s} n={n:2d}: reference {t_vc * 1e6:6.1f} + signals "
                  f"{t_sig * 1e6:6.1f} + step {t_step * 1e6:7.1f} = "
                  f"{(t_vc + t_sig + t_step) * 1e6:7.1f} us")


if __name__ == "__main__":
    main()
