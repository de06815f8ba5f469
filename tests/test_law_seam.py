"""The control-law seam (controller.law, control/laws) and the one integrator over named state
rows (models/integrator.py): a law and a model slot added from outside the package."""
import math

import numpy as np
import pandas as pd
import pytest

import lagged_unicycle
import toy_law
from formation_traci.control.laws import DEFAULT_LAW, law_names, register_law
from formation_traci.models.integrator import HELD, rk4_for
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.runner import run_scenario
from run_helpers import cli, free_toml


def test_default_law_is_the_seeds(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(free_toml(1.0))
    assert load_scenario(p).controller.law == DEFAULT_LAW == "virtual_structure"
    assert "virtual_structure" in law_names()


def test_unknown_law_is_bad_input_naming_the_field(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(free_toml(1.0) + '[controller]\nlaw = "no_such_law"\n')
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    assert "controller.law" in str(ei.value) and "virtual_structure" in str(ei.value)
    code, text = cli("run", p, "--out", tmp_path / "out")
    assert code == 2 and "controller.law" in text
    assert not (tmp_path / "out").exists()


def test_a_law_registered_in_one_module_drives_the_members(tmp_path):
    """The toy law (tests/toy_law.py) holds v = 12.5 m/s straight ahead; the unicycle then
    moves x(t) = x0 + 12.5 t exactly (RK4 of a constant velocity), y constant."""
    register_law("toy_constant_speed", toy_law)
    p = tmp_path / "s.toml"
    p.write_text(free_toml(2.0) + '[controller]\nlaw = "toy_constant_speed"\n')
    sc = load_scenario(p)
    res = run_scenario(sc, tmp_path / "run", force=True, progress=False)
    assert res.status == "completed"
    df = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    a = df[df.vehicle_id == "a"].sort_values("t")
    x0 = a.x.iloc[0]
    assert np.allclose(a.x - x0, toy_law.V_SET * a.t, atol=1e-9, rtol=0)
    assert np.allclose(a.y, a.y.iloc[0], atol=1e-12)
    assert np.allclose(a.v, toy_law.V_SET)
    # the seed's law on the same scenario tracks the 20 m/s leader instead
    q = tmp_path / "q.toml"
    q.write_text(free_toml(2.0))
    run_scenario(load_scenario(q), tmp_path / "seed", force=True, progress=False)
    b = pd.read_parquet(tmp_path / "seed" / "trajectories.parquet")
    assert b[b.vehicle_id == "a"].v.iloc[-1] > 18.0


def test_a_state_slot_added_in_a_copy_of_a_model_is_integrated():
    """tests/lagged_unicycle.py adds a speed slot with a first-order lag tau: from V = 0 under
    u0 = 10 m/s, V(t) = 10 (1 - exp(-t / tau)) and X(t) = 10 (t - tau (1 - exp(-t / tau)))."""
    rk4 = rk4_for(lagged_unicycle)
    tau, u, t_end, h = 0.5, 10.0, 2.0, 0.01
    s = np.zeros(len(lagged_unicycle.SLOTS))
    P = np.array([[tau]])
    rk4(0, s, u, 0.0, P, 0, h, int(round(t_end / h)), np.empty((5, len(s))), HELD)
    e = math.exp(-t_end / tau)
    assert s[3] == pytest.approx(u * (1 - e), abs=1e-8)
    assert s[0] == pytest.approx(u * (t_end - tau * (1 - e)), abs=1e-8)
    assert s[1] == 0.0 and s[2] == 0.0
