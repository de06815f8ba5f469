"""The penetration-rate study shortened: scenarios/studies/penetration.toml's
grid at 0 % and 20 %, one seed, 30 s after a 40 s warm-up at 900 veh/h/lane (the bundled study:
1,700 veh/h/lane, 240 s, three seeds). Its summary has one row per case with the penetration, the
seed, the throughput, the delay and the conflicts; 0 % has no formation vehicle; means.csv has the
mean of every section measure per penetration."""
from pathlib import Path

import pandas as pd
import pytest

from formation_traci.sweep import run_sweep

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    base = (ROOT / "scenarios" / "studies" / "penetration.toml").read_text()
    text = (base.replace('seeds = [1, 2, 3]', 'seeds = [1]')
            .replace('[0.0, 0.05, 0.1, 0.2]', '[0.0, 0.2]')
            .replace('"run.duration" = 240.0', '"run.duration" = 30.0\n"traffic.flows.0.veh_per_hour_per_lane" = 900')
            .replace('"traffic.warmup" = 240.0', '"traffic.warmup" = 40.0')
            .replace('base = "../highway/', f'base = "{ROOT}/scenarios/highway/'))
    d = tmp_path_factory.mktemp("pen")
    (d / "pen.toml").write_text(text)
    return run_sweep(d / "pen.toml", d / "out", progress=False, workers=1)


def test_one_summary_row_per_case_with_rate_seed_throughput_delay_conflicts(study):
    df = study.summary
    assert len(df) == 2 and set(df["status"]) <= {"completed", "completed_with_incidents"}
    for part in ("penetration", "throughput", "delay", "conflict"):
        assert any(part in c for c in df.columns), part
    rate = "formation_flows.0.penetration"
    assert sorted(df[rate]) == [0.0, 0.2] and set(df["seed"]) == {1}
    assert df["throughput_veh_h"].notna().all() and df["delay_mean_s"].notna().all()
    assert df["conflicts_ttc"].notna().all()
    zero, twenty = (df[df[rate] == p].iloc[0] for p in (0.0, 0.2))
    # 0 %: traffic alone (the flow inserts no formation; the scenario has no other)
    assert zero["throughput_formation_veh_h"] == 0.0 and pd.isna(zero["delay_formation_mean_s"])
    assert twenty["member_collisions"] == 0


def test_the_twenty_percent_case_inserts_its_share(study):
    import json
    case = study.summary[study.summary["formation_flows.0.penetration"] == 0.2].iloc[0]
    meta = json.loads((study.out_dir / "cases" / case["case_id"] / "run.json").read_text())
    got = meta["formation_flows"]["pen"]
    assert got["requested"] >= 1 and got["inserted"] == got["requested"]
    assert got["share"] == pytest.approx(0.2, rel=0.25)  # 30 s: a few formations, coarse


def test_means_over_the_seeds_per_penetration(study):
    means = pd.read_csv(study.out_dir / "means.csv")
    assert set(means["formation_flows.0.penetration"]) == {0.0, 0.2}
    assert {"throughput_veh_h", "delay_mean_s", "conflicts_ttc"} <= set(means["metric"])
    assert (means["n_seeds"] <= 1).all() and (means.loc[means["n_seeds"] == 1, "note"] == "no confidence interval").all()


def test_the_study_runs_each_case_with_its_same_demand_twin(study):
    """The study file asks for the same-demand twin: every case has one, and at 0 % (no
    formation: the run and its twin drive the same vehicles) every paired effect is exactly 0."""
    import json
    from formation_traci.sweep.row import EFFECT_KEYS

    df = study.summary
    assert (df["twin_status"] == "completed").all()
    for r in df.itertuples():
        assert json.loads((study.out_dir / "twins" / r.case_id / "run.json").read_text())["baseline_mode"] == "same"
    eff = pd.read_csv(study.out_dir / "effects.csv")
    zero = eff[eff["formation_flows.0.penetration"] == 0.0].set_index("metric")
    assert set(zero.index) == set(EFFECT_KEYS) and (zero["mean"] == 0.0).all() and (zero["n_seeds"] == 1).all()
