"""The recording paths of issue 18 write, byte for byte, the part files the straightforward
code writes: the step's rows (written by the compiled member_signals / step_members, or by
Recorder.add_step and add_periods in one write per block, against add_signal_rows +
add_comfort_rows + add_vc and add_comfort_periods), the background rows (add_background against
the column-by-column append), and the traffic and emergency watches report the events the
loops they shortcut report. Parts are made tiny so
the fallbacks (a part ending inside a step, members out of the run, signals out of range)
are crossed too. No timing here: benchmarks/ measures the speed."""
from __future__ import annotations

import numpy as np
import pytest

from formation_traci.control.formation import LeaderState
from formation_traci.record.columns import SIGNAL_COLUMNS
from formation_traci.sim import recorder as recorder_module
from formation_traci.sumo.events import EmergencyWatch, LaneTracker, MemberWatch, TrafficWatch
from formation_traci.sim.recorder import MAX_SLIP, Recorder
from formation_traci.sumo.types import Neighbours

IDS = ["m0", "m1", "m2", "m3"]
PERIODS = 5
COL = {c: j for j, c in enumerate(SIGNAL_COLUMNS)}


def _steps(n_steps=40, seed=5):
    """Synthetic recorded steps: (t, sig, extra, mask, truth, periods (m, n, 3))."""
    rng = np.random.default_rng(seed)
    n = len(IDS)
    out = []
    for k in range(n_steps):
        t = k * 0.05
        sig = rng.normal(size=(n, len(SIGNAL_COLUMNS)))
        sig[:, COL["v"]] = 25.0 + rng.normal(size=n)
        sig[:, [COL["slip_front"], COL["slip_rear"]]] *= 0.02
        sig[:, COL["friction_usage"]] = rng.uniform(0.0, 0.5, n)
        sig[k % n, COL["power"]] = np.nan  # NaN signals (e.g. the kinematic model's)
        if 7 <= k <= 9:
            sig[1, COL["slip_rear"]] = -2 * MAX_SLIP  # out of range: model_range once
        if k == 20:
            sig[3, COL["friction_usage"]] = 1.5
        if k == 30:
            sig[0, COL["v"]] = -70.0  # |v| large but v not above MAX_SPEED: no event
        extra = {"s": rng.normal(size=n), "d": rng.normal(size=n), "slot": np.arange(n, dtype=float),
                 "sumo_gap": rng.uniform(0, 0.1, n), "lane_index": rng.integers(0, 3, n).astype(float),
                 "leader_age_s": np.zeros(n)}
        if k % 11 == 5:
            extra = {"leader_age_s": np.zeros(n)}  # a world without road and SUMO columns
        mask = np.ones(n, dtype=bool)
        if 12 <= k <= 16:
            mask[2] = False
        if k == 25:
            mask = None
        truth = rng.normal(size=8)
        if k % 4 == 0:
            truth[7] = np.nan  # no s: d stays NaN
        out.append((t, sig, extra, mask, truth, rng.normal(size=(PERIODS, n, 3))))
    return out


def _part_bytes(out_dir):
    return {p.relative_to(out_dir).as_posix(): p.read_bytes()
            for p in sorted(out_dir.rglob("*.parquet")) if p.is_file()}


def _record(tmp_path, name, steps, fast, cut):
    rec = Recorder(tmp_path / name, IDS, with_sumo=False, periods_per_step=PERIODS)
    for k, (t, sig, extra, mask, truth, per) in enumerate(steps):
        if fast:
            rec.add_step(t, sig.copy(), extra, mask, truth)
            rec.add_periods(t, 0.01, per, mask)
        else:
            rec.add_signal_rows(t, sig.copy(), extra, mask=mask)
            rec.add_comfort_rows(t, sig, mask=mask)
            rec.add_vc(t, LeaderState(*(float(q) for q in truth[:7])), s=float(truth[7]))
            rec.add_comfort_periods([t + j * 0.01 for j in range(1, PERIODS)], per[1:], mask=mask)
        if cut:
            rec.end_step(k, t)
    assert rec.flush(t_end=steps[-1][0]) == []
    return rec


