"""Parameter studies: expansion, the local and the Dask executor, failures, resume, reports.

Real processes, real SUMO (libsumo) and a real distributed.LocalCluster; cases are tiny
(free space 1.5 s; one SUMO scenario of 2 s after a 5 s warm-up, two seeds).
"""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.report.sweep_report import analyze_sweep
from formation_traci.scenario import load_scenario
from formation_traci.sweep import SweepError, expand_sweep, load_sweep, run_sweep
from formation_traci.sweep import launch
from formation_traci.sweep.row import WALL_COLUMNS

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "scenarios" / "thesis" / "case_2_3_1_straight.toml"
HIGHWAY = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"
STUDIES = ROOT / "scenarios" / "studies"


def sweep_file(directory: Path, name: str, base: Path, body: str) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    rel = os.path.relpath(base, directory)  # the documented form: relative to the sweep file
    path = directory / name
    path.write_text(f'base = "{rel}"\n{body}', encoding="utf-8")
    return path


FREE_BODY = """name = "tiny"
seeds = [1, 2]
[overrides]
"run.duration" = 1.5
[grid]
"controller.k" = [1.0, -1.0, 2.0]
"""
SUMO_BODY = """seeds = [1, 2]
[overrides]
"run.duration" = 2.0
"traffic.warmup" = 5.0
"""


def _no_wall(df: pd.DataFrame) -> pd.DataFrame:
    return df.drop(columns=list(WALL_COLUMNS))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweeps")
    return {"free": sweep_file(d, "free.toml", THESIS, FREE_BODY),
            "sumo": sweep_file(d, "sumo.toml", HIGHWAY, SUMO_BODY)}


@pytest.fixture(scope="module")
def local(files, tmp_path_factory):
    out = tmp_path_factory.mktemp("local")
    return {k: run_sweep(p, out / k, workers=2, progress=False) for k, p in files.items()}


@pytest.fixture(scope="module")
def dask(files, tmp_path_factory):
    from distributed import Client, LocalCluster

    out = tmp_path_factory.mktemp("dask")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        worker_pids = set(client.run(os.getpid).values())
        res = {k: run_sweep(p, out / k, scheduler=cluster.scheduler_address, progress=False)
               for k, p in files.items()}
    return res, worker_pids


# --- expansion ----------------------------------------------------------------------------

def test_expand_order_ids_random_samples_and_overrides(tmp_path):
    body = """seeds = [1, 2]
[overrides]
"run.duration" = 2.0
[grid]
"controller.k" = [0.5, 1.0]
"members.1.k_theta" = [2, 4]
[random]
n = 3
seed = 7
"controller.k_theta" = { uniform = [1.0, 9.0] }
"vehicle.model" = { choice = ["kinematic", "dynamic"] }
[labels]
"members.1.k_theta" = "kt1"
"""
    path = sweep_file(tmp_path, "s.toml", THESIS, body)
    cases = expand_sweep(path)
    assert len(cases) == 2 * 2 * 3 * 2
    assert [c.index for c in cases] == list(range(24))
    assert len({c.id for c in cases}) == 24
    c0, c1 = cases[0], cases[1]
    assert c0.id.startswith("c0000-k0.5-kt12-k_theta") and c0.id.endswith("-s1")
    assert c1.id.startswith("c0001-k0.5-kt12-") and c1.id.endswith("-s2")
    assert c0.values == {k: v for k, v in c1.values.items()}  # seeds innermost
    assert cases[6].values["members.1.k_theta"] == 4 and cases[12].values["controller.k"] == 1.0
    assert list(c0.overrides) == ["run.duration", "controller.k", "members.1.k_theta",
                                  "controller.k_theta", "vehicle.model", "run.seed"]
    assert c0.overrides["run.seed"] == 1 and c1.overrides["run.seed"] == 2
    kt = [c.values["controller.k_theta"] for c in cases]
    assert all(1.0 <= v < 9.0 for v in kt) and len(set(kt)) == 3
    assert {c.values["vehicle.model"] for c in cases} <= {"kinematic", "dynamic"}
    assert [c.model_dump() for c in expand_sweep(path)] == [c.model_dump() for c in cases]
    path2 = sweep_file(tmp_path, "s2.toml", THESIS, body.replace("seed = 7", "seed = 8"))
    assert [c.values["controller.k_theta"] for c in expand_sweep(path2)] != kt
    sc = load_scenario(THESIS, **cases[13].overrides)  # overrides reach the scenario
    assert sc.controller.k == cases[13].values["controller.k"]
    assert sc.members[1].k_theta == cases[13].values["members.1.k_theta"]
    assert sc.run.seed == cases[13].seed


