"""Per SUMO step: the compiled formation layer against the numpy reference path.

    python benchmarks/step_kernels.py

For the dynamic and kinematic models and 1, 5, 20, 50 members on the curved bundled net: the
Frenet projection of the members and of 40 neighbours, the recorded signals and five control
periods (0.05 s step, 10 ms periods), with and without the previous arc lengths as guesses.
The builders are the ones tests/test_fast_step.py checks the two paths with.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import test_fast_step as h  # noqa: E402  (the test's builders)

from formation_traci.road.geometry import reference_line_from_net  # noqa: E402
from formation_traci.sim import fast  # noqa: E402
from formation_traci.sim import fleet as fl  # noqa: E402
from formation_traci.sim.fast import SIGNAL_COLUMNS, FastFleet  # noqa: E402
from sumo_nets import net_path  # noqa: E402


def per_call(fn, reps: int) -> float:
    """Mean time of one call [s] over ``reps`` calls after one warm-up call."""
    fn()
    t0 = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t0) / reps


def main() -> None:
    fast.warmup()
    curved = reference_line_from_net(net_path("curved3"), ["entry", "main"], 1)
    road = h._Road(curved)
    rng = np.random.default_rng(9)
    nb_s = rng.uniform(700.0, 1100.0, 40)
    nb_xy = curved.from_frenet(nb_s, rng.choice([-3.5, 0.0, 3.5], 40))
    print("per SUMO step (to_frenet of members + 40 neighbours, signals, 5 control periods):")
    for model in ("dynamic", "kinematic"):
        for n in (1, 5, 20, 50):
            cfg = h.make_cfg(model, n)
            slots, rigid, is_road = h.make_slots(n)
            ff = FastFleet.from_config(cfg, curved, slots, rigid, is_road)
            st = h.initial(cfg, curved, slots, rigid, is_road, 900.0, 25.0)
            v_cap, a_cap = h.caps(50, n, True)
            m_s = curved.to_frenet(fl.kinematics(cfg, st)[0])[0]
            out = np.full((n, len(SIGNAL_COLUMNS)), np.nan)

            def ref():
                curved.to_frenet(fl.kinematics(cfg, st)[0])
                curved.to_frenet(nb_xy)
                h.ref_step(cfg, road, slots, rigid, is_road, st, 900.0, 25.0, 0.3, v_cap, a_cap)

            def compiled(guess: bool):
                pos = ff.kinematics(st)[0]
                ff.to_frenet(pos, m_s if guess else None)
                ff.to_frenet(nb_xy, nb_s if guess else None)
                ff.signals(st, 900.0, 25.0, 0.3, v_cap, a_cap, out)
                ff.step(st, 900.0, 25.0, 0.3, v_cap, a_cap, h.DT_C, h.N_CTRL)

            t_ref = per_call(ref, 20 if n <= 20 else 8)
            t_f = per_call(lambda: compiled(True), 2000)
            t_fn = per_call(lambda: compiled(False), 2000)
            t_step = per_call(lambda: ff.step(st, 900.0, 25.0, 0.3, v_cap, a_cap, h.DT_C, h.N_CTRL), 2000)
            t_sig = per_call(lambda: ff.signals(st, 900.0, 25.0, 0.3, v_cap, a_cap, out), 2000)
            t_fr = per_call(lambda: ff.to_frenet(nb_xy, nb_s), 2000)
            print(f"  {model:9s} n={n:2d}: reference {t_ref * 1e3:7.3f} ms | kernels "
                  f"{t_f * 1e6:7.1f} us (no s guess {t_fn * 1e6:6.1f} us) = step "
                  f"{t_step * 1e6:6.1f} + signals {t_sig * 1e6:5.1f} + to_frenet(40) "
                  f"{t_fr * 1e6:5.1f} + members | x{t_ref / t_f:5.0f}")


if __name__ == "__main__":
    main()
