"""The penetration question answered right: a twin for every case whatever its status (a
twin that fails named), the same-demand twin (every member a SUMO-driven vehicle of its type
where and when it enters), exactly zero effects where no formation enters."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pandas as pd
import pytest

from run_helpers import cli

ROOT = Path(__file__).resolve().parents[1]
HIGHWAY = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"
LUST = ROOT.parent / "shared" / "realnet" / "LuSTMotorway.net.xml"

TRUCK = f"""name = "truck-slowdown"
[run]
duration = 20.0
step = 0.05
seed = 1
[road]
net = "{LUST}"
route = {{ from = "-30668#1", to = "-30668#6" }}
lane = 1
start = 200.0
[leader]
speed = {{ t = [0.0, 5.0, 10.0], values = [28.0, 28.0, 22.0], interp = "smooth" }}
[[members]]
id = "car_c"
slot = {{ along = 0.0, lanes = 0 }}
[[members]]
id = "car_l"
slot = {{ along = 0.0, lanes = 1 }}
[[members]]
id = "truck"
preset = "small_truck"
speed_gains = "table_3_6"
slot = {{ along = -20.0, lanes = -1 }}
[traffic]
warmup = 10.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 300
"""
"""Cars abreast and a small truck 20 m behind one lane right, the leader slowing 28 -> 22 m/s
on LuST: with the virtual car not bounded by the truck's speed law (``bound_by_members =
false``) the truck overruns its slot into the cars (tests/test_incidents.py), a run that ends
``completed_with_incidents``; bounded, it ends completed."""


@pytest.mark.skipif(not LUST.is_file(), reason="needs ../shared/realnet beside the checkout")
def test_sweep_twins_a_case_that_ended_with_incidents(tmp_path):
    """`sweep --baseline`: the case that ends completed_with_incidents has its twin (the
    same-demand one) and its paired effects, in summary.parquet and effects.csv."""
    base = tmp_path / "truck.toml"
    base.write_text(TRUCK)
    sweep = tmp_path / "s.toml"
    sweep.write_text('base = "truck.toml"\nseeds = [1]\n[grid]\n"leader.bound_by_members" = [false]\n')
    out = tmp_path / "out"
    code, text = cli("sweep", sweep, "--out", out, "--no-progress", "--workers", "1", "--baseline")
    assert (out / "summary.parquet").is_file(), text
    r = pd.read_parquet(out / "summary.parquet").iloc[0]
    assert r.status == "completed_with_incidents", text
    assert r.twin_status in ("completed", "completed_with_incidents") and pd.isna(r.twin_reason)
    assert json.loads((out / "twins" / r.case_id / "run.json").read_text())["baseline_mode"] == "same"
    assert pd.notna(r.fx_delay_total_s) and pd.notna(r.fx_throughput_veh_h)
    tr = json.loads((out / "cases" / r.case_id / "metrics.json").read_text())["traffic"]["run"]
    assert r.fx_delay_total_s == pytest.approx(tr["twin_delay_total_s"])
    eff = pd.read_csv(out / "effects.csv").set_index("metric").loc["fx_delay_total_s"]
    assert eff.n_seeds == 1 and eff["mean"] == pytest.approx(r.fx_delay_total_s)


def test_sweep_names_the_twins_that_failed(tmp_path):
    """Twins that cannot run (here: each twin's directory already holds a file the tool did not
    write, which a twin never deletes) leave their cases' status alone, their paired effects NaN,
    and are named: summary.parquet ``twin_status`` / ``twin_reason``, the terminal's last line,
    effects.csv's note (over 0 of 2 seeds, naming each case) and the sweep report."""
    from formation_traci.sweep.expand import load_sweep

    base = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"
    sweep = tmp_path / "s.toml"
    sweep.write_text(f'base = "{os.path.relpath(base, tmp_path)}"\nseeds = [1, 2]\n'
                     '[overrides]\n"run.duration" = 1.0\n"traffic.warmup" = 2.0\n')
    out = tmp_path / "out"
    for case in load_sweep(sweep).cases:
        (out / "twins" / case.id).mkdir(parents=True)
        (out / "twins" / case.id / "my_notes.txt").write_text("not the tool's")
    code, text = cli("sweep", sweep, "--out", out, "--no-progress", "--workers", "2", "--baseline")
    df = pd.read_parquet(out / "summary.parquet")
    assert code == 0 and (df.status == "completed").all(), text
    assert (df.twin_status == "failed").all()
    assert df.twin_reason.str.contains("is not a previous run of formation-traci").all(), df.twin_reason.tolist()
    assert df.fx_delay_total_s.isna().all()
    assert json.loads((out / "sweep.json").read_text())["counts"]["twins_failed"] == 2
    last = text.strip().splitlines()[-1]
    assert last.startswith("TWINS FAILED: 2:") and all(c in last for c in df.case_id), text
    eff = pd.read_csv(out / "effects.csv")
    assert (eff.n_seeds == 0).all()
    assert eff.note.str.contains("over 0 of 2 seeds").all()
    assert all(eff.note.str.contains(c).all() for c in df.case_id)
    from analysis.report.sweep_report import analyze_sweep

    page = analyze_sweep(out).files["report_html"].read_text()
    assert "Twins that did not reach their end (2)" in page and all(c in page for c in df.case_id)
    # the same command again: the sweep's directory (its twins/, effects.csv, means.csv) is its
    # own, and the cases whose twin failed run again
    code, text = cli("sweep", sweep, "--out", out, "--no-progress", "--workers", "2", "--baseline")
    assert code == 0 and "2 run now, 0 done before" in text and "TWINS FAILED: 2" in text, text
    assert all((out / "twins" / c / "my_notes.txt").read_text() == "not the tool's" for c in df.case_id)


