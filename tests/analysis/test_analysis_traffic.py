"""Traffic-interaction measures (analysis.metrics.traffic) against closed-form answers."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.metrics import traffic as tr

CAR_L, CAR_W = 4.6, 1.8


# --- footprints -----------------------------------------------------------------------------

def test_member_footprints_mirror_the_model_presets():
    from formation_traci.models.params import VEHICLE_PRESETS

    assert set(tr.MEMBER_FOOTPRINTS) == set(VEHICLE_PRESETS)
    for name, p in VEHICLE_PRESETS.items():
        fp = tr.MEMBER_FOOTPRINTS[name]
        assert (fp.length, fp.width, fp.a, fp.front_overhang) == (
            p.length, p.width, p.a, p.front_overhang)
        assert fp.cog_to_front == pytest.approx(p.cog_to_front_bumper)


def test_member_footprint_from_scenario_with_overrides():
    fp, src = tr.member_footprint({"vehicle": {"preset": "small_truck", "params": {
        "length": 8.0, "width": None, "front_overhang": 0.0}}})
    assert (fp.length, fp.width, fp.cog_to_front) == (8.0, 2.3, 1.7)
    assert "small_truck" in src and "length" in src and "front_overhang" in src
    fp, src = tr.member_footprint(None)
    assert fp == tr.MEMBER_FOOTPRINTS["passenger_car"] and "assumed" in src


def test_body_centre_moves_the_cog_along_the_heading():
    x, y = tr.body_centre(10.0, 5.0, math.pi / 2, 3.0, 7.5)  # truck: CoG 0.75 m ahead
    assert (float(x), float(y)) == pytest.approx((10.0, 4.25))


# --- clearance ------------------------------------------------------------------------------

def test_clearance_parallel_rectangles():
    # nose to tail: 10 m between centres, 4 m long -> 6 m; side by side: 5 - 2 = 3 m
    assert tr.clearance(0, 0, 0, 4, 2, 10, 0, 0, 4, 2)[0] == pytest.approx(6.0)
    assert tr.clearance(0, 0, 0, 4, 2, 0, 5, 0, 4, 2)[0] == pytest.approx(3.0)
    # diagonal: corner (2, 1) of A to corner (5, 3) of B
    assert tr.clearance(0, 0, 0, 4, 2, 6, 4, 0, 2, 2)[0] == pytest.approx(math.hypot(3, 2))


def test_clearance_rotated_rectangle():
    # a 2 x 2 square turned 45 deg at x = 5 points a corner at x = 5 - sqrt(2)
    assert tr.clearance(0, 0, 0, 4, 2, 5, 0, math.pi / 4, 2, 2)[0] == pytest.approx(
        3 - math.sqrt(2))
    # both rotated by the same angle: the distance of the unrotated pair
    h = 0.7
    c, s = math.cos(h), math.sin(h)
    assert tr.clearance(0, 0, h, 4, 2, 10 * c, 10 * s, h, 4, 2)[0] == pytest.approx(6.0)


def test_clearance_overlapping_is_zero_also_without_a_corner_inside():
    assert tr.clearance(0, 0, 0, 4, 2, 1, 1, 0.3, 4, 2)[0] == 0.0
    # a cross: two long thin bars, no corner of one inside the other
    assert tr.clearance(0, 0, 0, 10, 1, 0, 0, math.pi / 2, 10, 1)[0] == 0.0
    # touching edges
    assert tr.clearance(0, 0, 0, 4, 2, 4, 0, 0, 4, 2)[0] == 0.0


def _outline(x, y, h, length, width, n=120):
    c = tr.rectangle_corners(x, y, h, length, width)[0]
    f = np.linspace(0, 1, n, endpoint=False)[:, None]
    return np.concatenate([c[k] + f * (c[(k + 1) % 4] - c[k]) for k in range(4)])


def test_clearance_matches_brute_force_on_random_pairs():
    rng = np.random.default_rng(3)
    n = 150
    a = np.column_stack([np.zeros(n), np.zeros(n), rng.uniform(-np.pi, np.pi, n),
                         rng.uniform(3, 12, n), rng.uniform(1.5, 2.6, n)])
    b = np.column_stack([rng.uniform(-15, 15, n), rng.uniform(-8, 8, n),
                         rng.uniform(-np.pi, np.pi, n), rng.uniform(3, 12, n),
                         rng.uniform(1.5, 2.6, n)])
    got = tr.clearance(*a.T, *b.T)
    assert np.allclose(got, tr.clearance(*b.T, *a.T))
    checked = 0
    for k in range(n):
        pa, pb = _outline(*a[k]), _outline(*b[k])
        brute = np.min(np.hypot(*(pa[:, None, :] - pb[None, :, :]).transpose(2, 0, 1)))
        if brute > 0.15:  # clearly apart: exact value within the outline sampling step
            assert got[k] == pytest.approx(brute, abs=0.06)
            assert got[k] <= brute + 1e-9
            checked += 1
        elif got[k] > 0:  # a small gap: brute force can only be larger
            assert got[k] <= brute + 1e-9
    assert checked > 50


# --- 2-D time to collision -----------------------------------------------------------------

def test_ttc2d_rear_end_is_gap_over_closing_speed():
    # follower A at 30 m/s, leader B 30 m ahead (centres) at 25 m/s; cars 4.6 / 4.5 m long
    gap = 30 - CAR_L / 2 - 4.5 / 2
    got = tr.ttc_2d(tr.Moving(0, 0, 0, CAR_L, CAR_W, 30, 0), tr.Moving(30, 0, 0, 4.5, CAR_W, 25, 0))[0]
    assert got == pytest.approx(gap / 5.0)
    # a heading different from +x changes nothing
    h = 1.1
    c, s = math.cos(h), math.sin(h)
    got = tr.ttc_2d(tr.Moving(0, 0, h, CAR_L, CAR_W, 30 * c, 30 * s), tr.Moving(30 * c, 30 * s, h, 4.5, CAR_W, 25 * c, 25 * s))[0]
    assert got == pytest.approx(gap / 5.0)


def test_ttc2d_lateral_merge_touches_with_the_leading_corner():
    # B beside A, turned by th towards it; same speed along x: pure lateral approach
    th, v, dy = -0.1, 20.0, 3.5
    lowest = dy - CAR_L / 2 * math.sin(-th) - CAR_W / 2 * math.cos(th)  # B's front-right corner
    expected = (lowest - CAR_W / 2) / (v * math.sin(-th))
    got = tr.ttc_2d(tr.Moving(0, 0, 0, CAR_L, CAR_W, v * math.cos(th), 0), tr.Moving(0, dy, th, CAR_L, CAR_W, v * math.cos(th), v * math.sin(th)))[0]
    assert got == pytest.approx(expected)


def test_ttc2d_no_contact_cases():
    inf = math.inf
    # moving apart, same speed, beyond the horizon
    assert tr.ttc_2d(tr.Moving(0, 0, 0, 4, 2, 25, 0), tr.Moving(30, 0, 0, 4, 2, 30, 0))[0] == inf
    assert tr.ttc_2d(tr.Moving(0, 0, 0, 4, 2, 25, 0), tr.Moving(30, 0, 0, 4, 2, 25, 0))[0] == inf
    assert tr.ttc_2d(tr.Moving(0, 0, 0, 4, 2, 26, 0), tr.Moving(30, 0, 0, 4, 2, 25, 0), horizon=10.0)[0] == inf
    # crossing paths that miss: B crosses A's path 2.5 s before A gets there
    assert tr.ttc_2d(tr.Moving(0, 0, 0, 4, 2, 20, 0), tr.Moving(100, 50, -math.pi / 2, 4, 2, 0, -20))[0] == inf
    # ... and the same crossing timed to hit: B reaches y = 0 when A reaches x = 50
    t_hit = tr.ttc_2d(tr.Moving(0, 0, 0, 4, 2, 20, 0), tr.Moving(50, 50, -math.pi / 2, 4, 2, 0, -20))[0]
    assert 0 < t_hit < 2.5
    # already overlapping
    assert tr.ttc_2d(tr.Moving(0, 0, 0, 4, 2, 20, 0), tr.Moving(1, 0.5, 0, 4, 2, 20, 0))[0] == 0.0


def test_pair_measures_equal_the_single_functions():
    rng = np.random.default_rng(7)
    args = [rng.uniform(-20, 20, 50), rng.uniform(-5, 5, 50), rng.uniform(-0.3, 0.3, 50),
            np.full(50, 4.6), np.full(50, 1.8), rng.uniform(15, 30, 50), np.zeros(50)]
    brg = [rng.uniform(-20, 20, 50), rng.uniform(-5, 5, 50), rng.uniform(-0.3, 0.3, 50),
           np.full(50, 12.0), np.full(50, 2.5), rng.uniform(15, 30, 50), np.zeros(50)]
    clr, ttc = tr.pair_measures(tr.Moving(*args), tr.Moving(*brg))
    geo_a, geo_b = args[:5], brg[:5]
    np.testing.assert_array_equal(clr, tr.clearance(*geo_a, *geo_b))
    np.testing.assert_array_equal(ttc, tr.ttc_2d(tr.Moving(*args), tr.Moving(*brg)))


# --- road-coordinate gaps and headway ------------------------------------------------------

def test_lateral_gap_of_side_by_side_cars():
    assert tr.lateral_gap(0, 0, CAR_L, CAR_W, 1.0, 3.5, 4.5, 1.8) == pytest.approx(1.7)
    assert tr.lateral_gap(0, 0, CAR_L, CAR_W, 0.0, -2.9, 4.5, 1.8) == pytest.approx(1.1)
    # 4.6 m apart: not side by side (the bodies do not overlap along s)
    assert np.isnan(tr.lateral_gap(0, 0, CAR_L, CAR_W, 4.6, 3.5, 4.6, 1.8))


def test_headway_of_a_constructed_pair():
    # follower centre at 0 (4.6 m), leader centre at 30 (4.5 m): gap 30 - 2.3 - 2.25
    gap = tr.gap_ahead(0.0, CAR_L, 30.0, 4.5)
    assert gap == pytest.approx(25.45)
    assert tr.time_headway(gap, 20.0) == pytest.approx(25.45 / 20.0)
    assert np.isnan(tr.time_headway(gap, 0.0))
    assert tr.in_lateral_band(0.0, 1.8, 1.7, 1.8) and not tr.in_lateral_band(0.0, 1.8, 1.8, 1.8)


def test_same_time_pairs_match_every_combination():
    ia, ib = tr.same_time_pairs([5, 7, 5], [7, 5, 5, 9])
    assert sorted(zip(ia.tolist(), ib.tolist())) == [(0, 1), (0, 2), (1, 0), (2, 1), (2, 2)]


# --- SSM ------------------------------------------------------------------------------------

def _ssm(rows):
    return pd.DataFrame(rows, columns=["begin", "end", "ego", "foe", "member_involved",
                                       "min_ttc", "min_ttc_time", "max_drac",
                                       "max_drac_time", "pet"])


def test_ssm_duplicates_merged_and_split_by_member():
    t = _ssm([
        (1.0, 5.0, "m1", "bg1", True, 2.0, 3.0, 2.5, 3.0, np.nan),
        (1.0, 5.0, "bg1", "m1", True, 2.0, 3.0, 2.5, 3.0, np.nan),  # same conflict, swapped
        (2.0, 4.0, "bg2", "m2", True, 1.2, 3.5, 4.0, 3.5, 1.5),
        (6.0, 9.0, "bg3", "bg4", False, np.nan, np.nan, 3.5, 7.0, np.nan),
        (6.0, 9.0, "bg4", "bg3", False, np.nan, np.nan, 3.5, 7.0, np.nan),
        (6.5, 8.0, "bg5", "bg6", False, 0.8, 7.0, 1.0, 7.0, np.nan),
    ])
    m = tr.merge_ssm_duplicates(t)
    assert len(m) == 4 and list(m.columns) == list(t.columns)
    groups = np.where(m["member_involved"], "member", "other")
    s = tr.ssm_summary(m, groups)
    assert s.loc["member"].to_dict() == {
        "n_conflicts": 2, "ttc_min_s": 1.2, "drac_max_mps2": 4.0, "pet_min_s": 1.5,
        "n_ttc_warning": 2, "n_ttc_critical": 1, "n_drac_high": 1}
    assert s.loc["other", "n_conflicts"] == 2 and s.loc["other", "ttc_min_s"] == 0.8
    assert s.loc["other", "n_ttc_critical"] == 1 and s.loc["other", "n_drac_high"] == 1
    assert np.isnan(s.loc["other", "pet_min_s"])


def test_event_counts_per_vehicle_and_role():
    ev = pd.DataFrame({"t": [1, 2, 3, 4], "kind": ["collision", "cut_in", "collision", "cut_in"],
                       "vehicle_id": ["bg1", "bg2", "m1", "m1"],
                       "other_id": ["m1", "m1", "m2", "m2"], "detail": ""})
    c = tr.event_counts(ev, ["m1", "m2"], ["collision"])
    assert c["collision"].to_dict() == {"m1": 2, "m2": 1}
    c = tr.event_counts(ev, ["m1", "m2"], ["cut_in"], roles=("other_id",))
    assert c["cut_in"].to_dict() == {"m1": 1, "m2": 1}


# --- time loss, travel times, baseline --------------------------------------------------------

def test_time_loss_against_own_maximum_and_given_reference():
    v = np.r_[np.full(10, 20.0), np.full(20, 10.0), np.full(10, 20.0)]  # 2 s at half speed
    assert tr.time_loss(v, 0.1) == pytest.approx(1.0)
    assert tr.time_loss(v, 0.1, v_ref=40.0) == pytest.approx(0.1 * (20 * 0.5 + 20 * 0.75))
    two = np.vstack([v, np.full(40, 5.0)])
    np.testing.assert_allclose(tr.time_loss(two, 0.1), [1.0, 0.0])


def test_crossing_times_interpolate_and_ignore_backward_jitter():
    t = np.arange(6.0)
    s = np.array([0.0, 10.0, 9.9, 20.0, 30.0, 40.0])
    np.testing.assert_allclose(tr.crossing_times(t, s, [5.0, 15.0, 40.0]), [0.5, 2.5, 5.0])
    assert np.isnan(tr.crossing_times(t, s, [-1.0, 41.0])).all()


def _vehicle(vid, t, s):
    return pd.DataFrame({"t": t, "vehicle_id": vid, "s": s})


def test_baseline_comparison_a_vehicle_slowed_by_two_seconds():
    t = np.round(np.arange(0.0, 20.0 + 1e-9, 0.05), 9)
    base = pd.concat([_vehicle("slow", t, 20.0 * t), _vehicle("same", t, 5.0 + 25.0 * t),
                      _vehicle("only_base", t, 20.0 * t)])
    # "slow" stands still for 2 s at s = 100 (t = 5..7) in the formation run
    s_slow = np.where(t < 5, 20 * t, np.where(t < 7, 100.0, 100 + 20 * (t - 7)))
    run = pd.concat([_vehicle("slow", t, s_slow), _vehicle("same", t, 5.0 + 25.0 * t),
                     _vehicle("only_run", t, 20.0 * t)])
    out = tr.baseline_comparison(run, base, 50.0, 250.0)
    assert list(out.index) == ["slow", "same"]  # largest delay first; common ids only
    assert out.loc["slow", "delta_s"] == pytest.approx(2.0)
    assert out.loc["slow", "tt_base_s"] == pytest.approx(10.0)
    assert out.loc["slow", "v_run_mps"] == pytest.approx(200.0 / 12.0)
    assert out.loc["same", "delta_s"] == pytest.approx(0.0, abs=1e-9)
    assert out["full_section"].all()


def test_baseline_comparison_clips_to_the_part_recorded_in_both():
    t = np.round(np.arange(0.0, 10.0 + 1e-9, 0.1), 9)
    base = _vehicle("v", t, 20.0 * t)  # 0 .. 200 m
    near = t >= 3  # the formation run recorded it only from s = 60 m on, 10 % slower
    run = _vehicle("v", t[near], 60 + 18.0 * (t[near] - 3))
    out = tr.baseline_comparison(run, base, 0.0, 500.0)
    row = out.loc["v"]
    assert (row["s_from"], row["s_to"]) == pytest.approx((60.0, 186.0))
    assert not row["full_section"]
    assert row["tt_run_s"] == pytest.approx(126 / 18) and row["tt_base_s"] == pytest.approx(6.3)
    assert tr.baseline_comparison(run, base, 0.0, 500.0, min_length=200.0).empty


def test_section_travel_times():
    t = np.arange(0.0, 11.0)
    out = tr.section_travel_times(_vehicle("a", t, 10.0 * t), 20.0, 75.0)
    assert out.loc["a", "travel_time_s"] == pytest.approx(5.5)
    with pytest.raises(ValueError, match="s_b"):
        tr.section_travel_times(_vehicle("a", t, t), 5.0, 5.0)


def test_member_footprint_from_run_json_members_body():
    """run.json members carry the body the runner simulated; it wins over the preset table
    (a scenario saying small_truck with a recorded 5 m body gives the recorded body)."""
    members = [{"id": "a", "body": {"length": 5.0, "width": 2.0, "a": 1.5, "front_overhang": 0.0}}]
    fp, src = tr.member_footprint({"vehicle": {"preset": "small_truck"}}, members)
    assert (fp.length, fp.width, fp.a, fp.front_overhang) == (5.0, 2.0, 1.5, 0.0)
    assert fp.cog_to_front == 1.5 and src == "run.json members body"
    # a damaged body falls back to the scenario
    fp, src = tr.member_footprint({"vehicle": {"preset": "small_truck"}},
                                  [{"body": {"length": "x"}}])
    assert fp == tr.MEMBER_FOOTPRINTS["small_truck"] and "preset" in src


def test_runner_records_the_member_body(tmp_path):
    from formation_traci.models.params import SMALL_TRUCK
    from formation_traci.scenario import load_scenario
    from formation_traci.runner import run_scenario
    import json
    root = Path(__file__).resolve().parents[2]
    sc = load_scenario(root / "scenarios" / "thesis" / "dynamic_case1.toml",
                       **{"run.duration": 0.1, "vehicle.preset": "small_truck",
                          "vehicle.params.length": 9.0})
    run_scenario(sc, tmp_path / "r", progress=False, force=True)
    meta = json.loads((tmp_path / "r" / "run.json").read_text())
    fp, src = tr.member_footprint(meta["scenario"], meta["members"])
    assert src == "run.json members body"
    assert (fp.length, fp.width, fp.a, fp.front_overhang) == (
        9.0, SMALL_TRUCK.width, SMALL_TRUCK.a, SMALL_TRUCK.front_overhang)