@pytest.mark.parametrize("body, field, words", [
    ('seeds = [1]\nfoo = 1\n', "foo", "unknown field"),
    ('seeds = []\n', "seeds", "at least 1"),
    ('seeds = [1, 1]\n', "seeds", "unique"),
    ('seeds = [1]\n[grid]\n"controller.k" = []\n', 'grid."controller.k"', "at least 1"),
    ('seeds = [1]\n[grid]\n"run.seed" = [1, 2]\n', "(document)", "list the seeds"),
    ('seeds = [1]\n[overrides]\n"controller.k" = 2.0\n[grid]\n"controller.k" = [1.0]\n',
     "(document)", "both in [overrides] and swept"),
    ('seeds = [1]\n[grid]\n"controller..k" = [1.0]\n', "grid", "pattern"),
    ('seeds = [1]\n[random]\nn = 2\nseed = 1\n"controller.k" = { uniform = [2.0, 1.0] }\n',
     'random."controller.k"', "low < high"),
    ('seeds = [1]\n[random]\nn = 2\nseed = 1\n"controller.k" = { normal = [2.0, 1.0] }\n',
     'random."controller.k".normal', "unknown field"),
    ('seeds = [1]\n[grid]\n"members.5.k" = [1.0]\n', 'grid."members.5.k"', "not an index"),
    ('seeds = [1]\n[grid]\n"run.duration.x" = [1.0]\n', 'grid."run.duration.x"', "not a table"),
])
def test_bad_sweep_file_names_file_and_field(tmp_path, body, field, words):
    path = sweep_file(tmp_path, "bad.toml", THESIS, body)
    with pytest.raises(SweepError) as err:
        expand_sweep(path)
    msg = str(err.value)
    assert f"{path}: {field}" in msg and words in msg, msg


