"""The seed's claims for its experiments (sections 2.3 and 3.3.2), on scenarios/thesis/.

Each test names the claim and the tolerance. Where the physics does not give the seed's
claim, the test pins what it gives instead and docs/model.md says why.
"""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario

THESIS = Path(__file__).resolve().parents[1] / "scenarios" / "thesis"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    cache = {}

    def get(name, **overrides):
        key = (name, tuple(sorted(overrides.items())))
        if key not in cache:
            sc = load_scenario(THESIS / f"{name}.toml", **overrides)
            out = tmp_path_factory.mktemp(name.replace(".", "_"))
            res = run_scenario(sc, out, force=True, progress=False)
            assert res.status == "completed", res.reason
            df = pd.read_parquet(out / "trajectories.parquet")
            df["e"] = np.hypot(df.ex, df.ey)
            cache[key] = df
        return cache[key]

    return get


def member(df, vid):
    return df[df.vehicle_id == vid].reset_index(drop=True)


def settling_time(g, band):
    """First time after which the error norm stays inside ``band`` [m]."""
    outside = np.flatnonzero(g.e.to_numpy() >= band)
    if len(outside) == 0:
        return 0.0
    if outside[-1] == len(g) - 1:
        return np.inf
    return float(g.t.iloc[outside[-1] + 1])


def test_gain_study_k_table_2_1(runs):
    """Seed 2.3: higher k settles faster; k = 1 keeps |a_lat| below 3 m/s^2, k = 5 exceeds it."""
    df = runs("gain_study_k")
    ts = {k: settling_time(member(df, k), 0.2) for k in ("k0.5", "k1", "k5")}
    assert ts["k0.5"] > ts["k1"] > ts["k5"]
    alat = {k: member(df, k).a_lat.abs().max() for k in ("k0.5", "k1", "k5")}
    assert alat["k1"] < 3.0 and alat["k0.5"] < 3.0
    assert alat["k5"] > 3.0
    assert alat["k1"] == pytest.approx(2.89, abs=0.02)  # the margin is small: pinned


def test_gain_study_ktheta_table_2_1(runs):
    """Seed 2.3: k_theta above 3 makes |a_lat| exceed 3 m/s^2; 1 and 3 stay below."""
    df = runs("gain_study_ktheta")
    alat = {k: member(df, k).a_lat.abs().max() for k in ("ktheta1", "ktheta3", "ktheta9")}
    assert alat["ktheta1"] < alat["ktheta3"] < 3.0 < alat["ktheta9"]


@pytest.mark.parametrize("name", ["case_2_3_1_straight", "case_2_3_2_circle", "case_2_3_3_varying"])
def test_kinematic_cases_converge(runs, name):
    """Seed 2.3.1-2.3.3: every member reaches its slot; afterwards only minor deviations."""
    df = runs(name)
    for vid, g in df[df.vehicle_id != "vc"].groupby("vehicle_id"):
        assert g.e.iloc[-1] < 0.02, vid
        assert np.isfinite(settling_time(g, 0.2)), vid
    if name == "case_2_3_3_varying":  # leader changes v and omega after the transient
        late = df[(df.vehicle_id != "vc") & (df.t > 40)]
        assert late.e.max() < 0.5


def test_dynamic_case1_dynamic_and_kinematic_paths_stay_close(runs):
    """Seed 3.3.2.1: with the Table 3.10 gains the dynamic car moves on nearly the kinematic path."""
    dyn = member(runs("dynamic_case1"), "car")
    kin = member(runs("dynamic_case1", **{"vehicle.model": "kinematic"}), "car")
    gap = np.hypot(dyn.x - kin.x, dyn.y - kin.y)
    assert gap.max() < 0.5  # m, over the whole 70 s run including the 15 m initial error
    assert dyn.e.iloc[-1] < 0.01
    assert dyn[dyn.t > 20].e.max() < 0.3
    # section 3.3.1 limits hold: slip < 4 deg, traction under its limit, |a_lat| < 3.6 m/s^2
    assert np.rad2deg(dyn[["slip_front", "slip_rear"]].abs().to_numpy().max()) < 4.0
    assert (dyn.traction_force <= dyn.traction_force_max + 1e-9).all()
    assert dyn.a_lat.abs().max() < 3.6
    assert (dyn.friction_usage < 1.0).all()


def test_dynamic_case2_poor_speed_loop(runs):
    """Seed 3.3.2.2: with the Table 3.12 speed gains the car cannot follow the reference while
    the leader changes speed. Physics: the error does return to zero once the leader's speed
    is constant again (docs/model.md), so we pin what it gives: during the leader's speed
    changes the error is far outside the band, about 10x case 1's."""
    good = member(runs("dynamic_case1"), "car")
    poor = member(runs("dynamic_case2"), "car")
    window = (poor.t > 38) & (poor.t < 50)  # leader slows 25 -> 20 m/s over 40-45 s
    assert poor[window].e.max() > 2.0
    assert poor[window].e.max() > 8 * good[window].e.max()
    speed_err = lambda g: np.sqrt(np.mean((g.v_ref - g.v)[window] ** 2))
    assert speed_err(poor) > 5 * speed_err(good)
    assert poor.e.iloc[-1] < 0.01  # converges once the leader's speed is constant


def test_dynamic_case3_initial_speed(runs):
    """Seed 3.3.2.3: v(0) = 10 m/s settles more slowly than v(0) = 15 m/s; both converge."""
    df = runs("dynamic_case3")
    first_in = {vid: float(member(df, vid).t[member(df, vid).e < 0.5].iloc[0])
                for vid in ("v0_10", "v0_15")}
    assert first_in["v0_10"] > first_in["v0_15"] + 3.0
    for vid in ("v0_10", "v0_15"):
        assert member(df, vid).e.iloc[-1] < 0.01


@pytest.mark.parametrize("name", ["dynamic_case4_straight", "dynamic_case4_turning"])
def test_dynamic_case4_settling_grows_linearly_with_distance(runs, name):
    """Seed 3.3.2.4: the error closes at a constant rate, so settling time is proportional to
    the initial distance. First principles: with tanh saturated the closing speed is k."""
    df = runs(name)
    ids = ("d10", "d20", "d40")
    d0 = np.array([member(df, i).e.iloc[0] for i in ids])
    ts = np.array([settling_time(member(df, i), 0.2) for i in ids])
    slope = np.polyfit(d0, ts, 1)[0]
    assert slope == pytest.approx(1.0 / 1.0, rel=0.05)  # 1/k [s/m], k = 1 m/s
    assert np.all(np.diff(ts) > 0)