def _first_rows(df: pd.DataFrame, ids) -> pd.DataFrame:
    return df[df.vehicle_id.isin(ids)].sort_values("t").groupby("vehicle_id").head(1).set_index("vehicle_id")


def test_same_demand_twin_inserts_the_runs_vehicles(tmp_path):
    """The same-demand twin (`run --baseline`, i.e. `--baseline same`) inserts the run's
    background vehicles (the same ids at the same departure times) and one SUMO vehicle per
    member, of the member's vType, on the member's lane at the member's place at the step the
    member enters; from then on SUMO drives it (it is in background.parquet). `--baseline
    absent` has the background only."""
    opts = ["--no-progress", "--set", "run.duration=3.0", "--set", "traffic.warmup=30.0"]
    for name, extra in (("run", []), ("same", ["--baseline"]), ("absent", ["--baseline", "absent"])):
        code, text = cli("run", HIGHWAY, "--out", tmp_path / name, *opts, *extra)
        assert code == 0, text
    meta = {n: json.loads((tmp_path / n / "run.json").read_text()) for n in ("run", "same", "absent")}
    assert (meta["same"]["baseline"], meta["same"]["baseline_mode"]) == (True, "same")
    assert meta["absent"]["baseline_mode"] == "absent"
    ids = [m["id"] for m in meta["run"]["members"]]
    dep = {n: pd.read_parquet(tmp_path / n / "departures.parquet") for n in ("run", "same", "absent")}
    assert len(dep["run"]) > 0
    for n in ("same", "absent"):
        pd.testing.assert_frame_equal(dep["run"].sort_values("vehicle_id").reset_index(drop=True),
                                      dep[n].sort_values("vehicle_id").reset_index(drop=True))
    traj = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    bg_same = pd.read_parquet(tmp_path / "same" / "background.parquet")
    bg_absent = pd.read_parquet(tmp_path / "absent" / "background.parquet")
    assert not set(ids) & set(bg_absent.vehicle_id)
    first_twin = _first_rows(bg_same, ids)
    assert set(first_twin.index) == set(ids)
    first_run = _first_rows(traj[traj.lane_index.notna()], ids)  # the first step SUMO has them
    for vid in ids:
        a, b = first_run.loc[vid], first_twin.loc[vid]
        assert a.t == b.t and int(a.lane_index) == int(b.lane_index), vid
        assert b.s == pytest.approx(a.s, abs=0.05)  # the same place (front-bumper vs CoG read-back)
        assert b.type.split("@")[0] == "member_passenger_car"  # the members' vType (its own copy: vehicle class)
        body = next(m["body"] for m in meta["run"]["members"] if m["id"] == vid)
        assert (b.length, b.width) == pytest.approx((body["length"], body["width"]))  # the member's body
    # SUMO drives them afterwards: they keep moving at about the set speed
    last = bg_same[bg_same.vehicle_id.isin(ids)].sort_values("t").groupby("vehicle_id").tail(1)
    assert (last.t > first_twin.t.max() + 2.0).all() and (last.v > 20.0).all()


