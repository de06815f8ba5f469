"""Case processes forked from the preloaded server (formation_traci/sweep/forked.py, issue 33).

Real sweeps, real SUMO: a forked case gives the same files as a case started as a new
interpreter, runs in a process and session of its own, sees the sweep's environment at the
time it starts, and stops on the supervisor's signals like one started with Popen.
"""
import json
import os
from datetime import datetime
from pathlib import Path

import pandas as pd
import pytest
import test_sweep  # tests/ is importable (conftest.py): its sweep-file helper

from formation_traci.sweep import forked, launch, run_sweep
from formation_traci.sweep.row import WALL_COLUMNS

ROOT = Path(__file__).resolve().parents[1]
THESIS = ROOT / "scenarios" / "thesis" / "case_2_3_1_straight.toml"
HIGHWAY = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"


def sweep_file(directory: Path, base: Path, body: str) -> Path:
    return test_sweep.sweep_file(directory, "s.toml", base, body)


def _stop_server() -> None:
    import multiprocessing.forkserver as fs

    fs._forkserver._stop()  # multiprocessing's own hook for its tests
    forked._context = None


@pytest.fixture(autouse=True)
def forks(monkeypatch):
    """Each test forks from a server started in its own environment: one started by an earlier
    test would not have, for one, the PYTHONHASHSEED that a Dask cluster (test_sweep.py) sets
    in this process, and rightly refuses to fork then (forked.unusable_reason). Yields the
    list of the forked cases' pids (a case started as a new interpreter is not in it)."""
    _stop_server()
    monkeypatch.setattr(forked, "_failed", [])
    pids = []
    real = forked.ForkedCase

    class Counted(real):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            pids.append(self.pid)

    monkeypatch.setattr(forked, "ForkedCase", Counted)
    yield pids
    _stop_server()


SUMO_BODY = ('seeds = [1, 2]\n[overrides]\n"run.duration" = 2.0\n"traffic.warmup" = 5.0\n'
             '[grid]\n"leader.speed" = [25.0, 30.0]\n')


def test_forked_cases_equal_new_interpreter_cases_file_for_file(tmp_path, monkeypatch, forks):
    path = sweep_file(tmp_path, HIGHWAY, SUMO_BODY)
    assert forked.usable(), forked.unusable_reason()
    fork = run_sweep(path, tmp_path / "fork", workers=2, progress=False)
    monkeypatch.setenv(forked.ENV, "exec")
    assert not forked.usable()
    new = run_sweep(path, tmp_path / "exec", workers=2, progress=False)
    a, b = (r.summary.drop(columns=list(WALL_COLUMNS)) for r in (fork, new))
    assert (a["status"] == "completed").all(), a["reason"].tolist()
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    for case in a["case_id"]:
        for table in ("trajectories", "background", "events", "comfort"):
            ta = pd.read_parquet(fork.out_dir / "cases" / case / f"{table}.parquet")
            tb = pd.read_parquet(new.out_dir / "cases" / case / f"{table}.parquet")
            pd.testing.assert_frame_equal(ta, tb, check_exact=True)
    pids = fork.summary["pid"].astype(int).tolist()
    assert sorted(pids) == sorted(forks)  # every case of the first sweep forked, none of the second
    assert len(set(pids)) == len(pids) and os.getpid() not in pids  # one process per case


def test_a_forked_case_has_its_own_session_the_sweeps_environment_and_its_log(tmp_path, monkeypatch):
    path = sweep_file(tmp_path, THESIS, 'seeds = [1]\n[overrides]\n"run.duration" = 0.5\n'
                                        '[grid]\n"controller.k" = [1.0]\n')
    run_sweep(path, tmp_path / "first", workers=1, progress=False)  # the server is running now
    monkeypatch.setenv("FORMATION_TRACI_PROBE", "set after the server started")
    seen = tmp_path / "seen.json"
    probe = ("import json, os, sys\n"
             f"json.dump({{'env': os.environ.get('FORMATION_TRACI_PROBE'), 'cwd': os.getcwd(), "
             f"'pid': os.getpid(), 'pgid': os.getpgid(0), 'sid': os.getsid(0), 'ppid': os.getppid(), "
             f"'argv': sys.argv}}, "
             f"open({str(seen)!r}, 'w'))\nprint('probe out'); print('probe err', file=sys.stderr)\n")
    monkeypatch.chdir(tmp_path)
    proc = forked.ForkedCase.__new__(forked.ForkedCase)
    ctx = forked._server()
    log = tmp_path / "probe.log"
    proc._proc = ctx.Process(target=_probe_entry, args=(probe, str(log), dict(os.environ), os.getcwd()))
    proc._proc.start()
    proc.pid = proc._proc.pid
    assert proc.wait(60) == 0
    got = json.loads(seen.read_text())
    assert got["env"] == "set after the server started" and got["cwd"] == str(tmp_path)
    assert got["pid"] == got["pgid"] == got["sid"] == proc.pid  # its own session and group
    assert got["ppid"] != os.getpid()  # forked by the server, not by the sweep
    assert got["argv"][0].endswith(os.path.join("formation_traci", "sweep", "case.py"))  # as with -m
    # both streams in the log (stdout to a file is block-buffered, as with Popen: order not kept)
    assert sorted(log.read_text().splitlines()) == ["probe err", "probe out"]


def _probe_entry(code, log_path, env, cwd):
    """case_entry with the case replaced by ``code`` (same session, output and environment)."""
    import formation_traci.sweep.case as case

    def main(argv):
        exec(code, {})
        return 0
    case.main = main
    forked.case_entry("{}", log_path, env, cwd)


