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
                     "--duration", "0.5")  # the same field twice: refused, not one of them dropped
    assert code == 2 and "--duration" in text and "run.duration" in text and not (tmp_path / "o2").exists()


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
                     '[grid]\n"controller.k" = [1.0]\n')
    cases = load_sweep(sweep, {"run.duration": 0.5}).cases
    assert all(c.overrides["run.duration"] == 0.5 for c in cases) and len(cases) == 2
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


# --- the twin meets the same vehicles; sections time them over the whole stretch ----------
from test_realnet import LUST, SCENARIO as LUST_SCENARIO  # noqa: E402 (the LuST ring, 3 abreast)

LUST_TOML = (LUST_SCENARIO.replace('name = "lust"', 'name = "lust-twin"')
             .replace("duration = 120.0", "duration = 30.0").replace("warmup = 30.0", "warmup = 60.0")
             .replace("veh_per_hour_per_lane = 600", "veh_per_hour_per_lane = 1200"))
"""30 s of formation at 1,200 veh/h/lane after 60 s of warm-up, on-ramp flow 300 veh/h."""


@pytest.fixture(scope="module")
def lust_pair(tmp_path_factory):
    """The LuST motorway at 1,200 veh/h/lane: a formation run, its twin and the twin again
    (a run without the formation), the run analysed against the twin."""
    if not LUST.is_file():
        pytest.skip("needs ../shared/realnet beside the checkout")
    from analysis.api import analyze_run
    from formation_traci.scenario import load_scenario
    from formation_traci.runner import run_scenario

    d = tmp_path_factory.mktemp("lust_twin")
    p = d / "lust.toml"
    p.write_text(LUST_TOML)
    sc = load_scenario(p)
    for name, base in (("run", False), ("twin", True), ("twin2", True)):
        assert run_scenario(sc, d / name, scenario_path=p, progress=False, baseline=base).status == "completed"
    res = analyze_run(d / "run", baseline=d / "twin", figures=False)
    return d, res


def _tables(d: Path, name: str):
    import pandas as pd

    return (pd.read_parquet(d / name / "departures.parquet"), pd.read_parquet(d / name / "events.parquet"),
            json.loads((d / name / "run.json").read_text()))


def test_twin_clears_the_same_vehicles_and_inserts_the_same_ones(lust_pair):
    """Both runs remove the same SUMO cars at the same step where the members are put; the
    vehicles inserted are the same ids in both, and departure times differ only for the
    counted exceptions the report lists (insertions the formation's queue delayed)."""
    d, res = lust_pair
    dep_r, ev_r, _ = _tables(d, "run")
    dep_t, ev_t, _ = _tables(d, "twin")
    clr = [sorted(map(tuple, e.loc[e.kind == "cleared_at_insertion", ["t", "vehicle_id"]].values.tolist()))
           for e in (ev_r, ev_t)]
    assert clr[0] and clr[0] == clr[1]  # this scenario does clear cars at insertion
    assert set(dep_r.vehicle_id) == set(dep_t.vehicle_id)
    m = dep_r.merge(dep_t, on="vehicle_id", suffixes=("_r", "_t"))
    differ = int((m.depart_r != m.depart_t).sum())
    doc = json.loads((d / "run" / "metrics.json").read_text())["traffic"]["run"]
    dd = doc["twin_detail"]["departures"]
    assert dd["only_run"] == dd["only_twin"] == 0
    assert dd["later_in_run"] + dd["earlier_in_run"] == differ == doc["twin_departures_moved"]
    assert doc["twin_cleared_both"] == len(clr[0])


def test_lust_stretch_is_timed_whole_in_both_runs(lust_pair):
    """>= 90 % of the background vehicles in the measured stretch are timed from the same
    first section to the last one in both runs; every one of them is matched by id; the
    measures name their population; signs of delay and stretch speed agree (same vehicles)."""
    d, res = lust_pair
    doc = json.loads((d / "run" / "metrics.json").read_text())["traffic"]
    run = doc["run"]
    assert 0.0 <= run["matched_share"] <= 1.0 and 0.0 <= run["stretch_coverage"] <= 1.0
    assert run["stretch_coverage"] >= 0.9 and run["matched_share"] == 1.0
    assert run["stretch_population"] >= 40
    assert run["twin_n_timed"] == round(run["stretch_coverage"] * run["stretch_population"])
    assert set(run["twin_detail"]["populations"]) >= {"stretch", "timed", "downstream"}
    page = (d / "run" / "report.html").read_text()
    assert "Against the twin at the measurement sections" in page and "populations" in page
    if run["twin_delay_total_s"] != 0:
        assert (run["twin_delay_total_s"] > 0) == (run["twin_speed_delta_mps"] < 0)
    import pandas as pd

    v = pd.read_csv(d / "run" / "twin.csv")
    assert len(v) == run["stretch_population"] and v.reason.notna().sum() == len(v) - v.timed.sum()


