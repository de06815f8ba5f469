"""Reliability III (issue 31): nothing written outside --out or through a symlink, a lock
--force cannot race, bad values refused before SUMO starts, honest records on a full disk,
damaged analysis inputs described. Each test reproduces one finding of the probe (it failed on
the code before the fix) with real SUMO and real processes; docs/reliability.md maps them."""
import contextlib
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.runner import run_scenario
from run_helpers import cli, meta_of, spawn, wait_for
from test_reliability_ii import free, previous_run, road, tmpfs

ROOT = Path(__file__).resolve().parents[1]
SUMO_NETS = ROOT / "sumo_nets"


def tree(d: Path) -> dict:
    """Every path under ``d`` (relative) -> its bytes (files) or None (directories, links)."""
    out = {}
    for p in sorted(d.rglob("*")):
        rel = str(p.relative_to(d))
        out[rel] = p.read_bytes() if p.is_file() and not p.is_symlink() else None
    return out


# -- 1. bad values refused before SUMO starts (exit 2 naming the field, nothing created) -----------
@pytest.mark.parametrize("flow, field", [
    ("veh_per_hour_per_lane = 1e308", "traffic.flows.0.veh_per_hour_per_lane"),
    ("veh_per_hour_per_lane = 1e9", "traffic.flows.0.veh_per_hour_per_lane"),
    ("veh_per_hour = 1e12", "traffic.flows.0.veh_per_hour"),
    ("veh_per_hour_per_lane = 800\nbegin = 50.0\nend = 10.0", "traffic.flows.0.end")],
    ids=["1e308", "1e9", "total", "end-before-begin"])
