"""Reliability IV: sweeps that resume, ids that never merge, a warm-up cache that deletes nothing,
no write through a link, bad input refused before anything runs. Each test reproduces one finding
of an adversarial probe (it failed on the code before the fix) with real SUMO and real processes;
docs/reliability.md maps them."""
import json
import signal
import threading
from pathlib import Path

import pandas as pd
import pytest

from run_helpers import cli, spawn, wait_for
from test_reliability_ii import free, road
from test_reliability_iii import tree

ROOT = Path(__file__).resolve().parents[1]


def _road_sweep(tmp_path, seeds="[1]", duration=1.0) -> Path:
    base = road(tmp_path, duration=duration, warmup=2.0)
    path = tmp_path / "sweep.toml"
    path.write_text(f'base = "{base}"\nseeds = {seeds}\n')
    return path


# -- 1. sweeps resume ------------------------------------------------------------------------------

def test_a_road_sweep_with_twins_runs_again_and_skips_what_is_done(tmp_path):
    sweep = _road_sweep(tmp_path)
    out = tmp_path / "sw"
    args = ("sweep", sweep, "--out", out, "--no-progress", "--workers", "1", "--baseline")
    code, text = cli(*args)
    assert code == 0, text
    assert (out / "means.csv").is_file() and (out / "effects.csv").is_file() and (out / "twins").is_dir()
    log = next((out / "logs").glob("*.log"))
    code, text = cli(*args)
    assert code == 0 and "1 done before" in text, text
    assert log.read_text().count("--- ") == 1  # the finished case (and its twin) not run again


def test_a_road_sweep_stopped_by_sigterm_resumes_to_the_same_summary(tmp_path):
    sweep = _road_sweep(tmp_path, "[1, 2, 3]", duration=3.0)
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    code, text = cli("sweep", sweep, "--out", whole, "--no-progress", "--workers", "1")
    assert code == 0, text
    proc = spawn("sweep", sweep, "--out", cut, "--no-progress", "--workers", "1")
    try:
        assert wait_for(lambda: len(list((cut / "cases").glob("*/case.json"))) >= 1, timeout=300)
        assert wait_for(lambda: len(list((cut / "logs").glob("*.log"))) >= 2, timeout=60)
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and "run the same command again" in err, err
    cut_rows = pd.read_parquet(cut / "summary.parquet")  # the cut case has no row or an unfinished one
    assert int((cut_rows["status"] == "completed").sum()) < 3, cut_rows
    code, text = cli("sweep", sweep, "--out", cut, "--no-progress", "--workers", "1")
    assert code == 0 and "done before" in text, text
    assert (cut / "summary.parquet").read_bytes() == (whole / "summary.parquet").read_bytes()
    assert list(pd.read_parquet(cut / "timings.parquet").columns) == ["case_id", "wall_s", "host", "pid"]


# -- 2. ids unique over the whole run ----------------------------------------------------------------
FLOWS = """
name = "ids"
[run]
duration = 2.0
seed = 1
[road]
net = "straight3"
lane = 1
start = 300.0
[leader]
speed = 30.0
[[members]]
id = "{top}"
slot = {{ along = 0.0, lanes = 0 }}
[[formations]]
id = "{fid}"
start = 600.0
leader = {{ speed = 30.0 }}
members = [{{ id = "{fmember}", slot = {{ along = 0.0, lanes = 0 }} }}]
[[formation_flows]]
id = "ff"
lane = 0
start = 900.0
period_s = 10.0
[formation_flows.formation]
leader = {{ speed = 28.0 }}
members = [{{ id = "m", slot = {{ along = 0.0, lanes = 0 }} }}]
[traffic]
warmup = 0.0
[[traffic.flows]]
id = "main"
veh_per_hour_per_lane = 600
"""


