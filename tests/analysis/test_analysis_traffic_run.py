"""Traffic metrics of whole runs: synthetic road runs with background, events, SSM."""
from __future__ import annotations

import dataclasses
import json
import os

import numpy as np
import pytest

import analysis_synth as S
from analysis import analyze_run, compare_runs
from analysis.load.run_data import DamagedPartWarning, load_run
from analysis.runs.summary import DEFAULT_SETTINGS, MEMBER_METRICS, compute_run
from analysis.runs.traffic_run import TRAFFIC_MEMBER_METRICS, load_baseline

DT, T_END, V = 0.05, 6.0, 20.0
OFFSETS = {"a": (0.0, 0.0), "b": (0.0, 3.5)}  # side by side, lanes 1 and 2
CG = 2.321 - 2.3  # passenger car: body centre 0.021 m ahead of the CoG
FAST = dataclasses.replace(DEFAULT_SETTINGS, anim_duration_s=2.0, anim_fps=5.0)

VEHICLES = {
    "lead": {"s0": 30.0, "d": 0.0, "v": V},  # ahead of a in its lane
    "side": {"s0": 0.0, "d": -2.9, "v": V},  # alongside a, drifted 0.6 m towards it
    "closer": {"s0": -40.0, "d": 3.5, "v": 25.0},  # closing on b from behind at 5 m/s
    "far": {"s0": 250.0, "d": 0.0, "v": V},  # recorded, but beyond the 100 m range
}
EVENTS = [(1.0, "lane_change", "lead", "", "1 -> 1"),
          (2.0, "lane_change", "far", "", "1 -> 0"),
          (3.0, "cut_in", "lead", "a", "gap 25.4 m ahead of the member"),
          (4.0, "collision", "closer", "b", "lane main_2"),
          (5.0, "teleport", "far", "", ""),
          (5.5, "lane_change", "a", "", "1 -> 2")]
SSM_ROWS = [(-50.0, -40.0, "w1", "w2", False, 0.5, -45.0, 6.0, -45.0, np.nan),  # warm-up
            (3.0, 6.0, "closer", "b", True, 1.1, 6.0, 3.2, 6.0, np.nan),
            (3.0, 6.0, "b", "closer", True, 1.1, 6.0, 3.2, 6.0, np.nan),  # SUMO's copy
            (1.0, 2.0, "side", "lead", False, 2.5, 1.5, 1.0, 1.5, np.nan),
            (1.0, 2.0, "x1", "x2", False, 1.0, 1.5, 5.0, 1.5, np.nan)]


def road_run(path, *, vehicles=VEHICLES, events=EVENTS, ssm=SSM_ROWS, offsets=OFFSETS,
             t_end=T_END, meta=None, with_background=True):
    df = S.trajectories(dt=DT, t_end=t_end, v=V, offsets=offsets, road=True)
    S.write_run(path, df, offsets=offsets, meta={**S.ROAD_META, **(meta or {})})
    t = S.time_vector(DT, t_end)
    S.write_traffic(path, background_df=S.background(t, vehicles) if with_background else None,
                    events_df=S.events(events) if events is not None else None,
                    ssm_df=S.ssm(ssm) if ssm is not None else None, n_parts=2)
    return path


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    run = road_run(tmp_path_factory.mktemp("road") / "run")
    return run, analyze_run(run, settings=FAST)