# --- scenarios of formations only ------------------------------------------------------------
FOUR = """name = "four"
[run]
duration = 3.0
step = 0.05
[road]
net = "straight3"
lane = 1
start = 300.0
[traffic]
warmup = 20.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 600
[[formations]]
id = "a"
leader = { speed = 30.0 }
lane = 0
members = [{ id = "a1", slot = { along = 0.0, lanes = 0 } }]
[[formations]]
id = "b"
leader = { speed = 30.0 }
lane = 2
members = [{ id = "b1", slot = { along = 0.0, lanes = 0 } }]
[[formations]]
id = "c"
leader = { speed = 30.0 }
start = 400.0
members = [{ id = "c1", slot = { along = 0.0, lanes = 0 } }, { id = "c2", slot = { along = -12.0, lanes = 0 } }]
[[formations]]
id = "d"
leader = { speed = 30.0 }
start = 200.0
depart = 1.0
members = [{ id = "d1", slot = { along = 0.0, lanes = 0 } }]
"""
"""Four [[formations]], no top-level members and no top-level [leader]."""


def test_four_formations_without_a_top_level_one(tmp_path):
    """Exactly the four formations run (no top-level formation, no member of it): each its
    own members in trajectories.parquet, d entering at 1 s; run.json's formations on_road at
    the end (not 'running')."""
    p = tmp_path / "four.toml"
    p.write_text(FOUR)
    code, text = cli("run", p, "--out", tmp_path / "r", "--no-progress")
    assert code == 0, text
    meta = json.loads((tmp_path / "r" / "run.json").read_text())
    assert [m["id"] for m in meta["members"]] == ["a1", "b1", "c1", "c2", "d1"]
    assert set(meta["formations"]) == {"a", "b", "c", "d"}
    assert {f["status"] for f in meta["formations"].values()} == {"on_road"}
    assert meta["formations"]["d"]["entered_s"] == pytest.approx(1.0)
    traj = pd.read_parquet(tmp_path / "r" / "trajectories.parquet")
    members = traj[~traj.vehicle_id.str.startswith("vc")]
    assert dict(members.groupby("vehicle_id").formation_id.first()) == {
        "a1": "a", "b1": "b", "c1": "c", "c2": "c", "d1": "d"}
    assert members[members.vehicle_id == "d1"].t.min() == pytest.approx(1.0)


@pytest.mark.parametrize("text, field", [
    ('name = "x"\n[run]\nduration = 1.0\n[leader]\nspeed = 10.0\n', "members"),
    (FOUR + '[[maneuvers]]\nkind = "lane_change"\nlanes = 1\nat = { t = 1.0 }\n', "maneuvers"),
])
def test_without_any_formation_or_with_top_level_parts_is_refused(tmp_path, text, field):
    """No members and no [[formations]] / [[formation_flows]]: exit 2 naming ``members``;
    top-level maneuvers without top-level members: exit 2 naming ``maneuvers``."""
    p = tmp_path / "bad.toml"
    p.write_text(text)
    code, out = cli("run", p, "--out", tmp_path / "r", "--no-progress")
    assert code == 2 and field in out and str(p) in out and "Traceback" not in out, out
    assert not (tmp_path / "r").exists()


FLOW = """name = "flow-alone"
[run]
duration = {duration}
step = 0.05
seed = 1
[road]
net = "straight3"
lane = 1
start = 300.0
[[formation_flows]]
id = "pen"
lane = [0, 1, 2]
penetration = {p}
of_flow = "main"
[formation_flows.formation]
leader = {{ speed = 30.0, time_gap = 1.2 }}
members = [{{ id = "m1", slot = {{ along = 0.0, lanes = 0 }} }},
           {{ id = "m2", slot = {{ along = -12.0, lanes = 0 }} }}]
[traffic]
warmup = 30.0
[traffic.sections]
upstream = 100.0
downstream = 100.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 900
"""
"""A formation flow alone (no top-level formation, no [leader]): two-car columns as the share
``p`` of traffic flow ``main``."""


def test_a_formation_flow_alone_runs_and_inserts(tmp_path):
    """A scenario of one [[formation_flows]] only: its formations enter (the run's only
    members, the flow's) and run.json says so."""
    p = tmp_path / "flow.toml"
    p.write_text(FLOW.format(duration=12.0, p=0.3))
    code, text = cli("run", p, "--out", tmp_path / "r", "--no-progress")
    assert code == 0, text
    meta = json.loads((tmp_path / "r" / "run.json").read_text())
    assert meta["formation_flows"]["pen"]["inserted"] >= 1
    assert all(m["id"].startswith("pen.") for m in meta["members"])
    traj = pd.read_parquet(tmp_path / "r" / "trajectories.parquet")
    assert traj.vehicle_id.str.startswith("pen.").any()