def test_a_variable_read_at_import_that_changed_starts_a_new_interpreter(monkeypatch):
    forked._server()
    assert forked.usable(), forked.unusable_reason()
    monkeypatch.setenv("NUMBA_OPT", "1" if os.environ.get("NUMBA_OPT") != "1" else "2")
    assert not forked.usable()  # the server imported numba with the old value


def test_a_forked_case_past_its_timeout_is_stopped_and_recorded(tmp_path, forks):
    # the dynamic model at 1 ms physics steps: the timed-out case simulates some 1,500 s in its
    # 8 s, not hours, so that its analysis after the SIGTERM (which grows with the simulated
    # time) ends well inside the grace on a busy machine
    path = sweep_file(tmp_path, THESIS, 'seeds = [1]\ntimeout_s = 8.0\n[overrides]\n'
                                        '"vehicle.model" = "dynamic"\n"run.physics_step" = 0.001\n'
                                        '[grid]\n"run.duration" = [0.5, 200000.0]\n')
    assert forked.usable(), forked.unusable_reason()
    res = run_sweep(path, tmp_path / "out", workers=2, progress=False)
    st = res.summary.set_index("case_id")
    assert st.loc["c0000-duration0.5-s1", "status"] == "completed"
    slow = st.loc["c0001-duration200000.0-s1"]
    assert slow["status"] == "failed" and "timeout" in slow["reason"]
    assert 8.0 <= slow["wall_s"] < 8.0 + launch.GRACE_S  # stopped and analysed before the kill
    # SIGTERM reached it: the run stopped stepping at once and recorded its stop
    run = json.loads((tmp_path / "out" / "cases" / slow.name / "run.json").read_text())
    assert run["status"] == "interrupted" and run["reason"] == "SIGTERM received"
    stepped_s = (datetime.fromisoformat(run["finished"]) - datetime.fromisoformat(run["started"])).total_seconds()
    assert stepped_s <= 8.0 + 3.0  # whole seconds: from the case's start to its stop
    assert 0.0 < slow["t_end_s"] < 200000.0  # the run stopped at a step and was recorded
    assert sorted(res.summary["pid"].astype(int)) == sorted(forks)  # both cases were forked


def test_a_server_that_cannot_start_a_case_leaves_the_cases_to_new_interpreters(tmp_path, monkeypatch):
    path = sweep_file(tmp_path, THESIS, 'seeds = [1]\n[overrides]\n"run.duration" = 0.5\n'
                                        '[grid]\n"controller.k" = [1.0, 2.0]\n')
    class Broken:
        def __init__(self, *args):
            raise EOFError("the server died")  # what multiprocessing raises then

    monkeypatch.setattr(forked, "ForkedCase", Broken)
    assert forked.usable(), forked.unusable_reason()
    res = run_sweep(path, tmp_path / "out", workers=1, progress=False)
    assert (res.summary["status"] == "completed").all(), res.summary["reason"].tolist()
    assert not forked.usable() and forked._failed == ["EOFError: the server died"]


def _quick(code: int) -> None:
    """A forked process that ends at once with exit code ``code``."""
    raise SystemExit(code)


def test_an_exit_code_is_read_once_while_another_case_starts(monkeypatch):
    """The forkserver sends a child's exit status once, over a pipe. multiprocessing's
    Process.start polls every other child: a thread reading a case's status while another
    thread starts the next case must not have both read it, which left one at the pipe's end
    and made multiprocessing report 255 for a case that had ended with 0. The read is slowed
    down to widen the window the race needs."""
    import threading
    import time
    from multiprocessing import forkserver as fs
    from multiprocessing.connection import wait

    first = forked.ForkedCase("", "", target=_quick, args=(0,))
    wait([first._proc.sentinel], 30)  # it has ended: its status is in the pipe
    real = fs.read_signed
    monkeypatch.setattr(fs, "read_signed", lambda fd: time.sleep(0.3) or real(fd))
    got = {}
    reader = threading.Thread(target=lambda: got.setdefault("poll", first.poll()))
    reader.start()
    time.sleep(0.05)  # the reader is inside its read
    second = forked.ForkedCase("", "", target=_quick, args=(3,))  # start() polls `first` too
    reader.join()
    monkeypatch.setattr(fs, "read_signed", real)
    assert got["poll"] == 0
    assert first.poll() == 0
    assert second.wait(timeout=30) == 3


def test_a_case_killed_in_its_analysis_keeps_what_its_run_recorded(tmp_path, forks, monkeypatch):
    """The kinematic free-space case simulates hours in its 8 s; after the SIGTERM it stops
    at once and records its run, then its analysis (some 10 s) outlasts a 2 s grace and the
    case is killed. Its summary row keeps the run's end from run.json (before: t_end_s NaN)
    and its reason says the run is recorded and the analysis did not finish."""
    monkeypatch.setattr(launch, "GRACE_S", 2.0)
    path = sweep_file(tmp_path, THESIS, 'seeds = [1]\ntimeout_s = 8.0\n[grid]\n'
                                        '"run.duration" = [200000.0]\n')
    res = run_sweep(path, tmp_path / "out", workers=1, progress=False)
    row = res.summary.iloc[0]
    run = json.loads((tmp_path / "out" / "cases" / row["case_id"] / "run.json").read_text())
    assert run["status"] == "interrupted" and run["t_end"] > 600.0  # stopped and recorded
    assert not (tmp_path / "out" / "cases" / row["case_id"] / "metrics.json").exists()  # killed
    assert row["status"] == "failed" and "SIGKILL" in row["reason"] and "timeout" in row["reason"]
    assert row["t_end_s"] == run["t_end"]
    assert "is recorded (run.json); its analysis did not finish" in row["reason"]
