"""Scenario validation (refused before anything runs) and the run command's outputs."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from run_contract.columns import TRAJECTORY_COLUMNS
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.runner import run_scenario
from run_contract.rundir import RunDirExists
from run_helpers import free_toml

ROOT = Path(__file__).resolve().parents[1]
GOOD = free_toml(2.0, name="tiny", step=0.05, model="dynamic")


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def problems(tmp_path, text):
    p = write(tmp_path, text)
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert str(p) in msg  # names the file
    return ei.value.problems, msg


def test_good_scenario_loads_with_defaults(tmp_path):
    sc = load_scenario(write(tmp_path, GOOD))
    assert sc.run.control_step == 0.01 and sc.vehicle.tire == "load"
    assert sc.controller.speed_gains == "table_3_4" and sc.controller.yaw_gains == "table_3_8"


@pytest.mark.parametrize("edit,field,expect", [
    (("[run]", "[run]\nspeeed = 3"), "run.speeed", "unknown field"),
    (("duration = 2.0", 'duration = "long"'), "run.duration", "valid number"),
    (("model = \"dynamic\"", "model = \"dynamic\"\n[vehicle.params]\nm = -1480.0"), "vehicle.params.m", "greater than 0"),
    (("[leader]", "[controller]\nk = 0.0\n[leader]"), "controller.k", "greater than 0"),
    (("[leader]", "[controller]\nyaw_gains = { g_min = 0.0, g_max = 3.0, k_min = 10.0 }\n[leader]"),
     "controller.yaw_gains.g_min", "greater than 0"),
    (("offset = [0.0, 3.5]", "offset = [0.0]"), "members.0.offset", "2 items"),
    (("step = 0.05", "step = 0.05\ncontrol_step = 0.03"), "run", "whole number"),
    (("id = \"a\"", "id = \"vc\""), "(document)", "reserved"),
])
def test_bad_scenarios_name_file_field_and_expectation(tmp_path, edit, field, expect):
    probs, msg = problems(tmp_path, GOOD.replace(*edit))
    fields = [f for f, _ in probs]
    assert field in fields, msg
    assert any(expect in m for f, m in probs if f == field), msg


def test_missing_members_and_missing_leader(tmp_path):
    text = GOOD.split("[[members]]")[0]
    for doc in (text, "members = []\n" + text):  # no formation at all (none in [[formations]] either)
        probs, _ = problems(tmp_path, doc)
        assert any("members: at least one member, unless [[formations]] or [[formation_flows]]" in m
                   for _, m in probs), probs
    probs, _ = problems(tmp_path, GOOD.replace("[leader]\nspeed = 20.0", ""))
    assert ("leader", "required field is missing") in probs


def test_several_errors_reported_at_once(tmp_path):
    text = GOOD.replace("duration = 2.0", "duration = -1.0").replace("[leader]", "[leader]\nfoo = 1")
    probs, _ = problems(tmp_path, text)
    assert {"run.duration", "leader.foo"} <= {f for f, _ in probs}


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ScenarioError, match="file not found"):
        load_scenario(tmp_path / "nope.toml")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(write(tmp_path, "[run\nduration = 1"))


def test_cli_refuses_bad_scenario_before_running(tmp_path):
    bad = write(tmp_path, GOOD.replace("[vehicle]", "[vehicle]\nmass = 3"))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "formation_traci.cli", "run", str(bad), "--out", str(out),
                        "--no-progress"], capture_output=True, text=True)
    assert r.returncode == 2
    assert "vehicle.mass" in r.stderr and "unknown field" in r.stderr and str(bad) in r.stderr
    assert not out.exists()  # nothing ran, nothing was created


def test_a_bad_scenario_is_refused_without_importing_the_analysis_package(tmp_path):
    """Telling a bad scenario from a failure once imported every bad-input error class, the
    analysis package's among them (~1.7 s before the message); the run path never needs it."""
    bad = write(tmp_path, GOOD.replace("[vehicle]", "[vehicle]\nmass = 3"))
    code = ("import sys, runpy\n"
            "sys.argv = ['formation-traci', 'run', sys.argv[1], '--out', sys.argv[2], '--no-progress']\n"
            "try:\n    runpy.run_module('formation_traci.cli', run_name='__main__')\n"
            "except SystemExit as e:\n"
            "    print('exit', e.code, sorted(m for m in sys.modules if m.split('.')[0] == 'analysis'))\n")
    r = subprocess.run([sys.executable, "-c", code, str(bad), str(tmp_path / "out")],
                       capture_output=True, text=True)
    assert "vehicle.mass" in r.stderr and r.stdout.strip() == "exit 2 []", (r.stdout, r.stderr)