@pytest.mark.parametrize("cut", [True, False], ids=["cut every 6 steps", "parts end inside steps"])
def test_step_rows_equal_the_straightforward_calls_byte_for_byte(tmp_path, monkeypatch, cut):
    """add_step's block writes against the column-by-column calls (the control periods that
    sim/fleet.py step_members writes itself are compared in whole runs, below)."""
    monkeypatch.setattr(recorder_module, "STEPS_PER_CHUNK", 6)
    steps = _steps()
    slow = _record(tmp_path, "slow", steps, fast=False, cut=cut)
    fast = _record(tmp_path, "fast", steps, fast=True, cut=cut)
    a, b = _part_bytes(tmp_path / "slow"), _part_bytes(tmp_path / "fast")
    assert sorted(a) == sorted(b) and len([p for p in a if p.startswith("traj")]) >= 7
    for name in a:
        assert a[name] == b[name], name
    assert slow.event_counts == fast.event_counts == {"model_range": 2}


def _neighbours(ids, lanes, rng):
    n = len(ids)
    f = [rng.normal(size=n) for _ in range(7)]
    types = ["truck" if v.endswith("7") else "car" for v in ids]
    return Neighbours(list(ids), types, *f, list(lanes), np.array([int(ln[-1]) for ln in lanes]))


def _traffic(n_steps=60, seed=2):
    """Vehicles near the formation step by step: mostly the same ones on the same lanes
    (codes reused), some entering, leaving, changing lane or edge, steps with nobody."""
    rng = np.random.default_rng(seed)
    lanes = {f"f.{i}": f"e1_{i % 3}" for i in range(6)}
    out = []
    for k in range(n_steps):
        if k % 9 == 4:
            vid = next(iter(lanes))
            lanes[vid] = lanes[vid][:-1] + str((int(lanes[vid][-1]) + 1) % 3)  # lane change
        if k % 13 == 6:
            lanes.pop(sorted(lanes)[-1])  # leaves the radius
        if k % 7 == 3:
            lanes[f"f.{10 + k}"] = "e1_1"  # enters
        if k == 30:
            lanes = {v: "e2_" + ln[-1] for v, ln in lanes.items()}  # everybody on the next edge
        ids = [] if k in (40, 41) else sorted(lanes)
        out.append(_neighbours(ids, [lanes[v] for v in ids], rng))
    return out


def test_background_rows_equal_the_column_by_column_append_byte_for_byte(tmp_path, monkeypatch):
    monkeypatch.setattr(recorder_module, "BACKGROUND_CHUNK_ROWS", 17)  # parts end inside steps
    traffic = _traffic()
    recs = {m: Recorder(tmp_path / m, IDS, with_sumo=True) for m in ("slow", "fast")}
    rng = np.random.default_rng(0)
    for k, nb in enumerate(traffic):
        s, d = rng.normal(size=len(nb.ids)), rng.normal(size=len(nb.ids))
        if len(nb.ids):
            recs["slow"]._append_background(k * 0.05, nb, s, d)
        recs["fast"].add_background(k * 0.05, nb, s, d)
        if k % 20 == 19:
            for rec in recs.values():
                rec.end_step(k, k * 0.05)  # not a cut: STEPS_PER_CHUNK is 1200
                rec.background.flush(mark=k * 0.05)
    for rec in recs.values():
        assert rec.flush(t_end=3.0) == []
    a, b = _part_bytes(tmp_path / "slow"), _part_bytes(tmp_path / "fast")
    bg = [p for p in a if p.startswith("background")]
    assert sorted(a) == sorted(b) and len(bg) >= 10
    for name in bg:
        assert a[name] == b[name], name


