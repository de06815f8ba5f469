"""The usual free-space step as one compiled call (sim/free_path.py, sim/free_step.py) writes
the files the loop's own step writes, byte for byte: each case is run twice through the real
runner, with the compiled step and with ``FORMATION_TRACI_FUSED=off``.

Each case also checks that the compiled step took most of the run's steps (a compiled path
that silently never ran would pass the comparison) and, where a case is about events, that the
run had them."""
from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

import toy_law
from formation_traci.control.laws import register_law
from formation_traci.runner import run_scenario
from formation_traci.scenario import load_scenario
from formation_traci.sim import free_path, recorder as recorder_module
from formation_traci.sim.loop import free_space_run
from run_helpers import same_run_files

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "scenarios" / "thesis"

TWO = """[run]
duration = 8.0
[vehicle]
model = "dynamic"
[leader]
speed = 20.0
[[members]]
id = "a"
offset = [0.0, 3.5]
position = [-2.0, 2.0]
[[members]]
id = "b"
offset = [-8.0, 0.0]
position = [-10.0, 1.0]
[[formations]]
id = "east"
controller = { law = "toy_constant_speed", k = 1.5 }
[formations.leader]
x = 0.0
y = 200.0
speed = 15.0
yaw_rate_deg_s = 3.0
[[formations.members]]
id = "c"
offset = [0.0, -3.5]
position = [1.0, 195.0]
[[formations.members]]
id = "d"
offset = [-8.0, 0.0]
position = [-9.0, 201.0]
"""
"""Two formations in free space, the second under a law registered at run time
(tests/toy_law.py; tests/test_formations.py's pair)."""

OVERLAP = """[run]
duration = 10.0
[vehicle]
model = "dynamic"
[leader]
speed = 15.0
[[members]]
id = "a"
offset = [0.0, 0.5]
position = [-2.0, 4.0]
[[members]]
id = "b"
offset = [0.0, -0.5]
position = [-2.0, -4.0]
"""
"""Two members whose slots are 1 m apart abreast (their bodies 1.8 m wide): they collide as
they close on their slots (member_collision events, from the compiled step's clearances)."""

MOST = 0.8
"""The share of a case's steps the compiled step must take at least ..."""
FEWER = {"kinematic model, signals out of range": 0.35}
"""... but there the members drive above the recorder's limit from ~12 s on: every step after
a flagged one is the loop's (Recorder.any_out)."""

# name: (scenario file or text, overrides, recorder speed limit [m/s], steps per part file,
# events the run must have)
CASES = {
    "dynamic model, three members, tables cut every 40 steps": (
        THESIS / "dynamic_case4_turning.toml", {"run.duration": 20.0}, None, 40, set()),
    "kinematic model, signals out of range": (  # the leader goes 20 -> 25 m/s: above 22.5 m/s
        # the members' rows are flagged (model_range) and the steps after are the loop's
        THESIS / "case_2_3_3_varying.toml", {"run.duration": 30.0}, 22.5, None, {"model_range"}),
    "independent members": (THESIS / "dynamic_case3.toml", {"run.duration": 10.0}, None, None, set()),
    "resistances without the drag interaction": (  # fixed road load: no per-step part
        THESIS / "dynamic_case4_turning.toml",
        {"run.duration": 10.0, "energy.resistances": True, "energy.drag_interaction": False},
        None, None, set()),
    "two formations, a law registered at run time": (TWO, {}, None, 30, set()),
    "resistances with the drag interaction": (  # the drag ratios set each step
        THESIS / "dynamic_case4_turning.toml",
        {"run.duration": 10.0, "energy.resistances": True, "energy.drag_interaction": True},
        None, None, set()),
    "members that collide": (OVERLAP, {}, None, None, {"member_collision"}),
    "two formations, resistances with the drag interaction": (
        TWO, {"energy.resistances": True, "energy.drag_interaction": True}, None, None, set()),
}


def _run(tmp_path, name, case, monkeypatch, fused: bool):
    src, overrides, v_max, chunk, _ = case
    if v_max is not None:
        monkeypatch.setattr(recorder_module, "MAX_SPEED", v_max)
    if chunk is not None:
        monkeypatch.setattr(recorder_module, "STEPS_PER_CHUNK", chunk)
    monkeypatch.setenv(free_path.SWITCH, "on" if fused else "off")
    if isinstance(src, str):
        path = tmp_path / "scenario.toml"
        path.write_text(src)
    else:
        path = src
    out = tmp_path / name
    res = run_scenario(load_scenario(path, **overrides), out, scenario_path=path, progress=False)
    return res, out


@pytest.mark.parametrize("name", list(CASES))
def test_compiled_free_steps_write_the_files_of_the_loops_own_steps(tmp_path, monkeypatch, name):
    register_law(toy_law.NAME, toy_law)
    case = CASES[name]
    taken = []
    step = free_path.FreePath.step
    monkeypatch.setattr(free_path.FreePath, "step",
                        lambda self, *a: taken.append(a[0]) or step(self, *a))
    fused, a = _run(tmp_path, "fused", case, monkeypatch, True)
    n_fused = len(taken)
    loop, b = _run(tmp_path, "loop", case, monkeypatch, False)
    assert len(taken) == n_fused  # the switch turned the compiled path off
    incident = "member_collision" in case[4]  # a run never hides one: its status says so
    assert fused.status == ("completed_with_incidents" if incident else "completed"), fused.reason
    assert n_fused > FEWER.get(name, MOST) * fused.steps_done, f"only {n_fused} of {fused.steps_done} steps compiled"
    ev = pd.read_parquet(a / "events.parquet")
    assert case[4] <= set(ev.kind), f"the case provoked {sorted(set(ev.kind))}"
    if "model_range" in case[4]:
        assert n_fused < fused.steps_done - 1  # the steps after a flagged one were the loop's
    assert (fused.status, fused.reason, fused.steps_done) == (loop.status, loop.reason, loop.steps_done)
    parts = same_run_files(a, b)
    if case[3] is not None:
        assert len(parts) > 3  # the tables were cut


def test_the_loop_runs_every_step_without_compiled_kernels_with_a_radio_or_switched_off(monkeypatch):
    """NUMBA_DISABLE_JIT (the plain-Python reference), a transform (the radio: [comm]) and
    the switch take the loop's path."""
    from numba import config

    sc = load_scenario(THESIS / "dynamic_case4_turning.toml")
    rec = _Rec()
    parts = free_space_run(sc)
    monkeypatch.setattr(config, "DISABLE_JIT", True)
    assert free_path.free_path(parts, rec, sc, None) is None
    monkeypatch.setattr(config, "DISABLE_JIT", False)
    monkeypatch.setenv(free_path.SWITCH, "off")
    assert free_path.free_path(parts, rec, sc, None) is None
    monkeypatch.delenv(free_path.SWITCH)
    parts.formations[0].transforms.append(lambda ref: ref)
    assert free_path.free_path(parts, rec, sc, None) is None


class _Rec:
    """What free_path asks of the recorder before it builds the path."""

    class incidents:  # noqa: N801
        lane_watch = None