def test_clearance_lateral_gap_and_ttc2d(analysed):
    _, res = analysed
    m = res.members
    # a: 1.1 m to "side" (parallel, overlapping along s), 1.7 m to b
    assert m.loc["a", "clearance_min_m"] == pytest.approx(1.1)
    assert m.loc["a", "clearance_min_with"] == "side"
    assert m.loc["a", "lat_gap_min_m"] == pytest.approx(1.1)
    assert m.loc["a", "clearance_members_min_m"] == pytest.approx(1.7)
    assert m.loc["a", "clearance_bg_min_m"] == pytest.approx(1.1)
    # b: 1.7 m to a; to the background "side" across a's lane (3.5 + 2.9 - 1.8 m) beats
    # "closer", which ends 35.471 - 5 * 6 = 5.471 m behind it
    assert m.loc["b", "clearance_bg_min_m"] == pytest.approx(3.5 + 2.9 - 1.8)
    assert m.loc["b", "clearance_min_m"] == pytest.approx(1.7)
    assert m.loc["a", "t_clearance_below_s"] == 0.0 and m.loc["a", "t_lat_gap_below_s"] == 0.0
    # b vs "closer": rear-end, gap(t) = 35.471 - 5 t, TTC = gap / 5, smallest at t = 6
    gap0 = 40 + CG - 2.3 - 2.25
    assert m.loc["b", "ttc2d_min_s"] == pytest.approx((gap0 - 5 * T_END) / 5)
    assert m.loc["b", "ttc2d_min_with"] == "closer"
    assert m.loc["b", "ttc2d_min_t_s"] == pytest.approx(T_END)
    # below 3 s once gap < 15 m: t > 4.0942 s -> samples 4.10 ... 6.00
    assert m.loc["b", "t_ttc2d_below_s"] == pytest.approx(39 * DT)
    assert m.loc["a", "ttc2d_min_s"] is None and m.loc["a", "t_ttc2d_below_s"] == 0.0
    assert res.traffic["ttc2d_min_s"] == pytest.approx((gap0 - 5 * T_END) / 5)
    assert res.traffic["clearance_min_m"] == pytest.approx(1.1)


def test_headways(analysed):
    _, res = analysed
    m = res.members
    gap_a = (30 - 2.25) - (CG + 2.3)  # a's front bumper to lead's rear
    assert m.loc["a", "headway_min_s"] == pytest.approx(gap_a / V)
    assert m.loc["a", "headway_mean_s"] == pytest.approx(gap_a / V)
    assert m.loc["a", "follower_headway_min_s"] is None  # nobody behind a in its lane
    assert m.loc["b", "headway_min_s"] is None
    gap0 = 40 + CG - 2.3 - 2.25
    assert m.loc["b", "follower_headway_min_s"] == pytest.approx((gap0 - 5 * T_END) / 25)
    # follower headway (35.471 - 5 t)/25 < 1 s for t > 2.0942 s -> samples 2.10 ... 6.00
    assert m.loc["b", "t_follower_headway_below_s"] == pytest.approx(79 * DT)


def test_events_ssm_and_background_speed(analysed):
    run, res = analysed
    tr, m = res.traffic, res.members
    assert (tr["n_lane_changes_bg"], tr["n_lane_changes_bg_near"],
            tr["n_lane_changes_members"]) == (2, 1, 1)
    assert (tr["n_cut_ins"], tr["n_collisions"], tr["n_collisions_member"]) == (1, 1, 1)
    assert (tr["n_teleports"], tr["n_teleports_member"]) == (1, 0)
    assert (m.loc["a", "n_cut_ins"], m.loc["b", "n_collisions"], m.loc["a", "n_lane_changes"]) \
        == (1, 1, 1)
    # SSM: the copy merged, the warm-up conflict left out, member vs other split
    assert (tr["ssm_n_duplicates_merged"], tr["ssm_n_before_start"]) == (1, 1)
    assert (tr["ssm_n_member"], tr["ssm_ttc_min_member_s"], tr["ssm_drac_max_member_mps2"]) \
        == (1, 1.1, 3.2)
    assert (tr["ssm_n_ttc_critical_member"], tr["ssm_n_drac_high_member"]) == (1, 1)
    assert (tr["ssm_n_other"], tr["ssm_ttc_min_other_s"], tr["ssm_n_other_near"]) == (2, 1.0, 1)
    assert (m.loc["b", "ssm_n_conflicts"], m.loc["b", "ssm_ttc_min_s"],
            m.loc["a", "ssm_n_conflicts"]) == (1, 1.1, 0)
    # background near the formation: lead ahead, side alongside, closer behind; far out
    assert tr["bg_n_vehicles"] == 4 and tr["bg_n_vehicles_near"] == 3
    assert tr["bg_speed_mean_by_lane_mps"] == {"0": pytest.approx(20.0),
                                               "1": pytest.approx(20.0),
                                               "2": pytest.approx(25.0)}
    assert (tr["bg_speed_mean_behind_mps"], tr["bg_speed_mean_alongside_mps"],
            tr["bg_speed_mean_ahead_mps"]) == pytest.approx((25.0, 20.0, 20.0))
    assert tr["bg_time_loss_total_s"] == pytest.approx(0.0)
    doc = json.loads((run / "metrics.json").read_text())
    assert doc["traffic"]["run"]["ssm_n_member"] == 1
    assert doc["traffic"]["member_conflicts"][0]["foe"] in ("b", "closer")
    assert set(doc["units"]["members"]) == set(MEMBER_METRICS)