class ReferenceTrafficWatch:
    """TrafficWatch without its shortcut: every vehicle looked at every step."""

    def __init__(self, rec, ids, lanes, time_gap, min_gap):
        self.rec, self.ids, self.lanes = rec, ids, lanes
        self.time_gap, self.min_gap = time_gap, min_gap

    def __call__(self, t, nb, lead_idx, gap, v_m, active):
        prev, seen, moved = self.lanes.prev, self.lanes.lane, []
        for j, vid in enumerate(nb.ids):
            lane, li = nb.lane_ids[j], int(nb.lane_index[j])
            if seen.get(vid) == lane:
                continue
            edge = lane.rsplit("_", 1)[0]
            was_edge, was_index = prev.get(vid, (None, None))
            seen[vid], prev[vid] = lane, (edge, li)
            if was_edge == edge and was_index != li and edge[:1] != ":":
                moved.append(j)
                self.rec.add_event(t, "lane_change", vid, "", f"{was_index} -> {li}")
        for i, member in enumerate(self.ids):
            j = lead_idx[i]
            if active[i] and j in moved and gap[i] < self.min_gap + self.time_gap * v_m[i]:
                self.rec.add_event(t, "cut_in", nb.ids[j], member, f"gap {gap[i]:.1f} m ahead of the member")


class ReferenceEmergencyWatch:
    """EmergencyWatch without its shortcut: every step, who brakes hard now against before."""

    def __init__(self, rec, ids, vc_ids=None):
        self.rec, self.who = rec, [*ids, *(vc_ids or ["vc"])]
        self.on = np.zeros(len(self.who), dtype=bool)

    def __call__(self, t, info):
        now = np.append(info["emergency_members"], info["emergency"])
        a = np.append(info["a_cap_request"], info["a_request"])
        for i in np.flatnonzero(now != self.on):
            start = ("emergency_brake", f"braking request {-a[i]:.2f} m/s^2")
            end = ("emergency_end", "back within comfortable braking")
            kind, detail = start if now[i] else end
            self.rec.add_event(t, kind, self.who[i], "", detail)
        self.on = now


class Events:
    def __init__(self):
        self.rows = []

    def add_event(self, *row, value=None):  # value: an incident's (sim/incident_log.py)
        self.rows.append(row)


def test_traffic_and_emergency_watches_report_what_the_full_loops_report():
    """Same events, step by step, with the member watch writing the shared lane tracker in
    between (a member whose id a SUMO vehicle also has: the shortcut must not hide it)."""
    rng = np.random.default_rng(4)
    traffic = _traffic(80, seed=9)
    got, want = Events(), Events()
    watches = []
    for cls, emerg, rec in ((TrafficWatch, EmergencyWatch, got),
                            (ReferenceTrafficWatch, ReferenceEmergencyWatch, want)):
        lanes = LaneTracker()
        watches.append((cls(rec, IDS, lanes, 1.0, 2.0), emerg(rec, IDS), MemberWatch(rec, ["f.0"] + IDS[1:], lanes)))
    for k, nb in enumerate(traffic):
        m = len(nb.ids)
        lead = rng.integers(-1, max(m, 1), len(IDS)) if m else np.full(len(IDS), -1)
        gap, v_m = rng.uniform(0, 60, len(IDS)), rng.uniform(20, 30, len(IDS))
        active = rng.uniform(size=len(IDS)) > 0.1
        members = rng.uniform(size=len(IDS)) > (0.2 if 20 <= k < 30 else 1.0)
        info = {"emergency_members": members, "emergency": bool(k in (50, 51, 55)),
                "a_request": -6.0, "a_cap_request": rng.uniform(-8, -5, len(IDS))}
        for traffic_watch, emergency_watch, member_watch in watches:
            if k % 10 == 8:  # member "f.0" on a lane, written into the shared tracker
                member_watch.lane_changes(k * 0.1, [0], [True], [f"e1_{k % 3}"], [k % 3])
            emergency_watch(k * 0.1, info)
            traffic_watch(k * 0.1, nb, lead, gap, v_m, active)
    kinds = {r[1] for r in want.rows}
    assert {"lane_change", "cut_in", "emergency_brake", "emergency_end"} <= kinds
    assert got.rows == want.rows


