"""End to end: analyze_run and compare_runs on synthetic run directories."""
from __future__ import annotations

import json
import os

import numpy as np
import pandas as pd
import pytest

from analysis import NoTrajectoryData, analyze_run, compare_runs
from analysis.load.run_data import DamagedPartWarning
from analysis.runs.summary import MEMBER_METRICS
from analysis_synth import exp_error, make_run, trajectories, write_run

E0 = {"m1": 1.0, "m2": 0.5, "m3": 0.25, "m4": 2.0}
TAU = 2.0
PNG = b"\x89PNG\r\n\x1a\n"


def _only(mid, fn, default):
    return lambda m, t: fn(t) if m == mid else np.full_like(t, default)


COLUMNS = {
    "a_lat": _only("m1", lambda t: 4.0 * np.sin(2 * np.pi * 0.25 * t), 0.0),
    "a_lon": _only("m2", lambda t: 3.0 * np.sin(2 * np.pi * 0.1 * t), 0.0),
    "slip_front": _only("m2", lambda t: np.where(((t >= 2) & (t < 3)) | ((t >= 6) & (t < 6.5)),
                                                 0.1, 0.01), 0.01),
    "traction_force": _only("m3", lambda t: np.where((t >= 1) & (t < 1.5), 9000.0, 500.0), 500.0),
    "friction_usage": _only("m4", lambda t: np.where((t >= 4) & (t < 5), 1.2, 0.1), 0.1),
}


def strict_json(path):
    def no_nan(x):
        raise AssertionError(f"non-JSON constant {x} in {path}")
    return json.loads(path.read_text(), parse_constant=no_nan)


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    run = make_run(tmp_path_factory.mktemp("runs") / "dyn", error=exp_error(E0, TAU),
                   columns=COLUMNS)
    return run, analyze_run(run)


def test_outputs_are_written(analysed):
    run, res = analysed
    assert res.out_dir == run
    doc = strict_json(run / "metrics.json")
    assert doc["schema"] == "formation-traci/metrics/1"
    assert [m["id"] for m in doc["members"]] == ["m1", "m2", "m3", "m4"]
    assert doc["damaged"] is False
    assert set(doc["units"]["members"]) == set(MEMBER_METRICS)
    csv = pd.read_csv(run / "metrics.csv")
    assert list(csv["id"]) == ["m1", "m2", "m3", "m4"]
    assert list(csv.columns) == ["id", *MEMBER_METRICS]
    figs = sorted(p.name for p in (run / "figures").iterdir())
    assert figs == ["comfort.png", "errors.png", "limits.png", "paths.png", "propagation.png",
                    "tracking.png"]
    for p in (run / "figures").iterdir():
        assert p.read_bytes()[:8] == PNG and p.stat().st_size > 10_000
    html = (run / "report.html").read_text()
    assert html.count('src="data:image/png;base64,') == 6
    assert "http://" not in html and "https://" not in html
    assert "Missing or damaged" in html and "m4" in html


def test_formation_metrics_match_closed_form(analysed):
    _, res = analysed
    m = res.members
    for mid, e0 in E0.items():
        assert m.loc[mid, "settling_time_s"] == pytest.approx(TAU * np.log(e0 / 0.2), abs=0.01)
        assert m.loc[mid, "iae_m_s"] == pytest.approx(e0 * TAU * (1 - np.exp(-20 / TAU)), rel=1e-3)
        assert m.loc[mid, "e_max_m"] == pytest.approx(e0)
        assert m.loc[mid, "e_max_settled_m"] <= 0.2
    ss = res.string_stability
    assert list(zip(ss["leader"], ss["follower"])) == [("m1", "m2"), ("m2", "m3")]
    np.testing.assert_allclose(ss["peak_ratio"], [0.5, 0.5])
    assert res.run["string_stable"] is True
    assert res.run["shape_error_final_m"] < 1e-3 < res.run["shape_error_max_m"]


def test_comfort_and_limit_metrics(analysed):
    _, res = analysed
    m = res.members
    # m1: a_lat = 4 sin(2 pi 0.25 t) over 20 s: 10 half-waves beyond 3.6 m/s^2
    assert m.loc["m1", "a_lat_peak_mps2"] == pytest.approx(4.0, rel=1e-3)
    assert m.loc["m1", "a_lat_over_n"] == 10
    assert m.loc["m1", "t_lat_uncomfortable_s"] == pytest.approx(
        20 * (1 - 2 / np.pi * np.arcsin(0.9)), abs=0.11)
    assert m.loc["m1", "t_lat_beyond_s"] == 0.0
    assert m.loc["m1", "jerk_lat_peak_mps3"] == pytest.approx(4.0 * np.pi / 2, rel=0.03)
    # m2: |a_lon| = |3 sin(2 pi 0.1 t)| > 2 in 4 episodes; slip beyond 4 deg twice, 1.5 s
    assert m.loc["m2", "n_lon_above_comfort"] == 4
    assert m.loc["m2", "t_lon_above_comfort_s"] == pytest.approx(
        20 * (1 - 2 / np.pi * np.arcsin(2 / 3)), abs=0.05)
    assert (m.loc["m2", "slip_over_n"], m.loc["m2", "slip_over_s"]) == (2, pytest.approx(1.5))
    assert (m.loc["m3", "traction_over_n"], m.loc["m3", "traction_over_s"]) == (1, pytest.approx(0.5))
    assert (m.loc["m4", "friction_over_n"], m.loc["m4", "friction_over_s"]) == (1, pytest.approx(1.0))
    assert m.loc["m4", "slip_over_n"] == 0 and m.loc["m1", "traction_over_s"] == 0.0
    # ISO 2631: 100 Hz recording -> partial band, value reported
    assert res.run["iso2631_full_band"] is False
    assert np.isfinite(m.loc["m1", "aw_lat_mps2"]) and m.loc["m1", "aw_lat_mps2"] > 0


