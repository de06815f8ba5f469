"""Traffic interaction measured right (issue 29): the generic ``--set`` override of ``run`` and
``sweep``, the twin that meets the same vehicles, the measurement sections timed in both runs,
paired effects over seeds."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from run_helpers import cli, free_toml

ROOT = Path(__file__).resolve().parents[1]
HIGHWAY = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"


# --- --set KEY=VALUE -----------------------------------------------------------------------
def test_run_set_overrides_any_field_as_toml_values(tmp_path):
    p = tmp_path / "free.toml"
    p.write_text(free_toml(5.0))
    out = tmp_path / "o"
    code, text = cli("run", p, "--out", out, "--no-progress", "--set", "run.duration=1.0",
                     "--set", "run.seed=7", "--set", "vehicle.model=dynamic",
                     "--set", "members.0.offset=[0.0, 2.5]")
    assert code == 0, text
    meta = json.loads((out / "run.json").read_text())
    assert (meta["duration"], meta["seed"], meta["model"]) == (1.0, 7, "dynamic")
    assert meta["scenario"]["members"][0]["offset"] == [0.0, 2.5]
    code, text = cli("run", p, "--out", tmp_path / "o2", "--no-progress", "--set", "run.duration=1.0",
                     "--duration", "0.5")  # the named option wins over --set
    assert code == 0 and json.loads((tmp_path / "o2" / "run.json").read_text())["duration"] == 0.5


@pytest.mark.parametrize("pair, field", [("run.duration=-1", "run.duration"),
                                         ("run.durration=3", "run.durration"),
                                         ("controller.k=soft", "controller.k"),
                                         ("run.duration", "--set run.duration"),
                                         ("=3", "--set =3")])
def test_run_bad_set_exits_2_naming_the_field_nothing_created(tmp_path, pair, field):
    p = tmp_path / "free.toml"
    p.write_text(free_toml(1.0))
    out = tmp_path / "o"
    code, text = cli("run", p, "--out", out, "--set", pair)
    assert code == 2, text
    assert field in text and str(p) in text and "Traceback" not in text
    assert not out.exists()


def test_sweep_set_reaches_every_case_and_bad_set_refuses_the_sweep(tmp_path):
    from formation_traci.sweep import load_sweep

    sweep = tmp_path / "s.toml"
    rel = os.path.relpath(ROOT / "scenarios" / "thesis" / "case_2_3_1_straight.toml", tmp_path)
    sweep.write_text(f'base = "{rel}"\nseeds = [1, 2]\n[overrides]\n"run.duration" = 1.5\n'
                     '[grid]\n"controller.k" = [1.0, 2.0]\n')
    cases = load_sweep(sweep, {"run.duration": 0.5}).cases
    assert all(c.overrides["run.duration"] == 0.5 for c in cases) and len(cases) == 4
    for pair, field in (("controller.k=3", "--set controller.k"), ("run.seed=3", "--set run.seed"),
                        ("run.duration=-2", "run.duration"), ("members.9.k=1", "--set members.9.k")):
        out = tmp_path / f"out_{field.split()[-1]}"
        code, text = cli("sweep", sweep, "--out", out, "--no-progress", "--set", pair)
        assert code == 2, text
        assert field in text and "Traceback" not in text
        assert not out.exists()
    out = tmp_path / "ok"
    code, text = cli("sweep", sweep, "--out", out, "--no-progress", "--workers", "2",
                     "--set", "run.duration=0.5")
    assert code == 0, text
    for c in cases:
        assert json.loads((out / "cases" / c.id / "run.json").read_text())["duration"] == 0.5