def test_outputs_and_figures(analysed):
    run, res = analysed
    csv = (run / "metrics.csv").read_text().splitlines()[0].split(",")
    assert csv[-len(TRAFFIC_MEMBER_METRICS):] == list(TRAFFIC_MEMBER_METRICS)
    st = run / "figures" / "traffic_spacetime.png"
    gif = run / "figures" / "traffic_birdseye.gif"
    assert st.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and st.stat().st_size > 10_000
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a") and gif.stat().st_size > 5_000
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames == 11  # 2 s at 5 fps, both ends included
    html = (run / "report.html").read_text()
    assert "Traffic interaction" in html and "data:image/gif;base64," in html
    assert html.count("data:image/png;base64,") == 7  # + the propagation figure
    assert res.files["figure:traffic_birdseye"] == gif


def test_birdseye_falls_back_to_a_png_strip_without_pillow(tmp_path, monkeypatch):
    import importlib.util

    from analysis.figures import run_figures as figures

    run = road_run(tmp_path / "r", t_end=2.0)
    a = compute_run(load_run(run), FAST)
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *args: None if name == "PIL" else real(name, *args))
    out = figures.birdseye_animation(a, tmp_path / "anim.gif")
    assert out == tmp_path / "anim.png" and out.read_bytes()[:4] == b"\x89PNG"
    assert not (tmp_path / "anim.gif").exists()


def test_missing_tables_are_listed_and_the_rest_is_computed(tmp_path):
    run = road_run(tmp_path / "r", with_background=False, ssm=None)
    part = run / "events.parquet" / "part-00001.parquet"
    part.write_bytes(part.read_bytes()[:100])
    with pytest.warns(DamagedPartWarning):
        res = analyze_run(run, settings=FAST)
    kinds = {(k, w) for k, w in zip(res.issues["kind"], res.issues["what"])}
    assert ("missing_table", "background.parquet") in kinds
    assert ("missing_table", "ssm.parquet") in kinds
    assert ("corrupt_part", "events.parquet/part-00001.parquet") in kinds
    m = res.members
    assert m.loc["a", "clearance_min_m"] == pytest.approx(1.7)  # member-member still there
    assert m.loc["a", "e_max_m"] == pytest.approx(0.0)  # formation metrics unaffected
    assert res.traffic["ssm_n_member"] is None and res.traffic["bg_n_vehicles"] is None
    assert res.traffic["n_lane_changes_members"] is not None  # the readable events part
    doc = json.loads((run / "metrics.json").read_text())
    assert "background" in doc["traffic"]["unavailable"] and "ssm" in doc["traffic"]["unavailable"]
    assert {"traffic_spacetime", "traffic_birdseye"} <= set(doc["figures"])