def _straightforward(monkeypatch):
    """The recording as it was: the rows column by column, the watches' full loops."""
    from formation_traci.sumo import world as sumo_world

    def add_step(self, t, sig, extra, mask, truth, written=False):
        assert not written
        self.add_signal_rows(t, sig, extra, mask=mask)
        self.add_comfort_rows(t, sig, mask=mask)
        self.add_vc(t, LeaderState(*(float(q) for q in truth[:7])), s=float(truth[7]))

    def add_periods(self, t, dt, vals, mask=None, written=False):
        assert not written
        if vals.shape[0] > 1:
            self.add_comfort_periods([t + j * dt for j in range(1, vals.shape[0])], vals[1:], mask=mask)

    def add_background(self, t, nb, s, d):
        if len(nb.ids):
            self._append_background(t, nb, s, d)

    monkeypatch.setenv("FORMATION_TRACI_FUSED", "off")  # sumo/fused_path.py writes rows of its own
    monkeypatch.setattr(Recorder, "signal_rows", lambda self, mask: None)
    monkeypatch.setattr(Recorder, "period_rows", lambda self, m, mask: None)
    monkeypatch.setattr(Recorder, "add_step", add_step)
    monkeypatch.setattr(Recorder, "add_periods", add_periods)
    monkeypatch.setattr(Recorder, "add_background", add_background)
    monkeypatch.setattr(sumo_world, "TrafficWatch", ReferenceTrafficWatch)
    monkeypatch.setattr(sumo_world, "EmergencyWatch", ReferenceEmergencyWatch)


@pytest.mark.parametrize("case", ["highway", pytest.param("free space", marks=pytest.mark.jit_off),
                                  pytest.param("free space, delayed leader", marks=pytest.mark.jit_off)])
def test_runs_write_the_files_the_straightforward_recording_writes(tmp_path, monkeypatch, case):
    """Real runs (SUMO through libsumo; free space, also with a delayed virtual car, whose error
    is recorded against the true one), tables cut every 10 steps: the part files are the same
    bytes with the compiled rows and block writes as with the straightforward recording."""
    from pathlib import Path

    from formation_traci.scenario import load_scenario
    from formation_traci.runner import run_scenario

    root = Path(__file__).resolve().parents[1]
    if case == "highway":
        path = root / "scenarios" / "highway" / "straight_wedge5_medium.toml"
        kw = {"run.duration": 3.0, "traffic.warmup": 10.0}
    else:
        path = root / "scenarios" / "thesis" / "dynamic_case4_turning.toml"
        kw = {"run.duration": 2.0, **({"comm.delay_s": 0.1} if "delayed" in case else {})}
    monkeypatch.setattr(recorder_module, "STEPS_PER_CHUNK", 10)
    sc = load_scenario(path, **kw)
    fast = run_scenario(sc, tmp_path / "fast", scenario_path=path, progress=False, force=True)
    _straightforward(monkeypatch)
    slow = run_scenario(sc, tmp_path / "slow", scenario_path=path, progress=False, force=True)
    assert fast.status == slow.status == "completed"
    a, b = _part_bytes(tmp_path / "slow"), _part_bytes(tmp_path / "fast")
    assert sorted(a) == sorted(b) and len([p for p in a if p.startswith("traj")]) >= 4
    assert (case == "highway") == any(p.startswith("background") for p in a)
    for name in a:
        assert a[name] == b[name], name


def test_extras_after_a_step_without_road_columns_are_still_recorded(tmp_path):
    """A step lacking the road columns (free space) records NaN in them; a later step that has
    them records their values (sim/record_rows.py road_rows, through Recorder._road_rows)."""
    rec = Recorder(tmp_path / "extras", IDS, with_sumo=True)
    names = recorder_module.FILLED_BY_CALLER[2:]
    every = np.ones(len(IDS), dtype=bool)
    assert rec._road_rows({"leader_age_s": np.full(len(IDS), 0.5)}, 0, every) == len(IDS)
    want = np.full((len(names), len(IDS)), np.nan)
    want[names.index("leader_age_s")] = 0.5
    np.testing.assert_array_equal(rec._extra_block[:, :len(IDS)], want)
    full = {name: np.arange(len(IDS), dtype=float) + i for i, name in enumerate(names)}
    full["slot"] = np.arange(len(IDS))  # integers and scalars are taken as float64 rows
    full["leader_age_s"] = 0.25
    rec._road_rows(full, 0, every)
    full["slot"], full["leader_age_s"] = full["slot"].astype(float), np.full(len(IDS), 0.25)
    np.testing.assert_array_equal(rec._extra_block[:, :len(IDS)], np.array([full[name] for name in names]))
    assert rec.flush() == []
