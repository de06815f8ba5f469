"""The shared warm-up (sumo/warm_state.py, docs/sweeps.md "The shared warm-up"): the key, the
merge of SUMO's outputs, and with real SUMO (each run a process of its own, as in a sweep):
runs from the state are value-identical to each other, start from the unshared run's traffic,
and differ from it only by what SUMO's state does not hold (the documented exception)."""
from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

from formation_traci.sumo.types import MemberType
from formation_traci.sumo.warm_state import WarmSetup, merge_outputs, warm_key

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"
STEP = 0.05  # run.step of SCENARIO [s]
ACCEL, EMERGENCY_DECEL = 2.6, 9.0  # the cars' accel and emergencyDecel (sumo/traffic.py) [m/s^2]
MAX_SPEED_LAT = 1.0  # SUMO's default maxSpeedLat of the background vTypes [m/s]
SETUP = WarmSetup(("main",), 1.0, "formation_route", ("entry", "main"),
                  (MemberType("member_passenger_car", 4.5, 1.8, 1.5, (255, 0, 0), "custom1"),), (), ("custom1",))


def _args(run: Path, net: Path, seed: int = 1) -> list[str]:
    return ["-n", str(net), "-r", str(run / "traffic.rou.xml"), "--seed", str(seed),
            "--log", str(run / "sumo.log")]


def test_key_is_what_sumo_sees_not_where_the_run_is(tmp_path):
    net = tmp_path / "net.xml"
    net.write_text("<net/>")
    runs = []
    for name in ("a", "b"):
        d = tmp_path / name / "sumo"
        d.mkdir(parents=True)
        (d / "traffic.rou.xml").write_text("<routes><flow id='main'/></routes>")
        runs.append(d)
    key = warm_key(_args(runs[0], net), runs[0], SETUP, 1200)
    assert warm_key(_args(runs[1], net), runs[1], SETUP, 1200) == key  # another run directory
    assert warm_key(_args(runs[0], net, seed=2), runs[0], SETUP, 1200) != key
    assert warm_key(_args(runs[0], net), runs[0], SETUP, 1201) != key
    assert warm_key(_args(runs[0], net), runs[0], dataclasses.replace(SETUP, mu=0.5), 1200) != key
    (runs[1] / "traffic.rou.xml").write_text("<routes><flow id='main' vehsPerHour='1'/></routes>")
    assert warm_key(_args(runs[1], net), runs[1], SETUP, 1200) != key  # the flows as written
    net.write_text("<net version='2'/>")
    assert warm_key(_args(runs[0], net), runs[0], SETUP, 1200) != key  # the network's content


def test_merge_puts_the_warmup_part_first(tmp_path):
    entry, run = tmp_path / "entry", tmp_path / "run"
    entry.mkdir()
    run.mkdir()
    head = '<?xml version="1.0"?>\n<!-- <configuration><a value="x"/></configuration> -->\n'
    (entry / "sections.xml").write_text(head + '<instantE1 x="1">\n    <instantOut t="1"/>\n</instantE1>\n')
    (run / "sections.xml").write_text(head.replace("x", "y") + '<instantE1 x="1">\n    <instantOut t="2"/>\n</instantE1>\n')
    (entry / "messages.log").write_text("Warning: one\n")
    (run / "messages.log").write_text("Warning: two\n")
    merge_outputs(run, {"shared": True, "entry": str(entry)})
    root = ET.parse(run / "sections.xml").getroot()
    assert [el.get("t") for el in root] == ["1", "2"]
    assert 'value="y"' in (run / "sections.xml").read_text()  # the run's own header
    assert (run / "messages.log").read_text() == "Warning: one\nWarning: two\n"