@pytest.mark.parametrize("ids, words", [
    (dict(fid="ff.0"), ["formations.0.id: 'ff.0'", "formation flow 'ff'"]),
    (dict(fmember="vc"), ["formations.0.members.0.id", "reserved for the virtual car"]),
    (dict(fmember="ff.3.m"), ["formations.0.members.0.id: 'ff.3.m'", "formation_flows.0.formation.members.0.id"]),
    (dict(top="main.2"), ["members.0.id: 'main.2'", "traffic flow 'main'"]),
    (dict(fmember="main.17"), ["formations.0.members.0.id: 'main.17'", "traffic.flows.0.id"]),
], ids=["formation-vs-flow", "vc-in-formations", "member-vs-flow-member", "member-vs-background",
        "formation-member-vs-background"])
def test_ids_that_clash_anywhere_in_the_run_are_bad_input_naming_both(tmp_path, ids, words):
    sc = tmp_path / "ids.toml"
    sc.write_text(FLOWS.format(**{"top": "a", "fid": "g", "fmember": "b", **ids}))
    before = tree(tmp_path)
    code, text = cli("run", sc, "--out", tmp_path / "out", "--no-progress")
    assert code == 2 and "Traceback" not in text, text
    assert all(w in text for w in words), text
    assert tree(tmp_path) == before


def test_distinct_ids_of_formations_flows_and_traffic_still_load(tmp_path):
    from formation_traci.scenario import load_scenario

    sc = tmp_path / "ids.toml"
    sc.write_text(FLOWS.format(top="main", fid="ff1", fmember="main.x"))  # no vehicle is named so
    assert [f.id for f in load_scenario(sc).formations] == ["ff1"]


# -- 3. the warm-up cache: deletes nothing, follows no link, checks its entries, says when it waits --

def _warm(tmp_path, out, cache, *extra):
    sc = tmp_path / "road.toml"
    if not sc.is_file():
        road(tmp_path, duration=1.0, warmup=2.0)
    return cli("run", sc, "--out", out, "--warm-cache", cache, "--no-progress", *extra)


def test_the_warm_up_cache_never_deletes_a_users_folder_named_like_an_entry(tmp_path):
    cache = tmp_path / "cache"
    code, text = _warm(tmp_path, tmp_path / "r1", cache)
    assert code == 0, text
    entry = Path(json.loads((tmp_path / "r1" / "run.json").read_text())["warm_state"]["entry"])
    for p in entry.iterdir():
        p.unlink()
    (entry / "notes.txt").write_text("mine")
    code, text = _warm(tmp_path, tmp_path / "r2", cache)
    assert code == 1 and "notes.txt" in text and "Traceback" not in text, text
    assert (entry / "notes.txt").read_text() == "mine" and sorted(p.name for p in entry.iterdir()) == ["notes.txt"]


@pytest.mark.parametrize("where, words", [
    ("", "empty"), ("link", "symbolic link"), ("out", "run directory"), ("out/cache", "run directory"),
    ("prev/cache", "run directory"), ("a,b", "comma"), ("afile", "is a file")])
def test_warm_up_cache_paths_that_cannot_be_used_exit_2_and_create_nothing(tmp_path, where, words):
    from test_reliability_ii import previous_run
    previous_run(tmp_path)
    (tmp_path / "target").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "target")
    (tmp_path / "afile").write_text("x")
    road(tmp_path, duration=1.0, warmup=2.0)
    work = tmp_path / "work"
    work.mkdir()
    before = tree(tmp_path)
    cache = "" if where == "" else tmp_path / where
    sc = tmp_path / "road.toml"
    code, text = cli("run", sc, "--out", tmp_path / "out", "--warm-cache", cache, "--no-progress", cwd=work)
    assert code == 2 and words in text and "Traceback" not in text, text
    assert tree(tmp_path) == before


