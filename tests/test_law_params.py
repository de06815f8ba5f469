"""A law added from outside the package with its own parameters (tests/toy_law.py): its module
holds the parameter schema (SPEC, with its default), the packing and the kernel; one
registration line makes it a law the scenario names, and ``[controller.<law>]`` sets its
parameters, validated by its SPEC. It runs in free space and on a road; a value its SPEC
refuses is bad input naming the field."""
import json

import pandas as pd
import pytest

import toy_law
from formation_traci.control.laws import register_law
from formation_traci.runner import run_scenario
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.sumo import fused_path

register_law(toy_law.NAME, toy_law)  # the one registration line

MEMBERS = """
[controller]
law = "{law}"
[controller.{law}]
v_set = {v}
[[members]]
id = "a"
{where_a}
[[members]]
id = "b"
{where_b}
"""
FREE = """
[run]
duration = 12.0
[vehicle]
model = "kinematic"
[leader]
speed = 10.0
""" + MEMBERS
ROAD = """
[run]
duration = 12.0
[road]
net = "straight3"
lane = 1
start = 200.0
[leader]
speed = 10.0
""" + MEMBERS


def _run(tmp_path, text, out="run", **where):
    p = tmp_path / "toy.toml"
    p.write_text(text.format(law=toy_law.NAME, **where))
    res = run_scenario(load_scenario(p), tmp_path / out, scenario_path=p, progress=False)
    assert res.status == "completed", res.reason
    traj = pd.read_parquet(tmp_path / out / "trajectories.parquet")
    return traj[traj.vehicle_id.isin(["a", "b"])]


def test_a_law_added_from_outside_reads_its_parameters_in_free_space(tmp_path):
    """The unicycle takes v_set as its speed input: every member at exactly 8.5 m/s."""
    m = _run(tmp_path, FREE, v=8.5, where_a='offset = [0.0, 0.0]\nposition = [0.0, 0.0]',
             where_b='offset = [-10.0, 0.0]\nposition = [-10.0, 0.0]')
    assert (m[m.t > 0.5].v == 8.5).all()


def test_a_law_added_from_outside_reads_its_parameters_on_a_road(tmp_path):
    """The dynamic model approaches v_set = 14 m/s as a first order lag of 0.5 s from the
    leader's 10 m/s: after 12 s (24 time constants) within 1e-3 m/s of it."""
    m = _run(tmp_path, ROAD, v=14.0, where_a='slot = { along = 0.0, lanes = 0 }',
             where_b='slot = { along = -20.0, lanes = 0 }')
    last = m[m.t == m.t.max()]
    assert len(last) == 2 and (abs(last.v - 14.0) < 1e-3).all(), last.v.tolist()


@pytest.mark.parametrize("value, words", [("-1.0", "greater than 0"), ('"fast"', "valid number")])
def test_a_parameter_its_spec_refuses_is_bad_input_naming_the_field(tmp_path, value, words):
    p = tmp_path / "toy.toml"
    p.write_text(FREE.format(law=toy_law.NAME, v=value, where_a='offset = [0.0, 0.0]\nposition = [0.0, 0.0]',
                             where_b='offset = [-10.0, 0.0]\nposition = [-10.0, 0.0]'))
    with pytest.raises(ScenarioError, match=f"controller.*{toy_law.NAME}.v_set.*{words}"):
        load_scenario(p)


def test_a_law_added_from_outside_takes_the_compiled_step_on_a_road(tmp_path, monkeypatch):
    """The usual steps of the road run with the toy law are the compiled step's
    (sumo/fused_path.py: a copy of fused_step calling the law) and its files are those of the
    same run with every step the loop's (FORMATION_TRACI_FUSED=off), byte for byte."""
    taken = []
    step = fused_path.FusedPath.step
    monkeypatch.setattr(fused_path.FusedPath, "step",
                        lambda self, *a: taken.append(a[0]) or step(self, *a))
    where = {"v": 14.0, "where_a": 'slot = { along = 0.0, lanes = 0 }',
             "where_b": 'slot = { along = -20.0, lanes = 0 }'}
    monkeypatch.setenv(fused_path.SWITCH, "on")
    steps = _run(tmp_path, ROAD, out="fused", **where).t.nunique()
    n_fused = len(taken)
    monkeypatch.setenv(fused_path.SWITCH, "off")
    _run(tmp_path, ROAD, out="loop", **where)
    assert len(taken) == n_fused  # the switch turned the compiled step off
    a, b = tmp_path / "fused", tmp_path / "loop"
    meta = json.loads((a / "run.json").read_text())
    assert n_fused > 0.8 * steps and "fused_step" in meta["timing_s"], n_fused
    assert "fused_step" not in json.loads((b / "run.json").read_text())["timing_s"]
    parts = {p.relative_to(a).as_posix() for p in a.rglob("*.parquet") if p.is_file()}
    assert parts == {p.relative_to(b).as_posix() for p in b.rglob("*.parquet") if p.is_file()}
    assert "trajectories.parquet/part-00000.parquet" in parts
    for part in sorted(parts):
        assert (a / part).read_bytes() == (b / part).read_bytes(), part
