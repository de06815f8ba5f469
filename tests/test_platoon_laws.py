"""Platoon laws on the law seam (issue 28, docs/platoon_laws.md): ACC, CACC after PATH and
Ploeg's CACC follow the member ahead in a column (FleetConfig.pred) with the virtual
structure's lateral loop; the string-stability scenarios of scenarios/platoon/."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.sim.runner import run_scenario
from formation_traci.sim.setup import build_fleet, column_predecessors

PLATOON = Path(__file__).resolve().parents[1] / "scenarios" / "platoon"
IDS = [f"p{i}" for i in range(8)]
LENGTH_M = 4.6  # passenger_car preset


def short(name: str, duration: float):
    """A bundled platoon scenario cut to ``duration`` [s] (tests stay short)."""
    sc = load_scenario(PLATOON / name)
    return sc.model_copy(update={"run": sc.run.model_copy(update={"duration": duration})})


def run(tmp_path, name: str, duration: float) -> pd.DataFrame:
    res = run_scenario(short(name, duration), tmp_path / name, force=True, progress=False)
    assert res.status == "completed"
    return pd.read_parquet(tmp_path / name / "trajectories.parquet")


def wide(df: pd.DataFrame, col: str) -> pd.DataFrame:
    return df.pivot(index="t", columns="vehicle_id", values=col)


def peak_speed_errors(df: pd.DataFrame) -> np.ndarray:
    """max_t |v_i - v_(i-1)| [m/s] of followers p1 .. p7."""
    v = wide(df, "v")
    return np.array([(v[IDS[i]] - v[IDS[i - 1]]).abs().max() for i in range(1, 8)])


def test_column_predecessors_are_the_nearest_slot_ahead_in_the_lane(tmp_path):
    """Two lanes of free-space offsets: each member's predecessor is the nearest one ahead
    in its own lane; lane heads have none."""
    members = "".join(f'[[members]]\nid = "{m}"\noffset = [{dx}, {dy}]\nposition = [{dx}, {dy}]\n'
                      for m, dx, dy in (("a", 0, 0), ("b", -20, 0.2), ("c", -10, 0),
                                        ("d", 0, 3.5), ("e", -15, 3.5)))
    p = tmp_path / "s.toml"
    p.write_text('[run]\nduration = 1.0\n[vehicle]\nmodel = "dynamic"\n[controller]\n'
                 f'law = "acc"\n[leader]\nspeed = 20.0\n{members}')
    sc = load_scenario(p)
    assert column_predecessors(sc) == (-1, 2, 0, -1, 3)
    cfg = build_fleet(sc)
    assert cfg.pred == (-1, 2, 0, -1, 3)
    assert cfg.bumpers[0] == pytest.approx((0.9 + 1.2, 4.6 - 0.9 - 1.2), abs=0.5)


def test_law_parameters_are_validated(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('[run]\nduration = 1.0\n[controller]\nlaw = "cacc_ploeg"\n'
                 'cacc_ploeg = { h_s = -0.5 }\n[leader]\nspeed = 20.0\n'
                 '[[members]]\nid = "a"\noffset = [0.0, 0.0]\nposition = [0.0, 0.0]\n')
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    assert "controller.cacc_ploeg.h_s" in str(ei.value)


def test_ploeg_is_string_stable_on_the_sinusoid(tmp_path):
    """Ploeg's CACC at h = 0.5 s, no lag, perfect radio: |Gamma(jw)| <= 1 at every w for
    h > 0 (Ploeg et al. 2011), so the peak speed error shrinks from follower to follower."""
    e = peak_speed_errors(run(tmp_path, "sinusoid_cacc_ploeg.toml", 15.0))
    assert e[0] > 0.5  # the sinusoid excites the column
    assert np.all(np.diff(e) < 0)
    assert e[-1] / e[0] <= 1.0


def test_path_keeps_constant_spacing(tmp_path):
    """PATH (5 m, C1 0.5, xi 1, 0.2 Hz) on the +-10 km/h sinusoid (peak 3.5 m/s^2): with the
    leader's and the predecessor's accelerations fed forward the spacing error is driven
    only by the head's lag behind the virtual car (the leader term references the virtual
    car) and the one-period-old radio accelerations. Stated error: |gap - 5 m| <= 0.5 m for
    every follower, and it shrinks down the column."""
    df = run(tmp_path, "sinusoid_cacc_path.toml", 15.0)
    x = wide(df, "x")
    err = np.array([(x[IDS[i - 1]] - x[IDS[i]] - LENGTH_M - 5.0).abs().max() for i in range(1, 8)])
    assert err.max() <= 0.5
    assert np.all(np.diff(err) < 0)
    assert np.abs(wide(df, "y")[IDS].to_numpy()).max() < 1e-6  # the lane kept