def test_every_bad_input_class_the_cli_names_exists_where_it_says():
    """cli._BAD_INPUT names its classes by module (none imported before it is needed): a class
    moved elsewhere would turn its exit 2 silently into an exit 1."""
    import importlib

    from formation_traci.cli import _BAD_INPUT
    for module, name in _BAD_INPUT:
        cls = getattr(importlib.import_module(module), name)
        assert issubclass(cls, Exception), (module, name)


def test_run_writes_trajectories_and_run_json(tmp_path):
    sc = load_scenario(write(tmp_path, GOOD), **{"run.seed": 7})
    res = run_scenario(sc, tmp_path / "run", progress=False)
    assert res.status == "completed" and res.t_end == pytest.approx(2.0)
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["status"] == "completed" and meta["seed"] == 7 and meta["t_end"] == pytest.approx(2.0)
    assert meta["scenario"]["run"]["duration"] == 2.0
    assert {"numpy", "pandas", "pyarrow", "formation-traci", "python"} <= set(meta["versions"])
    assert meta["started"] and meta["finished"]
    df = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    assert list(df.columns) == [c.name for c in TRAJECTORY_COLUMNS]
    assert sorted(df.vehicle_id.unique()) == ["a", "vc"]
    assert len(df) == 2 * 41  # t = 0, 0.05, ..., 2.0 for the member and the virtual car
    a = df[df.vehicle_id == "a"]
    np.testing.assert_allclose(np.diff(a.t), 0.05)
    assert a[["x", "y", "v", "ex", "ey", "slip_front", "traction_force"]].notna().all().all()
    vc = df[df.vehicle_id == "vc"]
    assert vc.v_ref.isna().all() and (vc.v == 20.0).all()
    # error columns: e_lon/e_lat are (ex, ey) in the virtual car frame (heading 0 here)
    np.testing.assert_allclose(a.e_lon, a.ex)
    np.testing.assert_allclose(a.e_lat, a.ey)
    np.testing.assert_allclose(a.ex, a.x_des - a.x)


def test_existing_run_dir_refused_unless_force(tmp_path):
    sc = load_scenario(write(tmp_path, GOOD))
    run_scenario(sc, tmp_path / "run", progress=False)
    with pytest.raises(RunDirExists):
        run_scenario(sc, tmp_path / "run", progress=False)
    assert run_scenario(sc, tmp_path / "run", progress=False, force=True).status == "completed"


def test_cli_overrides_duration_and_seed(tmp_path):
    p = write(tmp_path, GOOD)
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "formation_traci.cli", "run", str(p), "--out", str(out),
                        "--duration", "1.0", "--seed", "5", "--model", "kinematic", "--no-progress"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    meta = json.loads((out / "run.json").read_text())
    assert meta["seed"] == 5 and meta["duration"] == 1.0 and meta["model"] == "kinematic"
    assert meta["t_end"] == pytest.approx(1.0)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_model_failure_is_recorded_not_lost(tmp_path):
    """A vehicle state that turns non-finite stops the run as 'failed' with a reason; rows
    recorded before are kept and readable."""
    text = GOOD.replace("duration = 2.0", "duration = 3.0").replace(
        "speed = 20.0", "speed = { t = [0.0, 1.0, 1.01], values = [20.0, 20.0, 1e308] }")
    sc = load_scenario(write(tmp_path, text))
    res = run_scenario(sc, tmp_path / "run", progress=False)
    assert res.status == "failed"
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["status"] == "failed" and "non-finite" in meta["reason"]
    assert 1.0 <= meta["t_end"] < 3.0
    df = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    assert df.t.max() == pytest.approx(meta["t_end"])
    assert (tmp_path / "run" / "error.txt").exists()


def test_same_scenario_same_bytes(tmp_path):
    sc = load_scenario(write(tmp_path, GOOD))
    run_scenario(sc, tmp_path / "r1", progress=False)
    run_scenario(sc, tmp_path / "r2", progress=False)
    a = pd.read_parquet(tmp_path / "r1" / "trajectories.parquet")
    b = pd.read_parquet(tmp_path / "r2" / "trajectories.parquet")
    pd.testing.assert_frame_equal(a, b, check_exact=True)


@pytest.mark.parametrize("path", sorted((ROOT / "scenarios" / "thesis").glob("*.toml")), ids=lambda p: p.stem)
def test_bundled_thesis_scenarios_validate(path):
    sc = load_scenario(path)
    assert sc.description  # each says what it reproduces and what it chose