def test_a_damaged_or_edited_warm_up_entry_is_made_again_with_a_warning(tmp_path):
    cache = tmp_path / "cache"
    code, text = _warm(tmp_path, tmp_path / "r0", cache)
    assert code == 0, text
    meta = json.loads((tmp_path / "r0" / "run.json").read_text())
    entry = Path(meta["warm_state"]["entry"])
    inserted = meta["traffic"]["flows"]["main"]["inserted"]

    def edit_departed():
        doc = json.loads((entry / "warm.json").read_text())
        doc["departed"] = {k: 99999 for k in doc["departed"]}
        (entry / "warm.json").write_text(json.dumps(doc))

    def truncate_state():
        data = (entry / "state.xml.gz").read_bytes()
        (entry / "state.xml.gz").write_bytes(data[: len(data) // 2])

    def break_json():
        (entry / "warm.json").write_text("{not json")

    for i, damage in enumerate((edit_departed, truncate_state, break_json), start=1):
        damage()
        code, text = _warm(tmp_path, tmp_path / f"r{i}", cache)
        assert code == 0 and "is damaged" in text and "made again" in text and "Traceback" not in text, text
        again = json.loads((tmp_path / f"r{i}" / "run.json").read_text())
        assert again["warm_state"]["produced"] is True
        assert again["traffic"]["flows"]["main"]["inserted"] == inserted  # not 99,999
        assert "99999" not in (entry / "warm.json").read_text()


def test_a_run_waiting_for_the_warm_up_lock_says_so(tmp_path):
    import fcntl
    import os
    cache = tmp_path / "cache"
    code, text = _warm(tmp_path, tmp_path / "r0", cache)
    assert code == 0, text
    key = json.loads((tmp_path / "r0" / "run.json").read_text())["warm_state"]["key"]
    fd = os.open(cache / f"{key}.lock", os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)
    proc = spawn("run", tmp_path / "road.toml", "--out", tmp_path / "r1", "--warm-cache", cache, "--no-progress")
    lines = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True)
    reader.start()
    try:
        said = wait_for(lambda: any("waiting for" in ln for ln in lines), timeout=120)
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
        proc.wait(timeout=120)
        reader.join(timeout=10)
    assert said and any(key in ln for ln in lines if "waiting for" in ln), lines
    assert proc.returncode == 0, lines


# -- 4. analyze-sweep writes only into its own output ------------------------------------------------

@pytest.fixture(scope="module")
def free_sweep(tmp_path_factory):
    d = tmp_path_factory.mktemp("fsw")
    path = d / "sweep.toml"
    path.write_text(f'base = "{free(d, 0.5)}"\nseeds = [1]\n')
    code, text = cli("sweep", path, "--out", d / "sw", "--no-progress", "--workers", "1")
    assert code == 0, text
    return d / "sw"


@pytest.mark.parametrize("case", ["out-is-a-run", "out-is-a-link", "out-is-another-sweep", "figures-link",
                                  "report-link", "stats-link"])
def test_analyze_sweep_never_writes_through_a_link_or_into_another_run(tmp_path, free_sweep, case):
    import shutil
    from test_reliability_ii import previous_run
    sw = tmp_path / "sw"
    shutil.copytree(free_sweep, sw)
    prev = previous_run(tmp_path)
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("mine")
    out = []
    if case == "out-is-a-run":
        out = ["--out", prev]
    elif case == "out-is-a-link":
        (tmp_path / "link").symlink_to(victim)
        out = ["--out", tmp_path / "link"]
    elif case == "out-is-another-sweep":
        shutil.copytree(free_sweep, tmp_path / "other")
        out = ["--out", tmp_path / "other"]
    elif case == "figures-link":
        (sw / "sweep_figures").symlink_to(victim)
    else:
        name = "sweep_report.html" if case == "report-link" else "sweep_stats.csv"
        (sw / name).symlink_to(victim / "keep.txt")
    before = tree(tmp_path)
    code, text = cli("analyze-sweep", sw, *out)
    assert code == 2 and "Traceback" not in text, text
    assert tree(tmp_path) == before and (victim / "keep.txt").read_text() == "mine"
    assert sorted(p.name for p in victim.iterdir()) == ["keep.txt"]


def test_analyze_sweep_writes_into_its_sweep_an_empty_directory_or_its_earlier_output(tmp_path, free_sweep):
    import shutil
    sw = tmp_path / "sw"
    shutil.copytree(free_sweep, sw)
    for args in ([], ["--out", tmp_path / "rep"], ["--out", tmp_path / "rep"]):
        code, text = cli("analyze-sweep", sw, *args)
        assert code == 0, text
    assert (sw / "sweep_report.html").is_file() and (tmp_path / "rep" / "sweep_report.html").is_file()


# -- grid and override paths are scenario fields ------------------------------------------------------

@pytest.mark.parametrize("table, path, value, near", [
    ("grid", "formation_flows.0.perentration", "[0.1, 0.2]", "formation_flows.0.penetration"),
    ("overrides", "run.durration", "3.0", "run.duration"),
    ("grid", "traffic.flows.0.veh_per_hour_per_lan", "[100, 200]", "traffic.flows.0.veh_per_hour_per_lane"),
])
def test_a_sweep_path_that_is_not_a_scenario_field_is_refused_before_any_case(tmp_path, table, path, value, near):
    base = tmp_path / "ids.toml"
    base.write_text(FLOWS.format(top="a", fid="g", fmember="b"))
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'base = "{base}"\nseeds = [1]\n[{table}]\n"{path}" = {value}\n')
    before = tree(tmp_path)
    code, text = cli("sweep", sweep, "--out", tmp_path / "out", "--no-progress", "--workers", "1")
    assert code == 2 and path in text and f"nearest field: {near}" in text and "Traceback" not in text, text
    assert tree(tmp_path) == before


