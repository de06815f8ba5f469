"""Traffic demand inserted as asked and reported (issue 15, item 1): real SUMO runs, shortened."""
import json
from pathlib import Path

import pandas as pd
import pytest

from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario
from formation_traci.sumo.traffic import requested_vehicles
from formation_traci.sweep import run_sweep

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ROOT / "scenarios" / "highway" / "straight_3lane_heavy.toml"


def test_requested_vehicles_counts_departures_of_the_window():
    # one vehicle every 1.8 s from t = 10 s: departures at 10, 11.8, ..., 98.2 before 100 s
    assert requested_vehicles(2000.0, 10.0, 1e9, 100.0) == 50
    assert requested_vehicles(2000.0, 10.0, 1e9, 100.1) == 51
    assert requested_vehicles(2000.0, 10.0, 55.0, 100.0) == 25  # 10 ... 53.2, none at 55
    assert requested_vehicles(2000.0, 120.0, 200.0, 100.0) == 0


def test_density_sweep_inserts_the_heavy_demand_and_rows_differ(tmp_path):
    """straight_3lane_heavy asks >= 2000 veh/h/lane and SUMO inserts >= 95 % of it; a density
    sweep over it has rows that differ in inserted vehicles and in the flow measured downstream
    (before, 1,600 and 2,200 veh/h/lane inserted the same vehicles)."""
    heavy = load_scenario(HEAVY)
    assert heavy.traffic.flows[0].veh_per_hour_per_lane >= 2000
    sweep = tmp_path / "density.toml"
    sweep.write_text(f'base = "{HEAVY}"\nseeds = [1]\n[overrides]\n"run.duration" = 10.0\n'
                     f'"traffic.warmup" = 40.0\n"traffic.measure_at" = 700.0\n'
                     f'[grid]\n"traffic.flows.0.veh_per_hour_per_lane" = [1000, '
                     f'{heavy.traffic.flows[0].veh_per_hour_per_lane}]\n')
    res = run_sweep(sweep, tmp_path / "out", workers=2, progress=False)
    df = res.summary.sort_values("traffic.flows.0.veh_per_hour_per_lane")
    assert (df.status == "completed").all(), df.reason.tolist()
    low, high = df.iloc[0], df.iloc[1]
    assert high.inserted_veh >= 0.95 * high.requested_veh
    assert high.requested_veh >= 2000 * 3 * 50.0 / 3600 - 1  # 3 lanes, 50 s of SUMO time
    assert high.inserted_veh > 1.8 * low.inserted_veh
    assert high.flow_measured_veh_h > 1.3 * low.flow_measured_veh_h
    assert high.density_measured_veh_km > low.density_measured_veh_km
    meta = json.loads((res.out_dir / "cases" / df.case_id.iloc[1] / "run.json").read_text())
    assert set(meta["traffic"]["flows"]) == {"main"}
    assert meta["traffic"]["measured"]["edge"] == "main"


def test_insertion_shortfall_is_an_event_and_a_warning(tmp_path, capsys):
    """A flow asking more than one lane can carry inserts less than 95 %: run.json says how
    many, an insertion_shortfall event and a warning on stderr say so."""
    sc = load_scenario(HEAVY, **{"run.duration": 2.0, "traffic.warmup": 20.0,
                                 "traffic.flows": [{"id": "jam", "veh_per_hour": 12000, "depart_lane": 0}]})
    res = run_scenario(sc, tmp_path / "run", scenario_path=HEAVY, progress=False, force=True)
    assert res.status == "completed", res.reason
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    jam = meta["traffic"]["flows"]["jam"]
    assert jam["requested"] == pytest.approx(12000 * 22.1 / 3600, abs=1.5)
    assert 0 < jam["inserted"] < 0.95 * jam["requested"]
    ev = pd.read_parquet(tmp_path / "run" / "events.parquet")
    short = ev[ev.kind == "insertion_shortfall"]
    assert list(short.vehicle_id) == ["jam"] and f"inserted {jam['inserted']} of" in short.detail.iloc[0]
    assert "flow 'jam' inserted" in capsys.readouterr().err