def test_zero_penetration_run_and_its_twin_give_exactly_zero_effects(tmp_path):
    """At 0 % the flow inserts no formation: the case analyses (traffic alone) and against
    its same-demand twin every paired effect is exactly 0 (same vehicles, same seed)."""
    from formation_traci.sweep.case import run_case
    from formation_traci.sweep.expand import Case
    from formation_traci.sweep.row import EFFECT_KEYS

    p = tmp_path / "flow.toml"
    p.write_text(FLOW.format(duration=20.0, p=0.0))
    case = Case(index=0, id="c0-s1", seed=1, values={}, overrides={})
    row = run_case({"case": case.model_dump(mode="json"), "base": str(p), "case_dir": str(tmp_path / "case"),
                    "log_path": str(tmp_path / "log"), "twin_dir": str(tmp_path / "twin")})
    assert row["status"] == "completed" and row["twin_status"] == "completed", row
    assert row["throughput_veh_h"] is not None and row["throughput_veh_h"] > 0
    assert row["stretch_coverage"] is not None and row["stretch_coverage"] > 0
    for key in EFFECT_KEYS:
        assert row[key] == 0.0, key


def test_formation_flow_shortfall_is_an_event_a_warning_and_a_summary_column(tmp_path, capsys):
    """A flow asking for a formation every second on a busy road inserts far fewer: a
    ``formation_shortfall`` event naming the flow, a warning on stderr and in run.json
    ``warnings``, and the case's ``formation_shortfall`` = 1 - inserted / requested."""
    from formation_traci.sweep.case import run_case
    from formation_traci.sweep.expand import Case

    p = tmp_path / "flow.toml"
    p.write_text(FLOW.format(duration=10.0, p=0.0).replace("penetration = 0.0\nof_flow = \"main\"",
                                                           "period_s = 1.0"))
    case = Case(index=0, id="c0-s1", seed=1, values={}, overrides={})
    row = run_case({"case": case.model_dump(mode="json"), "base": str(p), "case_dir": str(tmp_path / "case"),
                    "log_path": str(tmp_path / "log")})
    err = capsys.readouterr().err
    meta = json.loads((tmp_path / "case" / "run.json").read_text())
    c = meta["formation_flows"]["pen"]
    assert c["requested"] == 10 and c["inserted"] < 0.95 * c["requested"], c
    msg = f"formation flow 'pen' inserted {c['inserted']} of {c['requested']} formations due"
    assert any(w.startswith(msg) for w in meta["warnings"]) and f"warning: {msg}" in err
    ev = pd.read_parquet(tmp_path / "case" / "events.parquet")
    short = ev[ev.kind == "formation_shortfall"]
    assert len(short) == 1 and short.iloc[0].vehicle_id == "pen"
    assert row["formation_shortfall"] == pytest.approx(1.0 - c["inserted"] / c["requested"])