# -- 5./6. checked before the run, nothing silently dropped -----------------------------------------

def _off_road(tmp_path, dy) -> Path:
    """ROAD with member m1 given a position dy [m] left of its slot."""
    from formation_traci.scenario import load_scenario
    from formation_traci.sumo.plan import prepare
    p = road(tmp_path, duration=1.0, name="slot.toml")
    x, y = prepare(load_scenario(p), p).pos0[0]
    text = p.read_text().replace("slot = { along = 0.0, lanes = 0 }",
                                 f"slot = {{ along = 0.0, lanes = 0 }}\nposition = [{x}, {y + dy}]", 1)
    out = tmp_path / f"off{dy:g}.toml"
    out.write_text(text)
    return out


FLOW_WINDOW = {"begin-after-end": "begin = 1.0\nend = 1.0\n", "begin-after-the-run": "begin = 5.0\n"}


@pytest.mark.parametrize("what", ["position-off-road", "set-road-on-free", "set-sumo-on-free", "sumo-table-on-free",
                                  "flow-begin-after-end", "flow-begin-after-the-run", "set-value-then-more",
                                  "duration-and-set", "seed-and-set"])
def test_bad_input_is_refused_before_anything_is_created(tmp_path, what):
    sc, extra = free(tmp_path, 1.0), []
    if what == "position-off-road":
        sc = _off_road(tmp_path, 40.0)
    elif what == "set-road-on-free":
        extra = ["--set", "road.net=straight3"]
    elif what == "set-sumo-on-free":
        extra = ["--set", "sumo.fcd=true"]
    elif what == "sumo-table-on-free":
        sc.write_text(sc.read_text() + "[sumo]\nfcd = true\n")
    elif what.startswith("flow-"):
        sc = tmp_path / "flow.toml"
        window = FLOW_WINDOW[what[len("flow-"):]]
        sc.write_text(FLOWS.format(top="a", fid="g", fmember="b").replace("period_s = 10.0\n", f"period_s = 10.0\n{window}"))
    elif what == "set-value-then-more":
        extra = ["--set", "run.duration=1.0\n[traffic]\nwarmup = 5.0"]
    elif what == "duration-and-set":
        extra = ["--duration", "3", "--set", "run.duration=4"]
    else:
        extra = ["--seed", "3", "--set", "run.seed=4"]
    before = tree(tmp_path)
    code, text = cli("run", sc, "--out", tmp_path / "out", "--no-progress", *extra)
    assert code == 2 and "Traceback" not in text, text
    assert tree(tmp_path) == before