def test_a_run_without_the_formation_has_exactly_zero_effect(lust_pair):
    """Against a run where the formation is absent from the road (the twin run again):
    every vehicle matched and timed, and every formation-minus-twin effect exactly 0."""
    from analysis.runs.twin_sections import EFFECTS, read_sections, twin_comparison

    d, _ = lust_pair
    _, _, meta = _tables(d, "twin")
    a, b = read_sections(d / "twin2", meta), read_sections(d / "twin", meta)
    m, v, detail = twin_comparison(a, b, meta["sections"]["sections"])
    assert m["stretch_coverage"] == 1.0 and m["matched_share"] == 1.0 and m["twin_n_timed"] >= 40
    assert m["twin_departures_moved"] == 0
    for key in EFFECTS.values():
        assert m[key] == 0, key
    assert (v.delay_s == 0).all()


# --- twins in sweeps, paired effects over seeds --------------------------------------------
def test_sweep_with_twins_summarises_paired_effects_with_confidence_intervals(tmp_path):
    """`sweep --baseline`: every case's twin runs (twins/<id>, a baseline run), the summary's
    paired columns are the case's formation-minus-twin values, and effects.csv gives per grid
    point the mean over the seeds with its Student-t 95 % interval; one seed is flagged."""
    import math

    import numpy as np
    import pandas as pd

    from analysis.report.effects import paired_effects
    from formation_traci.sweep.row import EFFECT_KEYS

    sweep = tmp_path / "s.toml"
    sweep.write_text(f'base = "{os.path.relpath(HIGHWAY, tmp_path)}"\nseeds = [1, 2]\n'
                     '[overrides]\n"run.duration" = 3.0\n"traffic.warmup" = 10.0\n')
    out = tmp_path / "out"
    code, text = cli("sweep", sweep, "--out", out, "--no-progress", "--workers", "2", "--baseline")
    assert code == 0, text
    df = pd.read_parquet(out / "summary.parquet")
    assert (df.status == "completed").all() and {"stretch_coverage", "matched_share", *EFFECT_KEYS} <= set(df)
    for _, r in df.iterrows():
        assert json.loads((out / "twins" / r.case_id / "run.json").read_text())["baseline"] is True
        tr = json.loads((out / "cases" / r.case_id / "metrics.json").read_text())["traffic"]["run"]
        assert r.fx_delay_total_s == pytest.approx(tr["twin_delay_total_s"])
        assert r.fx_speed_mps == pytest.approx(tr["twin_speed_delta_mps"])
        assert 0.0 <= r.stretch_coverage <= 1.0 and 0.0 <= r.matched_share <= 1.0
    eff = pd.read_csv(out / "effects.csv")
    assert list(eff.columns[:6]) == ["metric", "mean", "se", "ci95_lo", "ci95_hi", "n_seeds"]
    row = eff.set_index("metric").loc["fx_delay_total_s"]
    x = df.fx_delay_total_s.to_numpy(float)
    half = 12.706204736 * x.std(ddof=1) / math.sqrt(2)  # t(0.975, 1 dof)
    assert row.n_seeds == 2 and row["mean"] == pytest.approx(x.mean())
    assert (row.ci95_lo, row.ci95_hi) == pytest.approx((x.mean() - half, x.mean() + half))
    assert bool(row.distinguishable) == (x.mean() - half > 0 or x.mean() + half < 0)
    from analysis.report.sweep_report import analyze_sweep

    rep = analyze_sweep(out)
    page = rep.files["report_html"].read_text()
    assert "Paired effects" in page and "timed" in page and rep.files["figure:effects"].is_file()
    one = paired_effects(df[df.seed == 1], [])
    assert (one.note == "no confidence interval").all() and one.ci95_lo.isna().all()
    assert (one.n_seeds == 1).all() and np.isfinite(one["mean"]).any()
