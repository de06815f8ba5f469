"""Conflicts from the recording (analysis/metrics/conflicts.py) and the classification of SUMO's
extreme SSM records (analysis/runs/conflict_run.py), on hand-made tables with numbers worked out
by hand."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.metrics import conflicts as cf
from analysis.runs.conflict_run import classify_extremes

DT = 0.05
CAR_L, CAR_W = 4.5, 1.8


def _rows(vehicles: dict, t_end: float) -> pd.DataFrame:
    """One row per vehicle per step; each vehicle: s0 [m] (body centre), v [m/s], lane, d [m],
    optional a [m/s^2] and lane_at (list of (t, lane, d) switches)."""
    t = np.round(np.arange(0.0, t_end + DT / 2, DT), 10)
    frames = []
    for vid, p in vehicles.items():
        a = p.get("a", 0.0)
        v = np.maximum(p["v"] + a * t, 0.0)
        s = p["s0"] + p["v"] * t + 0.5 * a * t * t
        lane = np.full(t.size, float(p["lane"]))
        d = np.full(t.size, float(p.get("d", 3.5 * (p["lane"] - 1))))
        for t_sw, ln, dd in p.get("lane_at", []):
            lane[t >= t_sw], d[t >= t_sw] = ln, dd
        frames.append(pd.DataFrame({"vehicle_id": vid, "t": t, "key": np.round(t / DT).astype(int),
                                    "s": s, "d": d, "v": v, "lane_index": lane,
                                    "length": p.get("length", CAR_L), "width": CAR_W}))
    return pd.concat(frames, ignore_index=True)


def test_ttc_and_drac_of_a_closing_follower():
    """Follower 10 m/s faster, bumper gap 20 m: TTC 2 s, DRAC = 10^2 / (2*20) = 2.5 m/s^2."""
    gap, ttc, drac = cf.following_measures(0.0, 4.0, 30.0, 24.0, 4.0, 20.0)
    assert (gap, ttc, drac) == pytest.approx((20.0, 2.0, 2.5))
    gap, ttc, drac = cf.following_measures(0.0, 4.0, 20.0, 24.0, 4.0, 30.0)  # opening
    assert np.isnan(ttc) and np.isnan(drac)
    gap, ttc, drac = cf.following_measures(0.0, 4.0, 30.0, 3.0, 4.0, 20.0)  # overlapping
    assert gap < 0 and ttc == 0.0 and np.isnan(drac)


def test_pairs_need_the_same_lane_and_overlapping_bodies():
    """Same SUMO lane but side by side without lateral overlap (a car passing a truck inside a
    3.5 m lane in the sublane model): not a following pair; another lane: not either."""
    key = [0, 0, 0, 0]
    lane = [1, 1, 1, 0]
    s = [0.0, 9.0, 30.0, 15.0]
    d = [1.62, -0.6, 1.0, -3.5]  # car at +1.62, truck at -0.6: 2.22 m apart > (1.8 + 2.5) / 2
    length = [4.5, 12.0, 4.5, 4.5]
    width = [1.8, 2.5, 1.8, 1.8]
    f, l = cf.following_pairs(key, lane, s, d, length, width)
    assert sorted(zip(f.tolist(), l.tolist())) == [(0, 2), (1, 2)]


def test_recorded_conflict_of_a_closing_pair_matches_the_closed_form():
    """Follower at 30 m/s, 40 m (bumper to bumper) behind a leader at 20 m/s in the same lane:
    TTC(t) = (40 - 10 t) / 10, below 3 s from t = 1 s; over 2 s the minimum is 2.0 s at t = 2 s;
    DRAC(t) = 100 / (2 (40 - 10 t)), largest 2.5 m/s^2 at t = 2 s (not above 3: TTC makes it)."""
    rows = _rows({"f": {"s0": 0.0, "v": 30.0, "lane": 1}, "l": {"s0": 44.5, "v": 20.0, "lane": 1}}, 2.0)
    c = cf.recorded_conflicts(rows, ["f"])
    assert len(c) == 1
    r = c.iloc[0]
    assert (r.follower, r.leader, bool(r.member_involved)) == ("f", "l", True)
    assert r.min_ttc == pytest.approx(2.0) and r.min_ttc_time == pytest.approx(2.0)
    assert r.max_drac == pytest.approx(2.5) and r.min_gap == pytest.approx(20.0)
    assert (r.begin, r.end) == (0.0, 2.0)


def test_pet_of_a_lane_change_in_front_of_a_follower():
    """At t = 1 s 'c' (25 m/s) moves into lane 1 with its rear 30 m ahead of the front of 'f'
    (30 m/s): f's front reaches that point 1 s later, PET = 30 / 30 = 1.0 s (< 2 s: a conflict),
    while its TTC is 30 / 5 = 6 s at the change."""
    rows = _rows({"f": {"s0": 0.0, "v": 30.0, "lane": 1},
                  "c": {"s0": 39.5, "v": 25.0, "lane": 0, "lane_at": [(1.0, 1, 0.0)]}}, 3.0)
    c = cf.recorded_conflicts(rows, [])
    assert len(c) == 1
    r = c.iloc[0]
    assert (r.follower, r.leader) == ("f", "c")
    assert r.pet == pytest.approx(1.0, abs=1e-9) and r.pet_time == pytest.approx(1.0)
    assert r.min_ttc == pytest.approx((30.0 - 2 * 5.0) / 5.0)  # smallest at t = 3 s
    assert not bool(r.member_involved)


def test_compare_with_ssm_finds_and_measures():
    ours = pd.DataFrame({"follower": ["a", "x"], "leader": ["b", "y"], "begin": [0.0, 5.0],
                         "end": [4.0, 6.0], "min_ttc": [2.1, 1.0]})
    ssm = pd.DataFrame({"ego": ["b", "a", "p"], "foe": ["a", "b", "q"], "begin": [1.0, 10.0, 0.0],
                        "end": [3.0, 12.0, 9.0], "min_ttc": [2.25, 2.0, 1.0]})
    chk = cf.compare_with_ssm(ours, ssm)
    assert chk["found"].tolist() == [True, False, False]
    assert chk["within"].tolist() == [True, False, False]
    assert chk["ours_min_ttc"].iloc[0] == pytest.approx(2.1)


def _ssm(**cols) -> pd.DataFrame:
    base = dict(begin=0.0, end=10.0, ego="p", foe="q", member_involved=False, min_ttc=0.0,
                min_ttc_time=5.0, max_drac=50.0, max_drac_time=4.95, pet=np.nan,
                min_ttc_type=111.0, min_ttc_s=500.0, min_ttc_d=0.0)
    n = max(len(v) for v in cols.values() if isinstance(v, list))
    return pd.DataFrame({k: cols.get(k, [v] * n) for k, v in base.items()})


def test_extreme_ssm_records_are_classified():
    """Numbers from real runs of straight3: TTC 0 of type 111 between a truck and a car side by
    side in one lane (no collision) is a lane-change artefact; with a SUMO collision of the pair
    it is real; at the start of the encounter an insertion; within 2 s of a member's insertion and
    50 m of it a moved-member artefact; TTC 2.5 s and DRAC 2.2 is not extreme."""
    ssm = _ssm(ego=["main.42", "p", "n1", "x", "main.21", "c"],
               foe=["main.46", "q", "n2", "y", "main.15", "main.12"],
               begin=[19.75, 0.0, 3.0, 1.0, 2.0, 0.0], min_ttc_time=[28.55, 5.0, 3.5, 1.0, 4.0, 0.7],
               min_ttc=[0.0, 0.0, 0.0, 0.0, 2.55, 0.0], max_drac=[46.4, 50.0, 20.0, 30.0, 2.2, 336.8],
               min_ttc_s=[703.7, 500.0, 900.0, 310.0, 600.0, 294.7],
               min_ttc_type=[111.0, 111.0, 111.0, 111.0, 2.0, 111.0])
    events = pd.DataFrame({"t": [5.0], "kind": ["collision"], "vehicle_id": ["q"], "other_id": ["p"],
                           "detail": [""]})
    member_s = pd.DataFrame({"t": [0.05, 1.0, 1.0], "vehicle_id": ["c", "c", "c"],
                             "s": [295.0, 320.0, 320.0]})
    cls = classify_extremes(ssm, {"c"}, events, member_s, t_insert=0.05)
    assert cls.tolist() == ["lane_change", "real", "insertion", "moved_member", "", "moved_member"]