def test_missing_base_is_an_error(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('base = "nowhere.toml"\nseeds = [1]\n')
    with pytest.raises(SweepError, match=r"base: scenario file not found"):
        load_sweep(path)


def test_bundled_studies_expand_and_every_case_validates():
    for name, n_min in (("density.toml", 9), ("gains.toml", 12)):
        sw = load_sweep(STUDIES / name)
        assert len(sw.cases) >= n_min, name
        for case in sw.cases:
            sc = load_scenario(sw.base, **case.overrides)
            assert sc.run.seed == case.seed and sc.road is not None
            assert sc.run.duration <= 60.0 and sc.traffic.warmup <= 120.0  # minutes, not hours


# --- running ------------------------------------------------------------------------------

def test_failed_grid_point_fails_alone_with_its_message(local, files):
    df = local["free"].summary
    assert list(df["case_id"]) == [c.id for c in expand_sweep(files["free"])]
    bad = df[df["controller.k"] == -1.0]
    good = df[df["controller.k"] != -1.0]
    assert (bad["status"] == "failed").all() and len(bad) == 2
    for reason in bad["reason"]:
        assert "controller.k" in reason and "greater than 0" in reason and "-1.0" in reason
    assert (good["status"] == "completed").all() and len(good) == 4
    assert np.isfinite(good[["e_rms_m", "a_lat_peak_mps2", "jerk_lat_rms_mps3"]].to_numpy()).all()
    assert good["a_lat_peak_mps2"].nunique() == 2  # k changes the run
    assert local["free"].n_completed == 4 and local["free"].n_failed == 2
    out = local["free"].out_dir
    pd.testing.assert_frame_equal(pd.read_parquet(out / "summary.parquet"), _no_wall(df))  # wall: timings.parquet
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["swept"] == ["controller.k"] and len(meta["cases"]) == 6
    assert meta["counts"]["completed"] == 4 and meta["counts"]["failed"] == 2
    assert "distributed" in meta["versions"] and "controller.k" in meta["sweep_text"]
    for cid in good["case_id"]:
        assert json.loads((out / "cases" / cid / "run.json").read_text())["status"] == "completed"


def test_sumo_cases_run_and_every_case_has_its_own_process(local, dask):
    res, worker_pids = dask
    sumo = local["sumo"].summary
    assert (sumo["status"] == "completed").all(), sumo["reason"].tolist()
    assert (sumo["collisions"] == 0).all() and sumo["emergency_brakes"].notna().all()
    rows = pd.concat([r.summary for r in (*local.values(), *res.values())])
    pids = rows["pid"].dropna().astype(int).tolist()
    assert len(pids) == len(rows) == 16
    assert len(set(pids)) == len(pids)  # a fresh process per case, on both executors
    assert not set(pids) & (worker_pids | {os.getpid()})


def test_local_and_dask_give_identical_summaries(local, dask):
    res, _ = dask
    for kind in ("free", "sumo"):
        a, b = _no_wall(local[kind].summary), _no_wall(res[kind].summary)
        pd.testing.assert_frame_equal(a, b, check_exact=True)
        assert (res[kind].out_dir / "cases" / a["case_id"][0] / "run.json").is_file()
        # ... and every completed case's trajectory file is bit for bit the same on both executors
        for case in a.loc[a.status == "completed", "case_id"]:
            ta = pd.read_parquet(local[kind].out_dir / "cases" / case / "trajectories.parquet")
            tb = pd.read_parquet(res[kind].out_dir / "cases" / case / "trajectories.parquet")
            pd.testing.assert_frame_equal(ta, tb, check_exact=True)


def test_second_invocation_runs_only_what_is_missing(local, files, tmp_path):
    out = tmp_path / "again"
    shutil.copytree(local["free"].out_dir, out)
    gone = "c0004-k2.0-s1"
    shutil.rmtree(out / "cases" / gone)
    kept = [c for c in ("c0000-k1.0-s1", "c0001-k1.0-s2", "c0005-k2.0-s2")]
    stamp = {c: (out / "cases" / c / "run.json").stat().st_mtime_ns for c in kept}
    res = run_sweep(files["free"], out, workers=2, progress=False)
    assert (res.n_skipped, res.n_run) == (3, 3)
    for c in kept:
        assert (out / "cases" / c / "run.json").stat().st_mtime_ns == stamp[c]
        assert (out / "logs" / f"{c}.log").read_text().count("--- ") == 1
    for c in (gone, "c0002-k-1.0-s1", "c0003-k-1.0-s2"):
        assert (out / "logs" / f"{c}.log").read_text().count("--- ") == 2  # launched again
    pd.testing.assert_frame_equal(_no_wall(res.summary), _no_wall(local["free"].summary))


def test_interrupt_leaves_a_consistent_summary(tmp_path):
    path = sweep_file(tmp_path, "long.toml", THESIS,
                      'seeds = [1]\n[grid]\n"run.duration" = [1.0, 200000.0, 200001.0, 1.5]\n')
    out = tmp_path / "out"
    code = ("import sys\nfrom formation_traci.sweep import run_sweep\n"
            f"try:\n    run_sweep({str(path)!r}, {str(out)!r}, workers=2, progress=False)\n"
            "except KeyboardInterrupt:\n    sys.exit(130)\n")
    proc = subprocess.Popen([sys.executable, "-c", code])
    first = out / "cases" / "c0000-duration1.0-s1" / "case.json"
    deadline = time.time() + 60
    while time.time() < deadline and not (first.is_file() and (out / "logs" / "c0002-duration200001.0-s1.log").is_file()):
        time.sleep(0.1)
    time.sleep(2.5)  # c0002's process is past its imports and simulating
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=60) == 130
    df = pd.read_parquet(out / "summary.parquet")
    status = dict(zip(df["case_id"], df["status"]))
    assert status["c0000-duration1.0-s1"] == "completed"
    assert status["c0001-duration200000.0-s1"] == "interrupted"
    assert status["c0002-duration200001.0-s1"] == "interrupted"
    assert df.set_index("case_id").loc["c0001-duration200000.0-s1", "t_end_s"] < 200000.0
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["status"] == "interrupted" and meta["counts"]["pending"] == 4 - len(df)
    assert not (out / ".summary.parquet.tmp").exists()