# --- incidents that name --------------------------------------------------------------------
@pytest.mark.skipif(not LUST.is_file(), reason="needs ../shared/realnet beside the checkout")
def test_incidents_name_who_when_where_in_run_json_terminal_and_report(tmp_path):
    """The truck overrunning its slot into the cars (TRUCK, unbounded): run.json incidents
    keeps its counts and lists each collision (kind, t, formation, the member and the other
    party, edge, lane, s, the clearance), counted per formation; the terminal's last lines
    name them; the report's first screen has their table; the traffic table's member
    collisions are the verdict's."""
    p = tmp_path / "truck.toml"
    p.write_text(TRUCK.replace("[leader]\n", "[leader]\nbound_by_members = false\n"))
    out = tmp_path / "r"
    code, text = cli("run", p, "--out", out, "--no-progress")
    assert code == 0, text
    meta = json.loads((out / "run.json").read_text())
    inc = meta["incidents"]
    n = inc["member_collisions"]
    assert n >= 1 and inc["events_total"] == n == len(inc["events"])
    assert inc["by_formation"] == {"f0": {"member_collisions": n}}
    ev = pd.read_parquet(out / "events.parquet")
    hits = ev[ev.kind == "member_collision"].sort_values("t")
    traj = pd.read_parquet(out / "trajectories.parquet")
    edges = set(meta["sumo"]["route"])
    for e, h in zip(inc["events"], hits.itertuples()):
        assert set(e) == {"kind", "t", "formation_id", "vehicle_id", "other_id", "edge", "lane", "s", "value"}
        assert (e["kind"], e["vehicle_id"], e["other_id"]) == ("member_collision", h.vehicle_id, h.other_id)
        assert e["t"] == pytest.approx(h.t, abs=1e-6)
        assert e["formation_id"] == "f0" and e["edge"] in edges and e["lane"] in (0, 1, 2)
        assert f"{-e['value']:.2f} m" in h.detail and e["value"] < 0  # the overlap the event states
        row = traj[(traj.vehicle_id == e["vehicle_id"]) & (traj.t <= e["t"] + 1e-9)].iloc[-1]
        assert e["s"] == pytest.approx(row.s, abs=1.0)  # where the member was (sensed at the step)
        assert int(row.lane_index) == e["lane"]
    tail = text.strip().splitlines()
    at = next(i for i, line in enumerate(tail) if line.startswith("INCIDENTS:"))
    named = tail[at + 1:at + 1 + min(n, 3)]
    assert all(line.startswith("  t = ") for line in named) and all(e["vehicle_id"] in line and e["edge"] in line
                                           for e, line in zip(inc["events"], named))
    code, text = cli("analyze", out, "--no-figures")
    assert code == 0, text
    html = (out / "report.html").read_text()
    first = html[:html.index("<h2>Tables</h2>")]
    assert '<h2 class="bad">Incidents</h2>' in first
    assert all(e["other_id"] in first and e["edge"] in first for e in inc["events"])
    tr = json.loads((out / "metrics.json").read_text())["traffic"]["run"]
    assert tr["n_collisions_member"] == n


def test_incident_log_keeps_the_first_hundred_and_counts_per_formation():
    """The log keeps 100 incidents whole, counts all of them per formation and kind; the
    report's table shows 10 and says how many more."""
    from analysis.report.incidents_html import INCIDENT_ROWS, incidents_html
    from formation_traci.sim.incident_log import MAX_EVENTS, IncidentLog, describe

    log = IncidentLog({"a1": "a", "b1": "b", "vc:a": "a"})
    log.locate = lambda vid: ("E1", 2, 123.4) if vid != "vc:a" else (None, None, None)
    for k in range(130):
        log.add(0.1 * k, "emergency_brake", "vc:a" if k % 2 else "b1", "", 7.0)
    log.add(20.0, "member_collision", "a1", "car.7", -0.25)
    m = log.meta()
    assert m["events_total"] == 131 and len(m["events"]) == MAX_EVENTS == 100
    assert m["by_formation"] == {"a": {"emergency_brakes": 65, "member_collisions": 1},
                                 "b": {"emergency_brakes": 65}}
    assert m["events"][0] == {"kind": "emergency_brake", "t": 0.0, "formation_id": "b", "vehicle_id": "b1",
                              "other_id": None, "edge": "E1", "lane": 2, "s": 123.4, "value": 7.0}
    assert describe(m["events"][0]) == ("t = 0.00 s emergency_brake: b1 (formation b, edge E1, lane 2, "
                                        "s = 123.4 m), braking request 7.00 m/s^2")
    html = incidents_html({"incidents": {**m}}, lambda h, rows, left=0: f"<table>{len(rows)}</table>")
    assert f"<table>{INCIDENT_ROWS}</table>" in html and "and 121 more" in html


def test_a_run_no_formation_entered_analyses_traffic_alone(tmp_path):
    """`analyze` on a run whose formation flow inserted nothing (0 %): exit 0, metrics.json
    with the traffic's section measures and the formation metrics marked absent, a report
    that says so; with its twin (`--baseline`) the paired comparison, exactly 0."""
    p = tmp_path / "flow.toml"
    p.write_text(FLOW.format(duration=12.0, p=0.0))
    for name, extra in (("r", []), ("t", ["--baseline"])):
        code, text = cli("run", p, "--out", tmp_path / name, "--no-progress", *extra)
        assert code == 0, text
    code, text = cli("analyze", tmp_path / "r", "--baseline", tmp_path / "t")
    assert code == 0, text
    doc = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert doc["run"]["formations_entered"] == 0 and "absent" in doc["run"]["formation_metrics"]
    assert doc["members"] == [] and doc["traffic"]["run"]["throughput_veh_h"] > 0
    assert doc["traffic"]["run"]["twin_delay_total_s"] == 0.0 and doc["traffic"]["run"]["matched_share"] == 1.0
    page = (tmp_path / "r" / "report.html").read_text()
    assert "no formation entered the road" in page and "throughput_veh_h" in page
