"""The merge study's files (docs/maneuvers.md, "The merge study"): scenarios/studies/merge.toml
(three abreast) and merge_column.toml (a 3-car column in the merge lane) expand into shape x
ramp demand x mode x seed cases that validate, and docs/merge_study.py's table pairs each mode
with the same seed's ``none`` (no runs: a summary written here)."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pandas as pd
import pytest

from formation_traci.scenario import load_scenario
from formation_traci.sweep import load_sweep

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "scenarios" / "studies"


def _study_script():
    spec = importlib.util.spec_from_file_location("merge_study", ROOT / "docs" / "merge_study.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name, lane, slots", [
    ("merge.toml", 1, [(0.0, -1), (0.0, 0), (0.0, 1)]),
    ("merge_column.toml", 0, [(0.0, 0), (-12.0, 0), (-24.0, 0)]),
])
def test_the_merge_studies_cross_ramp_demand_mode_and_seed(name, lane, slots):
    sw = load_sweep(STUDIES / name)
    assert len(sw.cases) == 2 * 3 * 3
    seen = set()
    for case in sw.cases:
        sc = load_scenario(sw.base, **case.overrides)
        assert sc.road.net == "onramp" and sc.road.lane == lane and sc.run.duration == 60.0
        assert [(m.slot.along, m.slot.lanes) for m in sc.members] == slots
        ramp = sc.traffic.flows[1]
        assert ramp.route[0] == "ramp" and sc.traffic.flows[0].veh_per_hour_per_lane == 1200
        seen.add((ramp.veh_per_hour, sc.cooperation.merge, sc.run.seed))
    assert seen == {(d, m, s) for d in (600.0, 900.0) for m in ("none", "open_gap", "shift") for s in (1, 2, 3)}


def test_the_table_pairs_each_mode_with_the_same_seeds_none(tmp_path):
    rows = []
    for mode, loss in (("none", (4.0, 2.0, 6.0)), ("open_gap", (3.0, 2.0, 4.0)), ("shift", (3.0, 2.0, 4.0))):
        for seed, x in zip((1, 2, 3), loss):
            rows.append({"seed": seed, "traffic.flows.1.veh_per_hour": 900.0, "cooperation.merge": mode,
                         "status": "completed", "ramp_vehicles": 10, "ramp_merged_before_lane_end": 9,
                         "ramp_speed_loss_mps": x, "ramp_wait_s": 0.0, "emergency_brakes": 0,
                         "member_collisions": 0})
    rows.append({**rows[0], "seed": 4, "status": "failed"})  # not counted
    pd.DataFrame(rows).to_parquet(tmp_path / "summary.parquet")
    (tmp_path / "sweep.json").write_text(json.dumps({"base": "/x/scenarios/highway/onramp_column.toml"}))
    t = _study_script().table([tmp_path]).set_index("merge")
    assert list(t.index) == ["none", "open_gap", "shift"] and set(t["shape"]) == {"column"}
    assert (t["seeds"] == 3).all() and (t["ramp_vehicles"] == 30).all()
    assert t.loc["none", "ramp_speed_loss_mps"] == pytest.approx(4.0)
    assert t.loc["open_gap", "loss_vs_none"] == pytest.approx(-1.0)  # (-1, 0, -2) over the seeds
    assert t.loc["open_gap", "loss_vs_none_lo"] < -1.0 < t.loc["open_gap", "loss_vs_none_hi"]
    assert t.loc["none", "merged_share"] == pytest.approx(0.9)


@pytest.mark.parametrize("name, lane", [("merge_seeds.toml", 1), ("merge_column_seeds.toml", 0)])
def test_the_twenty_seed_studies_cross_mode_and_seed_at_900_veh_h(name, lane, tmp_path):
    sw = load_sweep(STUDIES / name)
    assert len(sw.cases) == 3 * 20
    seen = set()
    for case in sw.cases:
        sc = load_scenario(sw.base, **case.overrides)
        assert sc.road.net == "onramp" and sc.road.lane == lane and sc.run.duration == 60.0
        seen.add((sc.traffic.flows[1].veh_per_hour, sc.cooperation.merge, sc.run.seed))
    assert seen == {(900.0, m, s) for m in ("none", "open_gap", "shift") for s in range(1, 21)}
    # the table takes the one ramp demand from the study's overrides (no grid column for it)
    rows = [{"seed": s, "cooperation.merge": m, "status": "completed", "ramp_vehicles": 10,
             "ramp_merged_before_lane_end": 10, "ramp_speed_loss_mps": 2.0 + (m == "none"),
             "ramp_wait_s": 0.0, "emergency_brakes": 0, "member_collisions": 0}
            for m in ("none", "open_gap", "shift") for s in range(1, 11)]
    pd.DataFrame(rows).to_parquet(tmp_path / "summary.parquet")
    (tmp_path / "sweep.json").write_text(json.dumps(
        {"base": str(sw.base), "sweep": {"overrides": {"traffic.flows.1.veh_per_hour": 900.0}}}))
    t = _study_script().table([tmp_path]).set_index("merge")
    assert (t["ramp_veh_h"] == 900.0).all() and (t["seeds"] == 10).all()
    assert t.loc["shift", "loss_vs_none"] == pytest.approx(-1.0)
