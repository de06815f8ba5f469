"""Writes the string-stability scenario set (docs/platoon_laws.md): Plexe's
reference experiment, 8 cars at 100 km/h in one lane of free space, the leader's speed a 0.2 Hz
+-10 km/h sinusoid from t = 5 s (sinusoid_<law>.toml) or a brake at 8 m/s^2 (braking_<law>.toml),
each column started at its law's equilibrium gap; sinusoid_sumo_cacc.toml and braking_sumo_cacc.toml: the
same column on a SUMO road (straight3, lane 0) whose followers SUMO's own CACC drives
(docs/platoon_laws.md "SUMO's CACC twin"). Run: python scenarios/platoon/make_platoon.py
"""
from __future__ import annotations

import math
from pathlib import Path

V0 = 100.0 / 3.6  # m/s
AMP = 10.0 / 3.6  # m/s
F_HZ = 0.2
N = 8
LENGTH_M = 4.6  # passenger_car preset, bumper to bumper
T_SIN = 5.0  # s
DURATION_S = 30.0
BRAKE_T_S, BRAKE_MPS2, BRAKE_TO = 5.0, 8.0, 50.0 / 3.6

LAWS = {  # law: (equilibrium gap at V0 [m], controller lines)
    "acc": (2.0 + 1.2 * V0, 'law = "acc"\nacc = { headway_s = 1.2 }\n', ""),
    "cacc_path": (5.0, 'law = "cacc_path"\ncacc_path = { spacing_m = 5.0, c1 = 0.5, xi = 1.0, '
                  'omega_n_hz = 0.2 }\n', ""),
    "cacc_ploeg": (2.0 + 0.5 * V0, 'law = "cacc_ploeg"\ncacc_ploeg = { h_s = 0.5, kp = 0.2, '
                   'kd = 0.7 }\n', ""),
    "virtual_structure": (2.0 + 0.5 * V0, 'law = "virtual_structure"\n', ""),
}


def sinusoid() -> str:
    ts = [0.0] + [T_SIN + 0.1 * k for k in range(int((DURATION_S - T_SIN) / 0.1) + 1)]
    vs = [V0] + [V0 + AMP * math.sin(2 * math.pi * F_HZ * (t - T_SIN)) for t in ts[1:]]
    return _profile(ts, vs)


def braking() -> str:
    t1 = BRAKE_T_S + (V0 - BRAKE_TO) / BRAKE_MPS2
    return _profile([0.0, BRAKE_T_S, t1], [V0, V0, BRAKE_TO])


def _profile(ts, vs) -> str:
    return ("{ t = [" + ", ".join(f"{t:.1f}" for t in ts) + "], values = ["
            + ", ".join(f"{v:.6f}" for v in vs) + '], interp = "linear" }')


def scenario(name: str, gap_m: float, controller: str, speed: str, vehicle_extra: str = "",
             duration: float = DURATION_S) -> str:
    members = "".join(
        f'[[members]]\nid = "p{i}"\noffset = [{-i * (gap_m + LENGTH_M):.4f}, 0.0]\n'
        f"position = [{-i * (gap_m + LENGTH_M):.4f}, 0.0]\nspeed = {V0:.6f}\n\n"
        for i in range(N))
    return (f'name = "{name}"\ndescription = "string stability (Plexe experiment): 8 cars at 100 km/h, '
            f'gap {gap_m:.2f} m (written by make_platoon.py)"\n\n'
            f"[run]\nduration = {duration}\nstep = 0.05\ncontrol_step = 0.01\n\n"
            f'[vehicle]\nmodel = "dynamic"\npreset = "passenger_car"\n{vehicle_extra}\n'
            f"[controller]\n{controller}\n[leader]\nspeed = {speed}\n\n{members}")


SUMO_CACC = ('law = "sumo_cacc"\nsumo_cacc = { tau_s = 0.5, min_gap_m = 2.0, accel_mps2 = 5.0, '
             'decel_mps2 = 8.0, emergency_decel_mps2 = 9.0 }\ncacc_ploeg = { h_s = 0.5, kp = 0.2, '
             'kd = 0.7 }\n')
"""SUMO's CACC at Ploeg's time gap and standstill gap (desired gap minGap + tau v = 15.89 m);
cacc_ploeg is the law our column runs in the comparison (--set controller.law='"cacc_ploeg"')."""


def road_scenario(name: str, gap_m: float, controller: str, speed: str,
                  duration: float = DURATION_S) -> str:
    """The column in lane 0 of the straight motorway (sumo_nets/straight3), no traffic: the
    head at 300 m, the others behind it at ``gap_m`` bumper to bumper."""
    members = "".join(f'[[members]]\nid = "p{i}"\nslot = {{ along = {-i * (gap_m + LENGTH_M):.4f}, '
                      f"lanes = 0 }}\n\n" for i in range(N))
    return (f'name = "{name}"\ndescription = "string stability (Plexe experiment) on a SUMO road: 8 cars at '
            f'100 km/h in lane 0, gap {gap_m:.2f} m (written by make_platoon.py)"\n\n'
            f"[run]\nduration = {duration}\nstep = 0.05\ncontrol_step = 0.01\n\n"
            f'[vehicle]\nmodel = "dynamic"\npreset = "passenger_car"\n\n'
            f'[road]\nnet = "straight3"\nlane = 0\nstart = 500.0\n\n'
            f"[controller]\n{controller}\n[leader]\nspeed = {speed}\n\n{members}")


def main(out: Path = Path(__file__).parent) -> None:
    for law, (gap, ctl, extra) in LAWS.items():
        (out / f"sinusoid_{law}.toml").write_text(scenario(f"sinusoid-{law}", gap, ctl,
                                                           sinusoid(), extra))
        (out / f"braking_{law}.toml").write_text(scenario(f"braking-{law}", gap, ctl,
                                                          braking(), extra, 15.0))
    gap = 2.0 + 0.3 * V0
    (out / "sinusoid_acc_short_gap.toml").write_text(scenario(
        "sinusoid-acc-short-gap", gap, 'law = "acc"\nacc = { headway_s = 0.3 }\n', sinusoid(),
        "[vehicle.params]\ndrive_lag_s = 0.5\n"))
    gap = 2.0 + 0.5 * V0
    (out / "sinusoid_sumo_cacc.toml").write_text(road_scenario("sinusoid-sumo_cacc", gap, SUMO_CACC,
                                                               sinusoid()))
    (out / "braking_sumo_cacc.toml").write_text(road_scenario("braking-sumo_cacc", gap, SUMO_CACC,
                                                              braking(), 15.0))


if __name__ == "__main__":
    main()