def test_free_space_run_has_no_traffic_figures_and_no_road_metrics(tmp_path):
    run = S.make_run(tmp_path / "free", t_end=3.0)
    res = analyze_run(run)
    assert "figure:traffic_spacetime" not in res.files
    assert res.members["headway_min_s"].isna().all()
    # members still have outlines: m2 is 12 m behind m1 -> 12 - 4.6 m between bumpers
    assert res.members.loc["m1", "clearance_min_m"] == pytest.approx(7.4)
    doc = json.loads((run / "metrics.json").read_text())
    assert "lateral gap / headway" in doc["traffic"]["unavailable"]


# --- baseline twin --------------------------------------------------------------------------

def _stop_and_go(t):
    return np.where(t < 2, 10 + V * t, np.where(t < 4, 50.0, 50 + V * (t - 4)))


RUN_VEH = {"delayed": {"s": _stop_and_go, "d": -3.5},  # stands 2 s at s = 50 m
           "steady": {"s0": -30.0, "d": 3.5, "v": V}}
BASE_VEH = {"delayed": {"s0": 10.0, "d": -3.5, "v": V},
            "steady": {"s0": -30.0, "d": 3.5, "v": V},
            "extra": {"s0": 500.0, "d": 0.0, "v": V}}


def _twin(path, seed=1):
    df = S.trajectories(dt=DT, t_end=8.0, v=V, offsets={}, road=True)  # virtual car only
    S.write_run(path, df, offsets={"a": (0.0, 0.0)},
                meta={**S.ROAD_META, "baseline": True, "seed": seed})
    S.write_traffic(path, background_df=S.background(S.time_vector(DT, 8.0), BASE_VEH),
                    events_df=S.events([]))
    return path


def test_baseline_comparison_end_to_end(tmp_path):
    run = road_run(tmp_path / "run", vehicles=RUN_VEH, offsets={"a": (0.0, 0.0)}, t_end=8.0,
                   events=[], ssm=[])
    twin = _twin(tmp_path / "twin")
    res = analyze_run(run, settings=FAST, baseline=twin, figures=False)
    tr = res.traffic
    assert tr["baseline_section_m"] == pytest.approx([0.0, 160.0])
    assert (tr["baseline_n_common"], tr["baseline_n_compared"]) == (2, 2)
    b = res.baseline
    assert b.loc["delayed", "delta_s"] == pytest.approx(2.0)
    assert (b.loc["delayed", "s_from"], b.loc["delayed", "s_to"]) == pytest.approx((10.0, 130.0))
    assert b.loc["delayed", "tt_run_s"] == pytest.approx(8.0)
    assert b.loc["steady", "delta_s"] == pytest.approx(0.0, abs=1e-9)
    assert tr["baseline_delta_total_s"] == pytest.approx(2.0)
    assert tr["baseline_delta_max_s"] == pytest.approx(2.0)
    assert (run / "baseline.csv").is_file()
    doc = json.loads((run / "metrics.json").read_text())
    assert doc["traffic"]["baseline_vehicles"][0]["vehicle_id"] == "delayed"
    assert not any(k.startswith("baseline") for k in res.issues["kind"])
    html = (run / "report.html").read_text()
    assert "Against the baseline twin" in html


def test_baseline_problems_are_issues_not_failures(tmp_path):
    run = road_run(tmp_path / "run", vehicles=RUN_VEH, offsets={"a": (0.0, 0.0)}, t_end=8.0,
                   events=[], ssm=[])
    res = analyze_run(run, baseline=_twin(tmp_path / "twin", seed=2), figures=False)
    assert ((res.issues["kind"] == "baseline_mismatch")
            & (res.issues["what"] == "baseline:seed")).any()
    res = analyze_run(run, baseline=tmp_path / "nowhere", figures=False)
    assert "missing_baseline" in set(res.issues["kind"])
    assert res.traffic["baseline_n_compared"] is None and res.baseline is None
    assert not (run / "baseline.csv").exists()


def test_the_twin_itself_analyses_without_member_errors(tmp_path):
    twin = _twin(tmp_path / "twin")
    res = analyze_run(twin, figures=False)
    assert "missing_vehicle" not in set(res.issues["kind"])
    assert "baseline_run" in set(res.issues["kind"])
    assert load_baseline(twin).background is not None


