"""Loading damaged and partial run directories."""
from __future__ import annotations

import json
import os

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from analysis.load.run_data import DamagedPartWarning, NoTrajectoryData, load_run
from analysis_synth import OFFSETS, exp_error, make_run, trajectories, write_run


def kinds(data):
    return {i.kind for i in data.issues}


def truncate(path, keep=0.5):
    b = path.read_bytes()
    path.write_bytes(b[: int(len(b) * keep)])


def test_complete_run_loads_cleanly(tmp_path):
    d = load_run(make_run(tmp_path / "r"))
    assert [i for i in d.issues if i.severity != "info"] == []
    assert {i.what for i in d.issues} == {"background.parquet", "events.parquet", "ssm.parquet",
                                          "comfort.parquet"}
    assert d.dt == pytest.approx(0.01)
    assert [m.id for m in d.members] == list(OFFSETS)
    assert d.members[1].offset == (-12.0, 0.0) and d.members[1].frame == "vehicle"
    assert len(d.trajectories) == 5 * 2001 and not d.missing_columns


def test_truncated_part_is_skipped_with_a_warning_and_a_gap(tmp_path):
    run = make_run(tmp_path / "r", n_parts=4)
    truncate(run / "trajectories.parquet" / "part-00001.parquet")
    with pytest.warns(DamagedPartWarning, match="part-00001.parquet"):
        d = load_run(run)
    corrupt = [i for i in d.issues if i.kind == "corrupt_part"]
    assert len(corrupt) == 1 and corrupt[0].what.endswith("part-00001.parquet")
    gap = [i for i in d.issues if i.kind == "time_gap"]
    assert len(gap) == 1 and "5-10.01 s" in gap[0].detail
    t = np.unique(d.trajectories["t"])
    assert t[0] == 0.0 and t[-1] == 20.0 and t.size == 2001 - 500


def test_truncated_last_part_is_a_missing_tail(tmp_path):
    run = make_run(tmp_path / "r", n_parts=4)
    truncate(run / "trajectories.parquet" / "part-00003.parquet", keep=0.3)
    with pytest.warns(DamagedPartWarning):
        d = load_run(run)
    tail = [i for i in d.issues if i.kind == "truncated_tail"]
    assert len(tail) == 1 and "t_end is 20 s" in tail[0].detail


def test_missing_run_json_infers_members_and_step(tmp_path):
    run = make_run(tmp_path / "r", error=exp_error({"m1": 1.0}))
    os.remove(run / "run.json")
    d = load_run(run)
    assert "missing_file" in kinds(d) and "members_inferred" in kinds(d)
    offs = {m.id: m.offset for m in d.members}
    for mid, off in OFFSETS.items():
        assert offs[mid] == pytest.approx(off, abs=1e-9)
    assert all(m.frame == "inferred" for m in d.members)
    assert d.dt == pytest.approx(0.01) and d.meta == {}


def test_invalid_run_json_and_missing_keys(tmp_path):
    run = make_run(tmp_path / "a")
    (run / "run.json").write_text("{not json")
    assert "invalid_file" in kinds(load_run(run))
    run = make_run(tmp_path / "b", meta={"status": "interrupted", "reason": "SIGINT"})
    meta = json.loads((run / "run.json").read_text())
    del meta["mu"], meta["record_step"]
    (run / "run.json").write_text(json.dumps(meta))
    d = load_run(run)
    missing = {i.what for i in d.issues if i.kind == "missing_meta_key"}
    assert missing == {"run.json:mu", "run.json:record_step"}
    status = [i for i in d.issues if i.kind == "run_status"]
    assert status and "interrupted" in status[0].detail and "SIGINT" in status[0].detail


def test_missing_column_is_listed_and_filled_with_nan(tmp_path):
    df = trajectories().drop(columns=["slip_rear", "friction_usage"])
    d = load_run(write_run(tmp_path / "r", df))
    assert d.missing_columns == {"slip_rear", "friction_usage"}
    assert {i.what for i in d.issues if i.kind == "missing_column"} == {"slip_rear",
                                                                         "friction_usage"}
    assert d.trajectories["slip_rear"].isna().all()