def test_killed_and_timed_out_cases_are_recorded_and_the_rest_complete(tmp_path, monkeypatch):
    # 8 s: the 1 s free-space case completes in ~3 s (test_sweep_fork.py's timeout case
    # gives a 0.5 s case the same 8 s); the sleeping case is stopped at 8 s, not 15 s
    path = sweep_file(tmp_path, "s.toml", THESIS, 'seeds = [1]\ntimeout_s = 8.0\n[overrides]\n'
                      '"run.duration" = 1.0\n[grid]\n"controller.k" = [1.0, 2.0, 3.0]\n')
    real = launch.case_command

    def command(spec_json: str) -> list[str]:
        cid = json.loads(spec_json)["case"]["id"]
        if "k2.0" in cid:
            return [sys.executable, "-c", "import os, signal; print('about to die', flush=True); "
                                          "os.kill(os.getpid(), signal.SIGKILL)"]
        if "k3.0" in cid:
            return [sys.executable, "-c", "import time; time.sleep(60)"]
        return real(spec_json)

    monkeypatch.setattr(launch, "case_command", command)
    res = run_sweep(path, tmp_path / "out", workers=3, progress=False)
    st = res.summary.set_index("case_id")
    assert st.loc["c0000-k1.0-s1", "status"] == "completed"
    assert st.loc["c0001-k2.0-s1", "status"] == "failed"
    assert "killed by SIGKILL" in st.loc["c0001-k2.0-s1", "reason"]
    assert "about to die" in st.loc["c0001-k2.0-s1", "reason"]
    assert st.loc["c0002-k3.0-s1", "status"] == "failed"
    assert "timeout" in st.loc["c0002-k3.0-s1", "reason"]
    assert st.loc["c0002-k3.0-s1", "wall_s"] < 45  # stopped at 8 s, long before its 60 s sleep ends


# --- analysis -----------------------------------------------------------------------------

def test_analyze_sweep_plots_means_and_writes_one_html(local, tmp_path):
    rep = analyze_sweep(local["free"].out_dir, out=tmp_path)
    assert rep.metrics[:1] == ["e_rms_m"] and "collisions" not in rep.metrics  # no values: left out
    pngs = sorted(tmp_path.glob("sweep_figures/*.png"))
    assert [p.stem for p in pngs] == sorted(rep.metrics)
    page = (tmp_path / "sweep_report.html").read_text()
    assert page.count("data:image/png;base64,") == len(rep.metrics)
    assert "c0002-k-1.0-s1" in page and "greater than 0" in page
    df = local["free"].summary
    done = df[df["status"] == "completed"]
    want = done.groupby("controller.k")["a_lat_peak_mps2"].agg(["mean", "min", "max", "count"])
    got = rep.stats.set_index("controller.k")
    np.testing.assert_allclose(got["a_lat_peak_mps2_mean"], want["mean"])
    np.testing.assert_allclose(got["a_lat_peak_mps2_max"], want["max"])
    assert list(got["n_seeds"]) == list(want["count"]) == [2, 2]
    rep2 = analyze_sweep(local["free"].out_dir, metrics=["jerk_lat_rms_mps3"], out=tmp_path / "b",
                         spread="std")
    assert rep2.metrics == ["jerk_lat_rms_mps3"] and (tmp_path / "b" / "sweep_report.html").is_file()
    with pytest.raises(SweepError, match="not a numeric summary column"):
        analyze_sweep(local["free"].out_dir, metrics=["no_such_metric"], out=tmp_path / "c")


def test_importing_sweeps_does_not_load_matplotlib():
    code = ("import sys, formation_traci.sweep as s\n"
            "s.run_sweep, s.expand_sweep, s.run_case\n"
            "import analysis.report.sweep_report\n"
            "assert 'matplotlib' not in sys.modules, 'matplotlib imported'\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_public_functions_document_their_parameters():
    import importlib
    import inspect
    import re

    for mod_name in ("formation_traci.sweep.spec", "formation_traci.sweep.expand",
                     "formation_traci.sweep.row", "formation_traci.sweep.case",
                     "formation_traci.sweep.launch", "formation_traci.sweep.executors",
                     "formation_traci.sweep.run", "analysis.report.sweep_report",
                     "analysis.figures.sweep_figures"):
        mod = importlib.import_module(mod_name)
        for name, fn in inspect.getmembers(mod, inspect.isfunction):
            if name.startswith("_") or fn.__module__ != mod.__name__:
                continue
            doc = inspect.getdoc(fn) or ""
            params = list(inspect.signature(fn).parameters)
            if params:
                assert "Parameters\n----------" in doc, f"{mod_name}.{name}: no Parameters"
                section = re.split(r"\n(Returns|Raises)\n-+", doc.split("Parameters\n----------")[1])[0]
                documented = set(re.findall(r"^(\w+) :", section, flags=re.M))
                assert set(params) <= documented, f"{mod_name}.{name}: {set(params) - documented}"
            assert "Returns\n-------" in doc, f"{mod_name}.{name}: no Returns"
