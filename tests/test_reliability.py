"""Reliability: any scenario document gives a Scenario or a ScenarioError; SIGKILL leaves
readable data; run.json is enough to repeat a run bit for bit."""
import copy
import json
import os
import signal
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from formation_traci.scenario import ScenarioError, load_scenario, parse_scenario
from formation_traci.scenario.schema import Scenario
from formation_traci.runner import run_scenario
from run_helpers import meta_of, free_toml, spawn, wait_for

ROOT = Path(__file__).resolve().parents[1]
BASE = {
    "name": "prop",
    "run": {"duration": 0.2, "step": 0.05, "control_step": 0.01, "seed": 3},
    "vehicle": {"model": "dynamic", "preset": "passenger_car", "tire": "load", "surface": "good_wet",
                "params": {"m": 1500.0}},
    "controller": {"k": 1.0, "k_theta": 3.0, "speed_gains": "table_3_4",
                   "yaw_gains": {"g_min": 0.7, "g_max": 3.0, "k_min": 10.0}},
    "leader": {"speed": {"t": [0.0, 1.0], "values": [20.0, 22.0], "interp": "smooth"}, "yaw_rate_deg_s": 1.0},
    "members": [{"id": "a", "offset": [0.0, 3.5], "position": [-2.0, 2.0], "heading_deg": 5.0},
                {"id": "b", "offset": [-10.0, 0.0], "position": [-12.0, 0.5], "speed": 18.0}],
}

junk = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                 st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
                 st.lists(st.floats(-1e3, 1e3), max_size=3), st.dictionaries(st.text(max_size=4), st.integers(), max_size=2))


def paths(doc, prefix=()):
    """Every (path, value) in a nested dict/list document."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield prefix + (k,), v
            yield from paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield prefix + (i,), v
            yield from paths(v, prefix + (i,))


ALL_PATHS = [p for p, _ in paths(BASE)]


@st.composite
def mutated(draw):
    doc = copy.deepcopy(BASE)
    for _ in range(draw(st.integers(1, 4))):
        path = draw(st.sampled_from(ALL_PATHS))
        node = doc
        try:
            for key in path[:-1]:
                node = node[key]
            action = draw(st.sampled_from(["replace", "delete", "add"]))
            if action == "replace":
                node[path[-1]] = draw(junk)
            elif action == "delete":
                del node[path[-1]]
            elif isinstance(node, dict):
                node[draw(st.text(min_size=1, max_size=6))] = draw(junk)
        except (KeyError, IndexError, TypeError):
            pass  # an earlier mutation removed or replaced that branch
    return doc


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_loader_returns_a_scenario_or_raises_scenario_error(doc):
    try:
        sc = parse_scenario(doc, "prop.toml")
    except ScenarioError as exc:
        assert exc.problems and all(isinstance(f, str) and isinstance(m, str) for f, m in exc.problems)
        assert str(exc).startswith("invalid scenario")
        return
    assert isinstance(sc, Scenario)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(mutated())
def test_a_valid_scenario_never_crashes_the_simulator(tmp_path_factory, doc):
    """Whatever validates runs: the run ends completed or failed-with-a-reason, never raises."""
    try:
        sc = parse_scenario(doc, "prop.toml", **{"run.duration": 0.1})
    except ScenarioError:
        return
    if sc.road is not None:
        return  # SUMO runs are covered by tests/test_sumo_runs.py
    out = tmp_path_factory.mktemp("prop")
    with np.errstate(all="ignore"):
        res = run_scenario(sc, out / "run", progress=False)
    assert res.status in ("completed", "failed")
    meta = json.loads((out / "run" / "run.json").read_text())
    assert meta["status"] == res.status
    if res.status == "failed":
        assert meta["reason"]


def test_sigkill_leaves_the_chunks_readable(tmp_path):
    """A process killed with SIGKILL keeps every part file written so far; the analysis reads them."""
    sc = tmp_path / "long.toml"
    sc.write_text(free_toml(5000.0))
    out = tmp_path / "run"
    proc = spawn("run", sc, "--out", out, "--no-progress", stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    parts = out / "trajectories.parquet"
    # two parts on disk and run.json's progress past them (it follows the parts by one update)
    wait_for(lambda: len(list(parts.glob("part-*.parquet"))) >= 2
             and (meta_of(out).get("t_end") or 0) > 0, every=0.1)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert len(list(parts.glob("part-*.parquet"))) >= 2
    meta = json.loads((out / "run.json").read_text())
    assert meta["status"] == "running"  # never finished: says how far it got
    df = pd.read_parquet(parts)  # temporary '.part-*.tmp' files are ignored by the reader
    assert df.t.max() >= meta["t_end"] > 0
    from analysis.api import analyze_run
    res = analyze_run(out, figures=False)
    assert len(res.members) == 1
    assert (out / "metrics.json").exists()


@pytest.mark.parametrize("path", [ROOT / "scenarios" / "thesis" / "dynamic_case3.toml",
                                  ROOT / "scenarios" / "highway" / "onramp_merge.toml"], ids=lambda p: p.stem)
def test_run_json_is_enough_to_repeat_the_run(tmp_path, path):
    """The scenario echo and seed in run.json reproduce the run bit for bit."""
    sc = load_scenario(path, **{"run.duration": 4.0, "traffic.warmup": 10.0} if "highway" in str(path)
                       else {"run.duration": 4.0})
    run_scenario(sc, tmp_path / "first", scenario_path=path, progress=False)
    meta = json.loads((tmp_path / "first" / "run.json").read_text())
    again = parse_scenario(meta["scenario"], meta["scenario_path"])
    run_scenario(again, tmp_path / "again", scenario_path=meta["scenario_path"], progress=False)
    for table in ("trajectories", "background"):
        if (tmp_path / "first" / f"{table}.parquet").exists():
            a = pd.read_parquet(tmp_path / "first" / f"{table}.parquet")
            b = pd.read_parquet(tmp_path / "again" / f"{table}.parquet")
            pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert meta["versions"]["numpy"] and meta["seed"] == sc.run.seed
    if "highway" in str(path):
        assert meta["versions"]["sumo"].startswith("SUMO 1.28")