def test_compare_runs_has_traffic_rows(tmp_path):
    road = road_run(tmp_path / "road")
    free = S.make_run(tmp_path / "free", t_end=3.0)
    res = compare_runs([road, free], tmp_path / "cmp", settings=FAST)
    assert res.table.loc["traffic clearance_min_m", "road"] == pytest.approx(1.1)
    assert res.table.loc["traffic ssm_n_member", "road"] == 1
    assert res.table.loc["traffic ssm_n_member", "free"] is None
    with pytest.raises(ValueError, match="baselines"):
        compare_runs([road], tmp_path / "x", baselines=[None, None])
    assert os.path.isfile(tmp_path / "cmp" / "compare.csv")


def test_a_600_s_run_with_50_vehicles_in_range_pairs_every_vehicle_with_every_member(tmp_path):
    """A long run with 50 vehicles in range: every (member, vehicle, step) pair is analysed.
    Its time is measured in benchmarks/analysis_speed.py, never here (timings stay out of tests)."""
    run = long_run_with_traffic(tmp_path / "long")
    a = compute_run(load_run(run), FAST)
    n_steps = int(round(600.0 / DT)) + 1
    assert a.traffic.run["n_pairs"] >= 3 * 50 * n_steps  # each member with each vehicle, each step


def long_run_with_traffic(run, t_end=600.0, n_vehicles=50):
    """A synthetic 3-abreast road run of ``t_end`` [s] with ``n_vehicles`` around it."""
    offsets = {"r": (0.0, -3.5), "c": (0.0, 0.0), "l": (0.0, 3.5)}
    S.write_run(run, S.trajectories(dt=DT, t_end=t_end, v=25.0, offsets=offsets, road=True),
                offsets=offsets, meta=S.ROAD_META, n_parts=4)
    rng = np.random.default_rng(1)
    vehicles = {f"bg{k}": {"s0": float(rng.uniform(-90, 90)), "d": 3.5 * (k % 3 - 1),
                           "v": 25.0} for k in range(n_vehicles)}
    S.write_traffic(run, background_df=S.background(S.time_vector(DT, t_end), vehicles),
                    n_parts=4)
    return run


def test_a_mixed_formation_gets_each_members_own_body(tmp_path):
    """run.json records every member's body; a truck among cars is a truck in the analysis
    (each member's clearance uses its own outline, not the first member's)."""
    from analysis.runs.interaction_run import member_rows
    from analysis.metrics.traffic import member_footprints

    car = {"length": 4.6, "width": 1.8, "a": 1.421, "front_overhang": 0.9}
    truck = {"length": 7.5, "width": 2.3, "a": 1.7, "front_overhang": 1.3}
    members = [{"id": mid, "offset": list(off), "frame": "vehicle", "body": body}
               for (mid, off), body in zip(OFFSETS.items(), (car, truck, car))]
    run = road_run(tmp_path / "run", meta={"members": members})
    data = load_run(run)
    fps = member_footprints(data.meta.get("scenario"), data.meta.get("members"))
    rows = member_rows(data, fps, data.dt)
    got = rows.groupby("vehicle_id")[["length", "width"]].first()
    for m in members:
        assert tuple(got.loc[m["id"]]) == (m["body"]["length"], m["body"]["width"])
    # the body centre sits (a + overhang - L/2) ahead of the CoG: 0.07 m for the car, -0.75 m for the truck
    traj = data.trajectories.set_index(["vehicle_id", "t"])
    first = rows.groupby("vehicle_id").first()
    for m in members:
        b = m["body"]
        x_cog = traj.loc[(m["id"], first.loc[m["id"], "t"]), "x"]
        assert first.loc[m["id"], "x"] - x_cog == pytest.approx(b["a"] + b["front_overhang"] - b["length"] / 2, abs=1e-9)
