"""SUMO's own CACC as a baseline twin (``controller.law = "sumo_cacc"``, sumo/driven.py,
docs/platoon_laws.md "SUMO's CACC twin"): real SUMO on the bundled sinusoid, cut to 10 s (the
leader's sinusoid starts at 5 s)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.api import analyze_run, compare_runs
from analysis.metrics.platoon import amplification
from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario
from run_helpers import cli

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "platoon" / "sinusoid_sumo_cacc.toml"
IDS = [f"p{i}" for i in range(8)]
LENGTH_M = 4.6  # passenger_car preset, bumper to bumper
STEP_S = 0.05
TAU_S, MIN_GAP_M = 0.5, 2.0  # the scenario's controller.sumo_cacc
MODEL_ONLY = ("v_ref", "omega_ref", "steer", "steer_rate", "beta", "power")


def _run(out: Path, **overrides) -> pd.DataFrame:
    sc = load_scenario(SCENARIO, **{"run.duration": 10.0, **overrides})
    res = run_scenario(sc, out, force=True, progress=False)
    assert res.status == "completed", res.reason
    return pd.read_parquet(out / "trajectories.parquet")


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    out = tmp_path_factory.mktemp("sumo_cacc") / "run"
    return out, _run(out)


def wide(df: pd.DataFrame, col: str) -> pd.DataFrame:
    return df[df.vehicle_id.isin(IDS)].pivot(index="t", columns="vehicle_id", values=col)[IDS]


def test_sumo_drives_the_followers_and_our_head_leads(twin):
    """Followers: SUMO's Euler update (default --step-method) moves a vehicle by its new speed
    over the step, x_(k+1) = x_k + v_(k+1) dt, and its acceleration is (v_(k+1) - v_k) / dt:
    both hold to round-off for p1 .. p7 (their recorded state is SUMO's, sumo_gap ~ 0) and not
    for the head, which our RK4 model moves (continuous speed within the step)."""
    out, df = twin
    meta = json.loads((out / "run.json").read_text())
    assert meta["sumo_cacc"]["moved"] == ["p0"]
    assert meta["sumo_cacc"]["driven_by_sumo"] == IDS[1:]
    assert meta["sumo_cacc"]["vtype"]["carFollowModel"] == "CACC"
    assert meta["sumo_cacc"]["vtype"]["tau"] == "0.5"
    x, v, a = wide(df, "x"), wide(df, "v"), wide(df, "a_lon")
    dx_err = (x.diff() - v * STEP_S).iloc[2:].abs().max()
    a_err = (a - v.diff() / STEP_S).iloc[2:].abs().max()
    assert (dx_err[IDS[1:]] < 1e-9).all() and (a_err[IDS[1:]] < 1e-9).all()
    assert dx_err["p0"] > 1e-4  # ours: RK4 over the step
    members = df[df.vehicle_id.isin(IDS)]
    driven = members[members.vehicle_id != "p0"]
    # SUMO's front bumper, our heading (the reference line's, within ~1e-6 rad of SUMO's
    # angle on this straight road): sumo_gap below a micrometre
    assert driven.sumo_gap.abs().max() < 1e-6
    for col in MODEL_ONLY:  # our model's columns: none for a vehicle SUMO drives
        assert driven[col].isna().all(), col
        assert members[members.vehicle_id == "p0"][col].notna().all(), col
    assert (driven[driven.t > 0].lane_index == 0).all()  # it keeps its lane (in SUMO from 0.05 s)
    cf = pd.read_parquet(out / "comfort.parquet")  # control rate: SUMO's step values held
    p3 = cf[cf.vehicle_id == "p3"].set_index("t")
    k = np.floor(p3.index.to_numpy() / STEP_S + 1e-6).astype(int)  # the step of each period
    held = wide(df, "v")["p3"].to_numpy()[k]
    assert np.abs(p3.v.to_numpy() - held).max() < 1e-12 and p3.v.diff().abs().max() > 0


def test_gaps_stay_at_sumo_cacc_desired_gap(twin):
    """SUMO's desired gap (MSCFModel_CACC: gap2pred = gap - minGap against tau v) is
    minGap + tau v bumper to bumper, 15.89 m at 100 km/h. The column starts on it and holds it
    to 1 mm until the sinusoid (5 s). Then the collision-avoidance mode (10 x 0.45 = 4.5 1/s^2
    on a shortfall) holds a shortfall near the relative acceleration over 4.5 1/s^2: the head's
    ~1 m/s^2 (the road governor's profile) gives ~0.22 m, bound 0.5 m; an excess is closed by
    the weak gap-closing mode (0.05 1/s^2): bound 1.5 m (0.87 m recorded over 30 s). No
    collision, and every follower's speed within 1.5 m/s of its predecessor's."""
    out, df = twin
    s, v = wide(df, "s"), wide(df, "v")
    gaps = pd.DataFrame({IDS[i]: s[IDS[i - 1]] - s[IDS[i]] - LENGTH_M for i in range(1, 8)})
    err = gaps - (MIN_GAP_M + TAU_S * v[IDS[1:]])
    assert err[err.index < 5.0].abs().max().max() < 1e-3
    assert err.min().min() > -0.5 and err.max().max() < 1.5
    assert (err.abs().max() > 0.02).all()  # SUMO's CACC does move the gaps on the sinusoid
    assert v.diff(axis=1).iloc[:, 1:].abs().max().max() < 1.5
    ev = pd.read_parquet(out / "events.parquet")
    assert not ev.kind.isin(["collision", "member_removed"]).any()
    assert json.loads((out / "run.json").read_text())["incidents"]["member_collisions"] == 0


def test_rows_carry_the_formation_and_the_string_amplification_is_computed(twin, tmp_path):
    """The followers' rows are in the same tables as our members' (formation 'f0', member
    ids); metrics.json's string_amplification is the tail's over the first follower's peak
    speed error of the recorded speeds (analysis/metrics/platoon.py), over the whole column."""
    out, df = twin
    assert set(df.vehicle_id) == set(IDS) | {"vc"}
    assert (df.formation_id == "f0").all()
    res = analyze_run(out, tmp_path / "analysis", figures=False)
    (rec,) = json.loads(res.files["metrics_json"].read_text())["formations"]
    assert rec["column"] == IDS
    ratio, first, last = amplification(wide(df, "v").dropna().to_numpy().T)
    assert rec["string_amplification"] == pytest.approx(ratio, rel=1e-12)
    assert rec["peak_speed_error_first_mps"] == pytest.approx(first, rel=1e-12) and first > 0.1


def test_one_compare_puts_our_column_beside_sumos(twin, tmp_path):
    """The same scenario with our Ploeg law (``--set controller.law="cacc_ploeg"``, same road,
    traffic and seed, same head) and `compare` of the two runs: one table with both columns'
    string_amplification and gamma_mean, each that run's metrics.json value."""
    out, df = twin
    ours = tmp_path / "ploeg"
    df_ours = _run(ours, **{"controller.law": "cacc_ploeg"})
    head = wide(df, "x")["p0"], wide(df_ours, "x")["p0"]
    assert (head[0] - head[1]).abs().max() < 1e-9  # the same head in both runs
    cmp = compare_runs([ours, out], tmp_path / "cmp")
    for run_dir in (ours, out):
        a = analyze_run(run_dir, tmp_path / f"{run_dir.name}.a", figures=False)
        (rec,) = json.loads(a.files["metrics_json"].read_text())["formations"]
        for key in ("string_amplification", "gamma_mean"):
            assert cmp.table.loc[key, run_dir.name] == pytest.approx(rec[key], rel=1e-12)
    assert cmp.table.loc["string_amplification", "ploeg"] != cmp.table.loc["string_amplification", "run"]


def test_unknown_law_and_sumo_cacc_without_a_road_exit_2(tmp_path):
    """Bad input exits 2 naming the file, the field and what is expected."""
    base = ('[run]\nduration = 1.0\n[controller]\nlaw = "{law}"\n[leader]\nspeed = 20.0\n'
            '[[members]]\nid = "a"\noffset = [0.0, 0.0]\nposition = [0.0, 0.0]\n')
    for law, expect in (("sumo_caac", "sumo_cacc"), ("sumo_cacc", "needs a [road]")):
        p = tmp_path / f"{law}.toml"
        p.write_text(base.format(law=law))
        code, text = cli("run", p, "--out", tmp_path / f"out_{law}", "--no-progress")
        assert code == 2, text
        assert str(p) in text and expect in text
        assert not (tmp_path / f"out_{law}").exists()
    assert "controller.law" in cli("run", tmp_path / "sumo_caac.toml", "--out", tmp_path / "o",
                                   "--no-progress")[1]


def test_sumo_emergency_braking_of_followers_is_an_incident(tmp_path):
    """tau_s = 1e6: SUMO's CACC wants a gap of 1e6 s x v and brakes its followers at once
    harder than their decel (SUMO's 'emergency braking' warnings about p1 ..): the run ends
    completed_with_incidents with them counted as sumo_emergency_brakes, the terminal's last
    line names them, --strict exits 1; no collision is counted."""
    text = SCENARIO.read_text().replace("tau_s = 0.5,", "tau_s = 1000000.0,")
    text = text.replace("duration = 30.0", "duration = 3.0")
    assert "tau_s = 1000000.0" in text and "duration = 3.0" in text
    sc = tmp_path / "tau.toml"
    sc.write_text(text)
    code, out = cli("run", sc, "--out", tmp_path / "r", "--no-progress")
    assert code == 0, out
    meta = json.loads((tmp_path / "r" / "run.json").read_text())
    assert meta["status"] == "completed_with_incidents"
    n = meta["incidents"]["sumo_emergency_brakes"]
    assert n >= 7 and meta["incidents"]["member_collisions"] == 0
    assert meta["sumo"]["messages"]["by_kind"]["emergency_braking"] >= n
    ev = pd.read_parquet(tmp_path / "r" / "events.parquet")
    braked = set(ev[(ev.kind == "sumo_message") & (ev.other_id == "emergency_braking")].vehicle_id)
    assert braked <= set(IDS[1:]) and len(braked) == 7  # every follower, never our head
    last = [line for line in out.strip().splitlines()[-3:] if line.startswith("INCIDENTS")]
    assert last and f"{n} sumo emergency brakes" in last[0] and "collision" not in last[0]
    code, out = cli("run", sc, "--out", tmp_path / "s", "--no-progress", "--strict")
    assert code == 1, out


def test_decel_above_emergency_decel_exits_2_naming_both_fields(tmp_path):
    """SUMO would raise the vType's emergencyDecel to a larger decel by itself (and warn that
    it 'may cause collisions'): refused when the scenario is read, nothing created."""
    text = SCENARIO.read_text().replace("decel_mps2 = 8.0,", "decel_mps2 = 12.0,")
    assert "decel_mps2 = 12.0" in text
    sc = tmp_path / "decel.toml"
    sc.write_text(text)
    code, out = cli("run", sc, "--out", tmp_path / "r", "--no-progress")
    assert code == 2, out
    assert str(sc) in out and "controller.sumo_cacc" in out
    assert "decel_mps2 = 12" in out and "emergency_decel_mps2 = 9" in out
    assert not (tmp_path / "r").exists()


def test_force_replaces_a_sumo_cacc_run(tmp_path):
    """The CACC vType file the run writes (sumo/sumo_cacc.add.xml) is the tool's: --force
    replaces the run (with traffic, whose measurement files share SUMO's additional-files
    option with it)."""
    text = SCENARIO.read_text().replace("duration = 30.0", "duration = 0.5") + (
        '[traffic]\nwarmup = 1.0\n[[traffic.flows]]\nid = "main"\nveh_per_hour_per_lane = 300\n')
    sc = tmp_path / "short.toml"
    sc.write_text(text)
    for _ in range(2):
        code, out = cli("run", sc, "--out", tmp_path / "r", "--no-progress", "--force")
        assert code == 0, out
    assert (tmp_path / "r" / "sumo" / "sumo_cacc.add.xml").is_file()
