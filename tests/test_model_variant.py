"""A state slot added from outside the package (tests/toy_slot.py: the dynamic bicycle with an
odometer): its module holds its slots, its parameter record (SPEC, with its default), the
packing and the right-hand side; one registration line makes it a variant the scenario names
(``vehicle.variant``), and ``[vehicle.<variant>]`` sets its parameter. It runs in free space
and on a road (real SUMO, the compiled step of the usual steps); the odometer is checked
against the integral of the recorded speed."""
import json

import numpy as np
import pandas as pd
import pytest

import toy_law
import toy_slot
from formation_traci.control.laws import register_law
from formation_traci.models.variants import register_model
from formation_traci.runner import run_scenario
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.sim import free_path
from formation_traci.sim.fleet import Fleet
from formation_traci.sumo import fused_path

register_model(toy_slot.NAME, toy_slot)  # the one registration line

VEHICLE = """
[vehicle]
model = "dynamic"
{variant}
[leader]
speed = {v}
[[members]]
id = "a"
{where_a}
[[members]]
id = "b"
{where_b}
"""
FREE = "[run]\nduration = 10.0\n" + VEHICLE
ROAD = """
[run]
duration = 12.0
[road]
net = "straight3"
lane = 1
start = 200.0
""" + VEHICLE
FREE_WHERE = {"where_a": "offset = [0.0, 0.0]\nposition = [0.0, 0.0]",
              "where_b": "offset = [-10.0, 0.0]\nposition = [-12.0, 1.0]", "v": 15.0}
ROAD_WHERE = {"where_a": "slot = { along = 0.0, lanes = 0 }",
              "where_b": "slot = { along = -20.0, lanes = 0 }", "v": 14.0}
TOY = f'variant = "{toy_slot.NAME}"\n'


def _run(tmp_path, monkeypatch, text, out, **fill):
    """The run's members' rows, the members' state after each step (t [s] -> state rows),
    through the loop's step and the compiled ones (road, free space), and the steps the
    compiled ones took."""
    states, taken = {}, []
    step, fused, free = Fleet.step, fused_path.FusedPath.step, free_path.FreePath.step

    def loop_step(self, state, ref, *a, **kw):
        new = step(self, state, ref, *a, **kw)
        states[round(ref.t + ref.dt * ref.n_ctrl, 9)] = new.x.copy()
        return new

    def fused_step(self, k, t, *a):
        new = fused(self, k, t, *a)
        taken.append(k)
        states[round(t + self.step_s, 9)] = new.x.copy()
        return new

    def free_step(self, k, t, *a):
        new = free(self, k, t, *a)
        taken.append(k)
        states[round(t + self.step_s, 9)] = new.x.copy()
        return new

    monkeypatch.setattr(Fleet, "step", loop_step)
    monkeypatch.setattr(fused_path.FusedPath, "step", fused_step)
    monkeypatch.setattr(free_path.FreePath, "step", free_step)
    p = tmp_path / f"{out}.toml"
    p.write_text(text.format(**fill))
    res = run_scenario(load_scenario(p), tmp_path / out, scenario_path=p, progress=False)
    assert res.status == "completed", res.reason
    traj = pd.read_parquet(tmp_path / out / "trajectories.parquet")
    return traj[traj.vehicle_id.isin(["a", "b"])].sort_values(["vehicle_id", "t"]), states, taken


def _odometer_is_the_distance(traj, states, scale):
    """ODO at the run's end = scale x the trapezoid integral of the recorded speed v (every
    0.05 s; its error, h^2/12 x the integral of |v''|, stays below 1 cm here), per member."""
    t_end = traj.t.max()
    x = states[round(t_end, 9)]
    assert x.shape[1] == toy_slot.ODO + 1
    for i, vid in enumerate(["a", "b"]):
        m = traj[traj.vehicle_id == vid]
        dist = float(np.sum(np.diff(m.t) * (m.v.values[1:] + m.v.values[:-1]) / 2))
        assert dist > 100.0
        assert x[i, toy_slot.ODO] == pytest.approx(scale * dist, abs=0.01), (vid, dist)


def test_a_state_slot_added_from_outside_runs_in_free_space(tmp_path, monkeypatch):
    """The odometer reads 1.02 x the distance; the bicycle's slots, and so every file, are
    those of the same run without the variant, byte for byte."""
    traj, states, _ = _run(tmp_path, monkeypatch, FREE, "toy",
                        variant=TOY + f"[vehicle.{toy_slot.NAME}]\nscale = 1.02", **FREE_WHERE)
    _odometer_is_the_distance(traj, states, 1.02)
    vehicle = json.loads((tmp_path / "toy" / "run.json").read_text())["scenario"]["vehicle"]
    assert (vehicle["variant"], vehicle["variant_params"]) == (toy_slot.NAME, {toy_slot.NAME: {"scale": 1.02}})
    _run(tmp_path, monkeypatch, FREE, "plain", variant="", **FREE_WHERE)
    a, b = tmp_path / "toy", tmp_path / "plain"
    parts = {p.relative_to(a).as_posix() for p in a.rglob("*.parquet") if p.is_file()}
    assert parts == {p.relative_to(b).as_posix() for p in b.rglob("*.parquet") if p.is_file()}
    assert "trajectories.parquet/part-00000.parquet" in parts
    for part in sorted(parts):
        assert (a / part).read_bytes() == (b / part).read_bytes(), part


def test_a_state_slot_added_from_outside_runs_on_a_road(tmp_path, monkeypatch):
    """Real SUMO: the usual steps are the compiled step's (a copy integrating the variant)
    and the odometer, at its default calibration 1, reads the distance."""
    monkeypatch.setenv(fused_path.SWITCH, "on")
    traj, states, taken = _run(tmp_path, monkeypatch, ROAD, "road", variant=TOY, **ROAD_WHERE)
    steps = traj.t.nunique()
    assert len(taken) > 0.8 * steps, f"only {len(taken)} of {steps} steps compiled"
    _odometer_is_the_distance(traj, states, 1.0)


def test_a_state_slot_runs_under_a_law_added_from_outside(tmp_path, monkeypatch):
    """The variant under the toy law (tests/toy_law.py, registered at run time too: one step
    kernel dispatching to the law and integrating the variant): the members approach v_set =
    12.5 m/s from the leader's 15 m/s, and the odometer reads the distance."""
    register_law(toy_law.NAME, toy_law)
    text = FREE + f'[controller]\nlaw = "{toy_law.NAME}"\n'
    traj, states, _ = _run(tmp_path, monkeypatch, text, "both", variant=TOY, **FREE_WHERE)
    last = traj[traj.t == traj.t.max()]
    assert (abs(last.v - toy_law.V_SET) < 1e-3).all(), last.v.tolist()
    _odometer_is_the_distance(traj, states, 1.0)


def test_a_variant_parameter_its_spec_refuses_is_bad_input_naming_the_field(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(FREE.format(variant=TOY + f"[vehicle.{toy_slot.NAME}]\nscale = -1.0", **FREE_WHERE))
    with pytest.raises(ScenarioError, match=f"vehicle.*{toy_slot.NAME}.scale.*greater than 0"):
        load_scenario(p)


def test_a_variant_of_another_model_is_bad_input(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(FREE.format(variant=TOY, **FREE_WHERE).replace('model = "dynamic"', 'model = "kinematic"'))
    with pytest.raises(ScenarioError, match="variant.*extends the dynamic model"):
        load_scenario(p)