def test_no_trajectory_data_raises_a_clear_error(tmp_path):
    with pytest.raises(NoTrajectoryData, match="not a directory"):
        load_run(tmp_path / "nope")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(NoTrajectoryData, match="trajectories.parquet does not exist"):
        load_run(empty)
    run = make_run(tmp_path / "r", n_parts=2)
    for p in (run / "trajectories.parquet").iterdir():
        truncate(p, 0.2)
    with pytest.warns(DamagedPartWarning), pytest.raises(NoTrajectoryData, match="part-0000"):
        load_run(run)
    run = tmp_path / "no_t"
    (run / "trajectories.parquet").mkdir(parents=True)
    pq.write_table(pa.Table.from_pandas(trajectories(t_end=1.0).drop(columns=["t"])),
                   run / "trajectories.parquet" / "part-00000.parquet")
    with pytest.raises(NoTrajectoryData, match="'t'"):
        load_run(run)


def test_single_file_dataset_hidden_files_and_optional_tables(tmp_path):
    run = write_run(tmp_path / "one", trajectories(t_end=2.0), single_file=True)
    assert len(load_run(run).trajectories) == 5 * 201
    run = make_run(tmp_path / "many", t_end=2.0)
    (run / "trajectories.parquet" / "_SUCCESS").write_text("")
    (run / "trajectories.parquet" / ".part-00009.parquet.tmp").write_text("partial")
    ev = pa.table({"t": [1.0], "kind": ["lane_change"], "vehicle_id": ["m1"],
                   "other_id": [None], "detail": ["x"]})
    (run / "events.parquet").mkdir()
    pq.write_table(ev, run / "events.parquet" / "part-00000.parquet")
    d = load_run(run)
    assert not [i for i in d.issues if i.severity == "error"]
    assert len(d.tables["events"]) == 1 and d.tables["background"] is None


def test_duplicate_rows_are_dropped(tmp_path):
    df = trajectories(t_end=2.0)
    df = pd.concat([df, df.iloc[:10]], ignore_index=True)
    d = load_run(write_run(tmp_path / "r", df, n_parts=1))
    assert "duplicate_rows" in kinds(d) and len(d.trajectories) == 5 * 201


def test_part_files_with_different_columns_and_null_ids(tmp_path):
    df = trajectories(t_end=1.0)
    run = write_run(tmp_path / "r", df, n_parts=1)
    extra = df.iloc[:5].assign(t=2.0, vehicle_id=[None, "m1", "m2", "m3", "m4"])
    extra = extra.drop(columns=["beta"])
    pq.write_table(pa.Table.from_pandas(extra, preserve_index=False),
                   run / "trajectories.parquet" / "part-00001.parquet")
    d = load_run(run)
    assert "schema_mismatch" in kinds(d) and "invalid_rows" in kinds(d)
    assert set(d.trajectories["vehicle_id"]) == {"vc", "m1", "m2", "m3", "m4"}
    assert d.trajectories.loc[d.trajectories["t"] == 2.0, "beta"].isna().all()


def test_unused_contract_columns_are_info_and_optional_tables_checked(tmp_path):
    df = trajectories(t_end=1.0).drop(columns=["steer", "beta"])
    run = write_run(tmp_path / "r", df)
    ev = pa.table({"t": [0.5], "kind": ["lane_change"], "vehicle_id": ["m1"]})
    (run / "events.parquet").mkdir()
    pq.write_table(ev, run / "events.parquet" / "part-00000.parquet")
    d = load_run(run)
    cols = {i.what: i.severity for i in d.issues if i.kind == "missing_column"}
    assert cols["steer"] == "info" and cols["beta"] == "info"
    assert not [i for i in d.issues if i.severity == "error"]
    ev_issue = [i for i in d.issues if i.what == "events.parquet" and i.kind == "missing_column"]
    assert ev_issue and "other_id" in ev_issue[0].detail


def test_lost_first_part_is_a_missing_head(tmp_path):
    run = make_run(tmp_path / "r", n_parts=4)
    truncate(run / "trajectories.parquet" / "part-00000.parquet")
    with pytest.warns(DamagedPartWarning):
        d = load_run(run)
    head = [i for i in d.issues if i.kind == "missing_head"]
    assert len(head) == 1 and "start at 5.01 s" in head[0].detail