def _run(out: Path, cache: Path | None, warmup: float = 10.0, duration: float = 2.0) -> dict:
    cmd = [sys.executable, "-m", "formation_traci.cli", "run", str(SCENARIO), "--out", str(out),
           "--set", f"traffic.warmup={warmup}", "--set", f"run.duration={duration}", "--no-progress"]
    res = subprocess.run(cmd + (["--warm-cache", str(cache)] if cache else []), capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return json.loads((out / "run.json").read_text())


def _tables(d: Path) -> dict[str, pd.DataFrame]:
    return {f.name: pd.read_parquet(f) for f in sorted(d.glob("*.parquet"))}


def test_runs_from_the_state_are_identical_and_start_from_the_unshared_traffic(tmp_path):
    cache = tmp_path / "warmups"
    m1, m2 = _run(tmp_path / "s1", cache), _run(tmp_path / "s2", cache)
    _run(tmp_path / "u", None)
    w1, w2 = m1["warm_state"], m2["warm_state"]
    assert w1["shared"] and w2["shared"] and w1["key"] == w2["key"]
    assert (w1["produced"], w2["produced"]) == (True, False)
    assert [p.name for p in cache.iterdir() if p.is_dir()] == [w1["key"]]
    s1, s2, u = _tables(tmp_path / "s1"), _tables(tmp_path / "s2"), _tables(tmp_path / "u")
    assert s1.keys() == s2.keys() == u.keys()
    for name in s1:  # the same state file, fresh processes: value-identical
        pd.testing.assert_frame_equal(s1[name], s2[name], check_exact=True, obj=name)
    # the warm-up as the unshared run simulated it: its insertions, its passages, its messages
    pd.testing.assert_frame_equal(s1["departures.parquet"], u["departures.parquet"], check_exact=True)
    before = {n: df[df["t"] < 0].reset_index(drop=True) for n, df in s1.items() if n in ("sections.parquet", "events.parquet")}
    for n, df in before.items():
        pd.testing.assert_frame_equal(df, u[n][u[n]["t"] < 0].reset_index(drop=True), check_exact=True, obj=n)
    assert len(before["sections.parquet"]) > 0
    # one step after the state: the same vehicles, as far apart as one step of different
    # decisions allows (same speed at t0: |ds| <= (accel + emergencyDecel) dt^2; lateral
    # speeds from zero against one in progress: |dd| <= 2 maxSpeedLat dt) ...
    bg_s, bg_u = s1["background.parquet"], u["background.parquet"]
    t1 = bg_u["t"].min()
    a, b = bg_u[bg_u["t"] == t1].reset_index(drop=True), bg_s[bg_s["t"] == t1].reset_index(drop=True)
    assert a["vehicle_id"].tolist() == b["vehicle_id"].tolist() and len(a) > 5
    assert np.abs(a["s"] - b["s"]).max() <= (ACCEL + EMERGENCY_DECEL) * STEP ** 2 + 1e-9
    assert np.abs(a["d"] - b["d"]).max() <= 2 * MAX_SPEED_LAT * STEP + 1e-9
    # ... and not equal: the sublane lane-change model's memory is not in SUMO 1.28's state
    assert not a.equals(b)


def test_sweep_shares_one_warmup_per_seed_with_the_twins(tmp_path):
    sweep = tmp_path / "mini.toml"
    sweep.write_text(f'name = "mini"\nbase = "{SCENARIO}"\nseeds = [1, 2]\n[overrides]\n'
                     '"run.duration" = 2.0\n"traffic.warmup" = 10.0\n"comm.beacon_hz" = 10.0\n'
                     '[grid]\n"comm.delay_s" = [0.0, 0.1]\n')
    out = tmp_path / "out"
    res = subprocess.run([sys.executable, "-m", "formation_traci.cli", "sweep", str(sweep), "--out", str(out), "--shared-warmup",
                          "--baseline", "--no-progress"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    metas = {p.parent.parent.name + "/" + p.parent.name: json.loads(p.read_text())
             for p in sorted(out.glob("*/*/run.json"))}
    assert len(metas) == 8  # 4 cases, 4 twins
    keys = {}
    for name, m in metas.items():
        assert m["warm_state"]["shared"], name
        keys.setdefault(m["seed"], set()).add(m["warm_state"]["key"])
    assert all(len(k) == 1 for k in keys.values()) and keys[1] != keys[2]
    assert sum(m["warm_state"]["produced"] for m in metas.values()) == 2  # one per seed
    assert sorted(p.name for p in (out / "warmups").iterdir() if p.is_dir()) == sorted(k for s in keys.values() for k in s)
    twins = sorted((out / "twins").iterdir())
    by_seed = {}
    for t in twins:
        by_seed.setdefault(json.loads((t / "run.json").read_text())["seed"], []).append(_tables(t))
    for a, b in by_seed.values():  # a twin sees no formation: the delay does not matter
        for name in a:
            pd.testing.assert_frame_equal(a[name], b[name], check_exact=True, obj=name)