def test_out_dir_leaves_the_run_directory_untouched(tmp_path):
    run = make_run(tmp_path / "r", t_end=5.0)
    before = sorted(os.listdir(run))
    res = analyze_run(run, tmp_path / "out", figures=False)
    assert sorted(os.listdir(run)) == before
    assert (tmp_path / "out" / "metrics.json").is_file()
    assert "data:image/png" not in (tmp_path / "out" / "report.html").read_text()
    assert res.files["metrics_csv"] == tmp_path / "out" / "metrics.csv"


def test_damaged_run_still_produces_metrics_and_lists_what_is_missing(tmp_path):
    df = trajectories(error=exp_error(E0, TAU)).drop(columns=["e_lat"])
    run = write_run(tmp_path / "damaged", df, n_parts=4)
    part = run / "trajectories.parquet" / "part-00001.parquet"
    part.write_bytes(part.read_bytes()[:300])
    os.remove(run / "run.json")
    with pytest.warns(DamagedPartWarning):
        res = analyze_run(run)
    doc = strict_json(run / "metrics.json")
    assert doc["damaged"] is True
    kinds = {(i["kind"], i["what"]) for i in doc["issues"]}
    assert ("missing_file", "run.json") in kinds
    assert ("missing_column", "e_lat") in kinds
    assert ("corrupt_part", "trajectories.parquet/part-00001.parquet") in kinds
    assert any(k == "time_gap" for k, _ in kinds)
    # the error is recomputed from ex, ey and the virtual-car heading; settling still found
    assert res.members.loc["m1", "settling_time_s"] == pytest.approx(TAU * np.log(5), abs=0.01)
    assert "recomputed" in doc["members"][0]["unavailable"]["e_lon/e_lat"]
    html = (run / "report.html").read_text()
    assert "part-00001.parquet" in html and "run.json is missing" in html


def test_kinematic_run_reports_tire_limits_as_not_applicable(tmp_path):
    run = make_run(tmp_path / "kin", model="kinematic", t_end=5.0)
    res = analyze_run(run, figures=False)
    assert res.members["slip_over_s"].isna().all()
    assert res.members["traction_over_s"].isna().all()
    doc = strict_json(run / "metrics.json")
    assert "kinematic" in doc["members"][0]["unavailable"]["slip limit"]
    assert doc["members"][0]["friction_over_s"] == 0.0


def test_no_data_at_all_raises(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(NoTrajectoryData):
        analyze_run(tmp_path / "empty")


def test_compare_runs_side_by_side(tmp_path):
    dyn = make_run(tmp_path / "dynamic", error=exp_error(E0, TAU), t_end=8.0)
    kin = make_run(tmp_path / "kinematic", model="kinematic", error=exp_error({"m1": 3.0}, TAU),
                   t_end=8.0)
    (tmp_path / "broken").mkdir()
    res = compare_runs([dyn, kin, tmp_path / "broken"], tmp_path / "cmp")
    assert list(res.table.columns) == ["unit", "dynamic", "kinematic"]
    assert res.table.loc["model", "kinematic"] == "kinematic"
    assert res.table.loc["worst e_max_m", "kinematic"] == pytest.approx(3.0)
    assert res.table.loc["worst e_max_m", "dynamic"] == pytest.approx(2.0)
    assert set(res.runs) == {"dynamic", "kinematic"}
    assert "no_trajectory_data" in set(res.issues.loc[res.issues["run"] == "broken", "kind"])
    for name in ("compare.csv", "compare.json", "report.html", "figures/compare_paths.png",
                 "figures/compare_signals.png"):
        assert (tmp_path / "cmp" / name).is_file()
    doc = strict_json(tmp_path / "cmp" / "compare.json")
    assert doc["metrics"]["worst settling_time_s"]["dynamic"] == pytest.approx(
        TAU * np.log(2.0 / 0.2), abs=0.01)
    html = (tmp_path / "cmp" / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 2 and "broken" in html
    assert not list(dyn.glob("metrics.*"))  # compare does not write into run directories


def test_compare_labels_repeated_names_and_needs_one_good_run(tmp_path):
    a = make_run(tmp_path / "a" / "run", t_end=3.0)
    b = make_run(tmp_path / "b" / "run", t_end=3.0)
    res = compare_runs([a, b], tmp_path / "out")
    assert list(res.table.columns) == ["unit", "a/run", "b/run"]
    (tmp_path / "e").mkdir()
    with pytest.raises(NoTrajectoryData):
        compare_runs([tmp_path / "e"], tmp_path / "out2")
    with pytest.raises(ValueError, match="empty"):
        compare_runs([], tmp_path / "out3")


def test_declared_member_without_rows_is_reported_not_fatal(tmp_path):
    offsets = {"m1": (0.0, 0.0), "m2": (-12.0, 0.0)}
    df = trajectories(offsets={"m1": (0.0, 0.0)}, t_end=3.0)
    run = write_run(tmp_path / "r", df, offsets=offsets)
    res = analyze_run(run, figures=False)
    assert res.members.loc["m2"].drop(["offset_dx_m", "offset_dy_m", "offset_frame"]).isna().all()
    assert res.run["n_members"] == 2 and res.run["n_members_with_data"] == 1
    issues = res.issues
    assert ((issues["kind"] == "missing_vehicle") & (issues["what"] == "m2")).any()
    doc = strict_json(run / "metrics.json")
    assert doc["members"][1]["unavailable"] == {"all": "no trajectory rows for this member"}