def test_flow_values_sumo_would_refuse_exit_2_before_anything_is_created(tmp_path, flow, field):
    sc = road(tmp_path)
    sc.write_text(sc.read_text().replace("veh_per_hour_per_lane = 800", flow))
    code, text = cli("run", sc, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and field in text and "Traceback" not in text, text
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("options", [
    '["--version"]', '[""]', '["my.sumocfg"]', '["--tripinfo-output", "a.xml", "--tripinfo-output", "b.xml"]',
    '["--no-warnings=/x"]', '["--verbose=/x"]', '["--time-to-teleport", "soon"]'],
    ids=["version", "empty", "positional", "twice", "managed-bool", "bad-bool", "bad-time"])
def test_sumo_options_sumo_refuses_at_start_are_bad_input(tmp_path, options):
    (tmp_path / "my.sumocfg").write_text("<configuration/>")
    code, text = cli("run", road(tmp_path, options=options), "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "sumo.options." in text and "Traceback" not in text, text
    assert "inserted 0 of" not in text and "Error:" not in text and "Quitting" not in text, text
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("option", ["--save-state.times", "--save-state.period"])
def test_sumo_save_state_never_writes_into_the_working_directory(tmp_path, option):
    work = tmp_path / "work"
    work.mkdir()
    code, text = cli("run", road(tmp_path, options=f'["{option}", "1"]'), "--out", tmp_path / "run",
                     "--no-progress", cwd=work)
    assert code == 2 and "sumo.options.0" in text, text
    assert list(work.iterdir()) == [] and not (tmp_path / "run").exists()


@pytest.mark.parametrize("content", [
    None, '<net version="1.20">\n  <edge id="a" from="x" to="y">\n    <lane id="a_0" index="0" ',
    '<?xml version="1.0"?>\n<!DOCTYPE net [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>\n'
    '<net version="1.20"><location netOffset="0,0"/>&b;</net>\n'], ids=["corrupt", "truncated", "entities"])
def test_a_corrupt_truncated_or_entity_laden_network_exits_2(tmp_path, content):
    if content is None:  # a real network with a byte cut out of a tag half-way
        text = (SUMO_NETS / "straight3.net.xml").read_text()
        content = text[: len(text) // 2] + "<<>" + text[len(text) // 2:]
    (tmp_path / "bad.net.xml").write_text(content)
    sc = road(tmp_path, net="bad.net.xml")
    sc.write_text(sc.read_text().replace('start = 300.0', 'route = ["a"]\nstart = 300.0'))
    code, text = cli("run", sc, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "road.net" in text and "Traceback" not in text, text
    assert not (tmp_path / "run").exists()


def test_deep_nesting_and_huge_files_of_unknown_keys_are_refused_at_once(tmp_path):
    deep = tmp_path / "deep.toml"
    deep.write_text(free(tmp_path).read_text() + "x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    code, text = cli("run", deep, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "nested" in text and "Traceback" not in text, text[-500:]
    huge = tmp_path / "huge.toml"
    huge.write_text(free(tmp_path).read_text() + "".join(f"k{i} = 1\n" for i in range(600_000)))
    t0 = time.monotonic()
    code, text = cli("run", huge, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "bytes" in text and len(text) < 2000 and time.monotonic() - t0 < 10, text[-500:]
    # below the size cap: the error list is capped, the count given
    many = tmp_path / "many.toml"
    many.write_text(free(tmp_path).read_text() + "".join(f"k{i} = 1\n" for i in range(3000)))
    code, text = cli("run", many, "--out", tmp_path / "run", "--no-progress")
    assert code == 2 and "3000 problems" in text and "and 2980 more" in text and text.count("unknown field") <= 40, text[-500:]
    assert not (tmp_path / "run").exists()


# -- 2. strict types: nothing coerced -------------------------------------------------------------
@pytest.mark.parametrize("field, value", [
    ("run.duration", '"5"'), ("run.seed", "true"), ("run.seed", "1.0"), ("leader.speed", '"20"'),
    ("road.lane", "true"), ("traffic.warmup", '"0"'),
    ("traffic.flows.0.veh_per_hour_per_lane", '"800"')], ids=lambda v: str(v))
def test_types_are_strict_for_every_field(tmp_path, field, value):
    import tomllib

    doc = tomllib.loads(road(tmp_path).read_text())
    *path, last = field.split(".")
    node = doc
    for k in path:
        node = node[int(k)] if k.isdigit() else node.setdefault(k, {})
    node[last] = tomllib.loads(f"v = {value}")["v"]
    from formation_traci.scenario.load import parse_scenario
    with pytest.raises(ScenarioError) as err:
        parse_scenario(doc, "s.toml")
    assert field in [f for f, _ in err.value.problems], err.value.problems
    ints = tomllib.loads(road(tmp_path).read_text().replace("duration = 1.0", "duration = 1"))
    assert parse_scenario(ints).run.duration == 1.0  # an integer is still a number of seconds


# -- 3. nothing written through a symbolic link or outside the run ---------------------------------
def _victim(tmp_path) -> Path:
    v = tmp_path / "victim.txt"
    v.write_bytes(b"a user's file\n")
    return v


@pytest.mark.parametrize("force", [False, True], ids=["fresh", "force"])
def test_a_symlinked_lock_file_is_never_followed(tmp_path, force):
    victim = _victim(tmp_path)
    out = previous_run(tmp_path) if force else tmp_path / "run"
    out.mkdir(exist_ok=True)
    (out / ".formation-traci.lock").unlink(missing_ok=True)
    (out / ".formation-traci.lock").symlink_to(victim)
    before = tree(tmp_path)
    code, text = cli("run", free(tmp_path, 0.5, "f.toml"), "--out", out, "--no-progress",
                     *(["--force"] if force else []))
    assert code == 2 and "symbolic link" in text and "Traceback" not in text, text
    assert victim.read_bytes() == b"a user's file\n"
    assert tree(tmp_path) == {**before, "f.toml": (tmp_path / "f.toml").read_bytes()}


@pytest.mark.parametrize("name", ["metrics.json", "report.html", "metrics.csv", "figures",
                                  ".formation-traci.lock"])
def test_analyze_never_writes_through_a_symlink_in_the_run(tmp_path, name):
    run = previous_run(tmp_path)
    victim = _victim(tmp_path)
    target = victim
    if name == "figures":
        target = tmp_path / "my_pictures"
        target.mkdir()
    (run / name).unlink(missing_ok=True)
    (run / name).symlink_to(target)
    before = tree(tmp_path)
    code, text = cli("analyze", run)
    assert code == 2 and "symbolic link" in text and "Traceback" not in text, text
    assert tree(tmp_path) == before and victim.read_bytes() == b"a user's file\n"
    assert not list(target.iterdir()) if target.is_dir() else True


def test_analyze_never_creates_anything_in_a_directory_that_is_not_a_run(tmp_path):
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "notes.txt").write_text("mine")
    code, text = cli("analyze", plain, "--no-figures")
    assert code == 2 and "not a run directory" in text and "Traceback" not in text, text
    assert sorted(p.name for p in plain.iterdir()) == ["notes.txt"]
    code, text = cli("analyze", tmp_path / "empty_dir_missing", "--no-figures")
    assert code == 2 and not (tmp_path / "empty_dir_missing").exists()


@pytest.mark.parametrize("where", ["sumo/my_notes.txt", "trajectories.parquet/README.txt",
                                   "figures/my_plot.svg", "trajectories.parquet/sub/x.parquet"])
def test_force_never_deletes_a_users_file_inside_the_tools_folders(tmp_path, where):
    prev = previous_run(tmp_path)
    victim = prev / where
    victim.parent.mkdir(parents=True, exist_ok=True)
    victim.write_text("mine")
    before = tree(prev)
    code, text = cli("run", free(tmp_path, 0.5, "g.toml"), "--out", prev, "--force", "--no-progress")
    assert code == 2 and "/".join(where.split("/")[:2]) in text and "Traceback" not in text, text
    assert tree(prev) == before


def test_force_still_replaces_a_road_run_with_its_named_sumo_outputs(tmp_path):
    out = tmp_path / "run"
    sc = road(tmp_path, options='["--summary-output", "summary.xml"]')
    code, text = cli("run", sc, "--out", out, "--no-progress")
    assert code == 0 and (out / "sumo" / "summary.xml").is_file(), text
    code, text = cli("analyze", out)
    assert code == 0, text
    code, text = cli("run", sc, "--out", out, "--force", "--no-progress")
    assert code == 0, text


def _sweep_file(tmp_path) -> Path:
    path = tmp_path / "sweep.toml"
    path.write_text(f'base = "{free(tmp_path, 0.5)}"\nseeds = [1]\n')
    return path


def test_sweep_out_is_checked_like_run_out(tmp_path):
    sweep = _sweep_file(tmp_path)
    prev = previous_run(tmp_path)
    thesis = tmp_path / "thesis"
    thesis.mkdir()
    (thesis / "thesis.tex").write_text("years of work")
    (tmp_path / "afile").write_text("x")
    for out in (prev, thesis, tmp_path / "afile", tmp_path / "afile" / "sub"):
        before = tree(tmp_path)
        code, text = cli("sweep", sweep, "--out", out, "--no-progress", "--workers", "1")
        assert code == 2 and "Traceback" not in text, (out, text)
        assert tree(tmp_path) == before, out
    # an earlier sweep is finished by a rerun; a user's file in it is refused
    code, text = cli("sweep", sweep, "--out", tmp_path / "sw", "--no-progress", "--workers", "1")
    assert code == 0, text
    code, text = cli("sweep", sweep, "--out", tmp_path / "sw", "--no-progress", "--workers", "1")
    assert code == 0 and "done before" in text, text
    (tmp_path / "sw" / "mine.txt").write_text("mine")
    code, text = cli("sweep", sweep, "--out", tmp_path / "sw", "--no-progress", "--workers", "1")
    assert code == 2 and "mine.txt" in text, text


@pytest.mark.parametrize("args", [("run", "{sc}", "--out", ""), ("compare", "{prev}", "--out", "{tmp}/cmp"),
                                  ("analyze", "{prev}", "--baseline", "{tmp}/nope", "--no-figures"),
                                  ("run", "{sc}", "--out", "{tmp}/" + "d" * 300)],
                         ids=["empty-out", "compare-one", "missing-baseline", "long-out"])
def test_small_command_line_mistakes_exit_2_and_create_nothing(tmp_path, args):
    prev = previous_run(tmp_path)
    sc = free(tmp_path, 0.5, "h.toml")
    work = tmp_path / "work"
    work.mkdir()
    before = tree(tmp_path)
    code, text = cli(*[a.format(sc=sc, prev=prev, tmp=tmp_path) for a in args], cwd=work)
    assert code == 2 and "Traceback" not in text, text
    assert tree(tmp_path) == before


# -- 4. full disk: honest records ------------------------------------------------------------------
def _many_members(tmp_path, n) -> Path:
    """``n`` members in free space, run as independent members: the (n, n) member-pair
    clearances (sim/incidents.py, ~90 % of the run's time at n = 500) are skipped; the tables,
    the run.json and what reaches the disk are those of the same members checked in pairs
    (free, parallel lanes 3.5 m and 10 m apart: no pair ever touches)."""
    from run_helpers import free_toml
    head = free_toml(400.0, name="many").split("[[members]]")[0]
    head = head.replace("[run]\n", "[run]\nindependent_members = true\n", 1)
    assert "independent_members = true" in head
    rows = "".join(f'[[members]]\nid = "m{i}"\noffset = [{-10.0 * (i // 4)}, {3.5 * (i % 4)}]\n'
                   f'position = [{-10.0 * (i // 4)}, {3.5 * (i % 4)}]\n' for i in range(n))
    p = tmp_path / "many.toml"
    p.write_text(head + rows)
    return p


def _t_on_disk(meta) -> float:
    return min(0.0 if v["complete_to_s"] is None else v["complete_to_s"] for v in meta["tables"].values())


@contextlib.contextmanager
def small_disk(tmp_path, size: str):
    """A tmpfs of ``size`` (e.g. "1m"), unmounted afterwards."""
    disk = tmpfs(tmp_path / "disk", f"size={size}")
    try:
        yield disk
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True)


def _run_to_full_disk(disk: Path, sc: Path) -> tuple[Path, dict]:
    """Run ``sc`` into ``disk``: it must fail as disk full with t_end the time every table has."""
    out = disk / "run"
    code, text = cli("run", sc, "--out", out, "--no-progress")
    assert code == 1 and "Traceback" not in text, text
    meta = meta_of(out)
    assert meta["status"] == "failed" and "disk full" in meta["reason"], meta.get("status")
    assert meta["t_end"] == pytest.approx(_t_on_disk(meta))
    assert not (out / ".reserve").exists() and not list(out.rglob(".*.tmp"))
    held = [t for t in _open_files() if t.startswith(str(disk))]
    assert not held, f"descriptors still open on the full disk (the space stays taken): {held}"
    return out, meta


def _open_files() -> list[str]:
    """What this process's file descriptors point at (the run ran in this process)."""
    out = []
    for fd in os.listdir("/proc/self/fd"):
        with contextlib.suppress(OSError):
            out.append(os.readlink(f"/proc/self/fd/{fd}"))
    return out


def test_a_full_disk_with_many_members_still_gives_a_final_run_json(tmp_path):
    """End to end (the reserve's size alone: the test below, which this one cannot replace: the
    failed part's space is freed too)."""
    with small_disk(tmp_path, "1m") as disk:  # the final run.json (~350 kB) is above 256 kB
        _run_to_full_disk(disk, _many_members(tmp_path, 500))


def test_a_disk_smaller_than_the_reserve_still_ends_with_the_final_run_json(tmp_path, monkeypatch):
    """500 members (a ~380 kB run.json, a ~1.5 MB reserve) on a 1 MB disk, parts every 10 s:
    the reserve was all or nothing (none here) and was taken before run.json, and a failed
    small part frees too little, so the final run.json could not be written: the run raised
    out of the CLI and run.json stayed 'running'."""
    import formation_traci.sim.recorder as recorder_module
    monkeypatch.setattr(recorder_module, "STEPS_PER_CHUNK", 200)
    with small_disk(tmp_path, "1m") as disk:
        _run_to_full_disk(disk, _many_members(tmp_path, 500))


def _fill(disk: Path) -> None:
    """Fill ``disk`` to the last byte (a file the test owns)."""
    with open(disk / "filler", "wb", buffering=0) as f:  # unbuffered: nothing left to flush
        for size in (1 << 16, 1 << 12, 1 << 8, 1):
            with contextlib.suppress(OSError):
                while True:
                    f.write(b"\1" * size)


def test_the_reserve_holds_the_final_run_json_of_many_members_when_nothing_else_is_free(tmp_path):
    """The reserve alone must take the final run.json: the end-to-end test above frees the
    failed part file too, so it cannot tell the old fixed 256 kB reserve (which this test fails
    on: a 500-member run.json is ~350 kB) from one sized after the first run.json."""
    from formation_traci.record.writer import json_text
    from formation_traci.run.scenario_run import RESERVE_BYTES, _reserve, _write_final, run_meta
    meta = run_meta(load_scenario(_many_members(tmp_path, 500)), "many.toml")
    assert len(json_text(meta)) > RESERVE_BYTES  # the case the fixed reserve could not hold
    with small_disk(tmp_path, "2m") as disk:
        out = disk / "run"
        out.mkdir()
        _reserve(out, len(json_text(meta)))
        _fill(disk)
        meta.update(status="failed", reason="disk full (no space left on device)", tables={
            f"table{i}": {"parts": 3, "rows": 1000, "complete_to_s": 12.5} for i in range(6)})
        _write_final(out / "run.json", meta)
        assert json.loads((out / "run.json").read_text()) == json.loads(json.dumps(meta, default=str))
        assert not (out / ".reserve").exists()


def test_without_any_space_the_final_run_json_replaces_the_first_in_place(tmp_path):
    """No reserve and not a byte free: the final run.json (without indentation) takes the
    first one's place instead of raising and leaving it 'running'."""
    from formation_traci.run.scenario_run import _write_final, atomic_write_json, run_meta
    meta = run_meta(load_scenario(_many_members(tmp_path, 200)), "many.toml")
    with small_disk(tmp_path, "1m") as disk:
        out = disk / "run"
        out.mkdir()
        atomic_write_json(out / "run.json", meta)
        _fill(disk)
        meta.update(status="failed", reason="disk full (no space left on device)", t_end=3.0)
        assert _write_final(out / "run.json", meta) is None
        assert json.loads((out / "run.json").read_text()) == json.loads(json.dumps(meta, default=str))


def test_t_end_is_the_minimum_over_the_tables_actually_on_disk(tmp_path):
    import pandas as pd
    with small_disk(tmp_path, "300k") as disk:
        out, meta = _run_to_full_disk(disk, free(tmp_path, 5.0))
        assert f"complete up to t = {meta['t_end']:.2f} s" in meta["reason"]
        for name, info in meta["tables"].items():
            if info["parts"]:
                assert len(pd.read_parquet(out / f"{name}.parquet")) == info["rows"]


def test_analyze_on_a_full_disk_names_the_file_and_leaves_no_empty_output(tmp_path):
    with small_disk(tmp_path, "400k") as disk:
        run = disk / "run"
        code, text = cli("run", free(tmp_path, 5.0), "--out", tmp_path / "src", "--no-progress")
        assert code == 0, text
        subprocess.run(["cp", "-r", str(tmp_path / "src"), str(run)], check=True)
        fd = os.open(disk / "fill", os.O_WRONLY | os.O_CREAT)
        try:  # the disk is full: not one more page fits
            while True:
                os.write(fd, b"\0" * 4096)
        except OSError:
            pass
        finally:
            os.close(fd)
        code, text = cli("analyze", run)
        assert code == 1 and "No space left" in text and str(run) in text and "Traceback" not in text, text
        for p in run.rglob("*"):
            assert not (p.is_file() and p.stat().st_size == 0 and p.name != ".formation-traci.lock"), p
        assert not list(run.rglob(".*.tmp"))


# -- 5. analysis of damaged inputs: describe the damage, compute the rest ---------------------------
@pytest.mark.parametrize("key, value", [("members", 5), ("members", [5, "x"]), ("mu", "x"),
                                        ("record_step", "0.05"), ("t_end", [1]), ("scenario", 3),
                                        ("status", 7)], ids=lambda v: str(v))
def test_run_json_of_wrong_types_is_described_and_the_rest_computed(tmp_path, key, value):
    run = previous_run(tmp_path)
    meta = meta_of(run)
    meta[key] = value
    (run / "run.json").write_text(json.dumps(meta))
    code, text = cli("analyze", run, "--no-figures")
    assert code == 0 and "Traceback" not in text, text
    doc = json.loads((run / "metrics.json").read_text())
    assert any(i["kind"] == "invalid_meta_value" and key in i["what"] for i in doc["issues"]), doc["issues"]
    assert doc["run"]["n_members_with_data"] == 1
    code, text = cli("compare", run, previous_run(tmp_path, "other"), "--out", tmp_path / "cmp")
    assert code == 0 and "Traceback" not in text, text


def test_infinite_values_in_the_trajectories_are_damage_not_a_crash(tmp_path):
    import pandas as pd
    run = previous_run(tmp_path)
    part = next((run / "trajectories.parquet").glob("part-*.parquet"))
    df = pd.read_parquet(part)
    df.loc[df.index[3:6], "x"] = float("inf")
    df.loc[df.index[7], "v"] = float("-inf")
    df.to_parquet(part, index=False)
    code, text = cli("analyze", run)
    assert code == 0 and "Traceback" not in text, text
    doc = json.loads((run / "metrics.json").read_text())
    kinds = {(i["kind"], i["what"]) for i in doc["issues"]}
    assert ("non_finite_values", "x") in kinds and ("non_finite_values", "v") in kinds
    assert doc["run"]["n_members_with_data"] == 1 and doc["damaged"]
    code, text = cli("compare", run, previous_run(tmp_path, "other"), "--out", tmp_path / "cmp")
    assert code == 0 and "Traceback" not in text, text


# -- 6. signals and messages -------------------------------------------------------------------------
def test_sighup_ends_a_run_as_interrupted_like_sigterm(tmp_path):
    out = tmp_path / "run"
    proc = spawn("run", free(tmp_path, 3000.0), "--out", out, "--no-progress")
    try:
        assert wait_for(lambda: meta_of(out).get("t_end", 0) > 0 or (out / "trajectories.parquet").is_dir())
    finally:
        proc.send_signal(signal.SIGHUP)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    meta = meta_of(out)
    assert meta["status"] == "interrupted" and "SIGHUP" in meta["reason"]


def test_sigterm_to_a_sweep_is_named_sigterm(tmp_path):
    path = tmp_path / "sweep.toml"
    path.write_text(f'base = "{free(tmp_path, 1.0)}"\nseeds = [1]\n[overrides]\n"run.duration" = 200000.0\n')
    out = tmp_path / "out"
    proc = spawn("sweep", path, "--out", out, "--workers", "1", "--no-progress")
    try:
        assert wait_for(lambda: any(meta_of(d).get("status") == "running" for d in (out / "cases").glob("*")))
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=90)
    assert proc.returncode == 130, err
    assert "SIGTERM received" in err and "SIGINT" not in err, err
    assert json.loads((out / "sweep.json").read_text())["reason"] == "SIGTERM received"


def test_a_damage_warning_is_one_line_without_a_source_line(tmp_path):
    run = previous_run(tmp_path)
    part = next((run / "trajectories.parquet").glob("part-*.parquet"))
    data = part.read_bytes()
    (run / "trajectories.parquet" / "part-00001.parquet").write_bytes(data[: len(data) // 2])
    proc = subprocess.run([*__import__("run_helpers").CLI, "analyze", str(run), "--no-figures"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = [x for x in proc.stderr.splitlines() if "part-00001" in x]
    assert lines and all(x.startswith("warning: ") for x in lines), proc.stderr
    assert "warnings.warn(" not in proc.stderr and "Warning:" not in proc.stderr, proc.stderr


def test_attach_to_a_closed_port_fails_fast_in_one_line(tmp_path):
    import socket
    with socket.socket() as so:
        so.bind(("127.0.0.1", 0))
        port = so.getsockname()[1]  # closed again: nothing listens there
    sc = road(tmp_path)
    sc.write_text(sc.read_text().split("[[traffic.flows]]")[0]
                  + f'[sumo]\nbackend = "traci"\nattach_port = {port}\n')
    t0 = time.monotonic()
    proc = subprocess.run([*__import__("run_helpers").CLI, "run", str(sc), "--out", str(tmp_path / "run"),
                           "--no-progress"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1 and "could not attach" in proc.stdout + proc.stderr, proc.stderr
    assert "Retrying" not in proc.stdout + proc.stderr and "Could not connect to TraCI" not in proc.stdout
    assert time.monotonic() - t0 < 45, "took a minute of retries"
    assert meta_of(tmp_path / "run")["status"] == "failed"


# -- 7. the lock holds from the moment the directory is claimed, against --force ------------------
def test_force_is_refused_from_the_claim_through_the_warm_up(tmp_path):
    out = tmp_path / "run"
    proc = spawn("run", road(tmp_path, duration=10.0, warmup=3000.0, vph=2400), "--out", out, "--no-progress")
    try:
        assert wait_for(lambda: (out / "run.json").exists(), every=0.01)  # claimed: compiling or starting
        started = meta_of(out).get("started")
        for moment in ("claimed", "warm-up"):
            if moment == "warm-up":
                assert wait_for(lambda: (out / "sumo" / "sumo.log").exists())
                time.sleep(1.0)
            code, text = cli("run", road(tmp_path, duration=2.0, name="b.toml"), "--out", out, "--force",
                             "--no-progress")
            assert code == 2 and f"pid {proc.pid}" in text, (moment, text)
            assert meta_of(out)["started"] == started and proc.poll() is None, moment
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=120)
    assert meta_of(out)["status"] == "interrupted" and meta_of(out)["started"] == started
