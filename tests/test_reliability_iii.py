"""Reliability III (issue 31): nothing written outside --out or through a symlink, a lock
--force cannot race, bad values refused before SUMO starts, honest records on a full disk,
damaged analysis inputs described. Each test reproduces one finding of the probe (it failed on
the code before the fix) with real SUMO and real processes; docs/reliability.md maps them."""
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.sim.runner import run_scenario
from run_helpers import cli, meta_of, spawn, wait_for
from test_reliability_ii import free, previous_run, road, tmpfs

ROOT = Path(__file__).resolve().parents[1]
SUMO_NETS = ROOT / "sumo_nets"


def tree(d: Path) -> dict:
    """Every path under ``d`` (relative) -> its bytes (files) or None (directories, links)."""
    out = {}
    for p in sorted(d.rglob("*")):
        rel = str(p.relative_to(d))
        out[rel] = p.read_bytes() if p.is_file() and not p.is_symlink() else None
    return out


# -- 1. bad values refused before SUMO starts (exit 2 naming the field, nothing created) -----------
@pytest.mark.parametrize("flow, field", [
    ("veh_per_hour_per_lane = 1e308", "traffic.flows.0.veh_per_hour_per_lane"),
    ("veh_per_hour_per_lane = 1e9", "traffic.flows.0.veh_per_hour_per_lane"),
    ("veh_per_hour = 1e12", "traffic.flows.0.veh_per_hour"),
    ("veh_per_hour_per_lane = 800\nbegin = 50.0\nend = 10.0", "traffic.flows.0.end")],
    ids=["1e308", "1e9", "total", "end-before-begin"])
def test_flow_values_sumo_would_refuse_exit_2_before_anything_is_created(tmp_path, flow, field):
    sc = road(tmp_path)
    sc.write_text(sc.read_text().replace("veh_per_hour_per_lane = 800", flow))
    code, text = cli("run", sc, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and field in text and "Traceback" not in text, text
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("options", [
    '["--version"]', '[""]', '["my.sumocfg"]', '["--tripinfo-output", "a.xml", "--tripinfo-output", "b.xml"]',
    '["--no-warnings=/x"]', '["--verbose=/x"]', '["--time-to-teleport", "soon"]'],
    ids=["version", "empty", "positional", "twice", "managed-bool", "bad-bool", "bad-time"])
def test_sumo_options_sumo_refuses_at_start_are_bad_input(tmp_path, options):
    (tmp_path / "my.sumocfg").write_text("<configuration/>")
    code, text = cli("run", road(tmp_path, options=options), "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "sumo.options." in text and "Traceback" not in text, text
    assert "inserted 0 of" not in text and "Error:" not in text and "Quitting" not in text, text
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("option", ["--save-state.times", "--save-state.period"])
def test_sumo_save_state_never_writes_into_the_working_directory(tmp_path, option):
    work = tmp_path / "work"
    work.mkdir()
    code, text = cli("run", road(tmp_path, options=f'["{option}", "1"]'), "--out", tmp_path / "run",
                     "--no-progress", cwd=work)
    assert code == 2 and "sumo.options.0" in text, text
    assert list(work.iterdir()) == [] and not (tmp_path / "run").exists()


@pytest.mark.parametrize("content", [
    None, '<net version="1.20">\n  <edge id="a" from="x" to="y">\n    <lane id="a_0" index="0" ',
    '<?xml version="1.0"?>\n<!DOCTYPE net [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>\n'
    '<net version="1.20"><location netOffset="0,0"/>&b;</net>\n'], ids=["corrupt", "truncated", "entities"])
def test_a_corrupt_truncated_or_entity_laden_network_exits_2(tmp_path, content):
    if content is None:  # a real network with a byte cut out of a tag half-way
        text = (SUMO_NETS / "straight3.net.xml").read_text()
        content = text[: len(text) // 2] + "<<>" + text[len(text) // 2:]
    (tmp_path / "bad.net.xml").write_text(content)
    sc = road(tmp_path, net="bad.net.xml")
    sc.write_text(sc.read_text().replace('start = 300.0', 'route = ["a"]\nstart = 300.0'))
    code, text = cli("run", sc, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "road.net" in text and "Traceback" not in text, text
    assert not (tmp_path / "run").exists()


def test_deep_nesting_and_huge_files_of_unknown_keys_are_refused_at_once(tmp_path):
    deep = tmp_path / "deep.toml"
    deep.write_text(free(tmp_path).read_text() + "x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    code, text = cli("run", deep, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "nested" in text and "Traceback" not in text, text[-500:]
    huge = tmp_path / "huge.toml"
    huge.write_text(free(tmp_path).read_text() + "".join(f"k{i} = 1\n" for i in range(600_000)))
    t0 = time.monotonic()
    code, text = cli("run", huge, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "bytes" in text and len(text) < 2000 and time.monotonic() - t0 < 10, text[-500:]
    # below the size cap: the error list is capped, the count given
    many = tmp_path / "many.toml"
    many.write_text(free(tmp_path).read_text() + "".join(f"k{i} = 1\n" for i in range(3000)))
    code, text = cli("run", many, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "3000 problems" in text and "and 2980 more" in text and text.count("unknown field") <= 40, text[-500:]
    assert not (tmp_path / "run").exists()


# -- 2. strict types: nothing coerced -------------------------------------------------------------
@pytest.mark.parametrize("field, value", [
    ("run.duration", '"5"'), ("run.seed", "true"), ("run.seed", "1.0"), ("leader.speed", '"20"'),
    ("road.lane", "true"), ("traffic.warmup", '"0"'),
    ("traffic.flows.0.veh_per_hour_per_lane", '"800"')], ids=lambda v: str(v))
def test_types_are_strict_for_every_field(tmp_path, field, value):
    import tomllib

    doc = tomllib.loads(road(tmp_path).read_text())
    *path, last = field.split(".")
    node = doc
    for k in path:
        node = node[int(k)] if k.isdigit() else node.setdefault(k, {})
    node[last] = tomllib.loads(f"v = {value}")["v"]
    from formation_traci.scenario.load import parse_scenario
    with pytest.raises(ScenarioError) as err:
        parse_scenario(doc, "s.toml")
    assert field in [f for f, _ in err.value.problems], err.value.problems
    ints = tomllib.loads(road(tmp_path).read_text().replace("duration = 1.0", "duration = 1"))
    assert parse_scenario(ints).run.duration == 1.0  # an integer is still a number of seconds