def test_a_position_near_the_road_is_still_accepted(tmp_path):
    from formation_traci.scenario import load_scenario
    from formation_traci.sumo.plan import prepare
    p = _off_road(tmp_path, 0.5)
    assert prepare(load_scenario(p), p).pos0.shape == (2, 2)


@pytest.mark.parametrize("option", ["--baseline", "--shared-warmup"])
def test_sweep_road_options_on_free_space_are_refused_before_any_case(tmp_path, option):
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'base = "{free(tmp_path, 0.5)}"\nseeds = [1, 2]\n')
    before = tree(tmp_path)
    code, text = cli("sweep", sweep, "--out", tmp_path / "out", "--no-progress", option)
    assert code == 2 and option in text and "road" in text and "Traceback" not in text, text
    assert tree(tmp_path) == before


def test_run_warm_cache_on_free_space_is_refused(tmp_path):
    before = tree(tmp_path)
    code, text = cli("run", free(tmp_path, 0.5), "--out", tmp_path / "out", "--no-progress",
                     "--warm-cache", tmp_path / "cache")
    assert code == 2 and "--warm-cache" in text and "Traceback" not in text, text
    assert sorted(tree(tmp_path)) == sorted([*before, "free.toml"])


# -- 7. one-line reasons; the --baseline checks agree ---------------------------------------------------

def test_analyze_a_failed_road_run_against_its_twin_computes_what_is_there(tmp_path):
    from formation_traci.scenario import load_scenario
    from formation_traci.runner import run_scenario
    p = road(tmp_path, duration=2.0, warmup=2.0)
    sc = load_scenario(p)

    def fail_at_5(k, t, ad):
        if k == 5:
            raise RuntimeError("injected")

    assert run_scenario(sc, tmp_path / "fail", scenario_path=p, progress=False, step_hook=fail_at_5).status == "failed"
    assert run_scenario(sc, tmp_path / "twin", scenario_path=p, progress=False, baseline=True).status == "completed"
    code, text = cli("analyze", tmp_path / "fail", "--baseline", tmp_path / "twin", "--no-figures")
    assert code == 0 and "Error" not in text, text
    assert (tmp_path / "fail" / "metrics.json").is_file()


@pytest.mark.parametrize("baseline", ["missing", "empty", "a-file"])
def test_a_baseline_that_is_not_a_run_is_refused_alike(tmp_path, baseline):
    from test_reliability_ii import previous_run
    prev = previous_run(tmp_path)
    (tmp_path / "empty").mkdir()
    (tmp_path / "a-file").write_text("x")
    before = tree(tmp_path)
    code, text = cli("analyze", prev, "--baseline", tmp_path / baseline, "--no-figures")
    assert code == 2 and "Traceback" not in text and str(tmp_path / baseline) in text, text
    assert tree(tmp_path) == before


def test_sweep_set_of_a_road_field_on_free_space_is_refused_before_any_case(tmp_path):
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f'base = "{free(tmp_path, 0.5)}"\nseeds = [1]\n')
    before = tree(tmp_path)
    code, text = cli("sweep", sweep, "--out", tmp_path / "out", "--no-progress", "--set", "road.net=straight3")
    assert code == 2 and "--set road.net" in text and "Traceback" not in text, text
    assert tree(tmp_path) == before


def test_a_failed_run_gives_its_reason_in_one_line(tmp_path):
    from formation_traci.scenario import load_scenario
    from formation_traci.runner import run_scenario
    p = road(tmp_path, duration=1.0)

    def fail(k, t, ad):
        if k == 3:
            raise RuntimeError("first line\nTraceback (most recent call last):\n  second line")

    res = run_scenario(load_scenario(p), tmp_path / "out", scenario_path=p, progress=False, step_hook=fail)
    meta = json.loads((tmp_path / "out" / "run.json").read_text())
    assert res.status == "failed" and meta["reason"] == res.reason
    assert "\n" not in res.reason and "first line" in res.reason and "second line" in res.reason
    assert "second line" in (tmp_path / "out" / "error.txt").read_text()  # the whole story stays on disk
