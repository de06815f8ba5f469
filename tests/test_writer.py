"""The chunked Parquet writer: what goes in comes out, parts are written in the background
but never reported before they are on disk, and a failed write is not lost."""
import numpy as np
import pandas as pd
import pytest

from run_contract.columns import Column
from formation_traci.record.writer import ChunkedTable

COLS = (Column("t", "float64", "s", ""), Column("id", "string", "-", ""),
        Column("a", "float64", "m", ""), Column("b", "float64", "m", ""),
        Column("k", "int32", "-", ""), Column("c", "float64", "m", ""))


def _read(path):
    return pd.read_parquet(path).reset_index(drop=True)


def test_rows_blocks_and_dict_appends_give_the_same_table(tmp_path):
    """The same 25 rows through append (dicts, scalars broadcast) and through rows/block/commit;
    7-row buffers, so parts split inside the blocks of append and early for rows()."""
    rng = np.random.default_rng(3)
    data = rng.normal(size=(25, 3))
    tabs = [ChunkedTable(tmp_path / f"{m}.parquet", COLS, chunk_rows=7, labels=["x"], progress_column="t")
            for m in ("dict", "block")]
    for r0 in range(0, 25, 5):
        blk = data[r0:r0 + 5]
        t = float(r0)
        tabs[0].append({"t": t, "id": np.array([tabs[0].code(f"v{i % 3}") for i in range(5)], np.int32),
                        "a": blk[:, 0], "b": blk[:, 1], "k": 4, "c": blk[:, 2]}, 5)
        tb = tabs[1]
        sl = tb.rows(5)
        tb.block(["a", "b"])[:, sl] = blk[:, :2].T
        tb.column("c")[sl] = blk[:, 2]
        tb.column("t")[sl] = t
        tb.column("k")[sl] = 4
        tb.column("id")[sl] = [tb.code(f"v{i % 3}") for i in range(5)]
        tb.commit(5)
    for tb in tabs:
        tb.close()
    a, b = _read(tmp_path / "dict.parquet"), _read(tmp_path / "block.parquet")
    pd.testing.assert_frame_equal(a, b)
    assert len(a) == 25 and a["id"].tolist()[:4] == ["v0", "v1", "v2", "v0"]
    np.testing.assert_array_equal(a[["a", "b", "c"]].to_numpy(), data)
    assert a["k"].dtype == np.int32 and (a["k"] == 4).all()
    # dict appends fill 7-row parts exactly; rows(5) writes early when 5 rows do not fit
    assert tabs[0].parts_written == 4 and tabs[1].parts_written == 5
    assert tabs[1].written_up_to() == 20.0  # last t on disk


def test_block_refuses_columns_that_are_not_neighbours(tmp_path):
    tb = ChunkedTable(tmp_path / "x.parquet", COLS, chunk_rows=4)
    assert tb.block(["t", "a", "b", "c"]).shape == (4, 4)  # float64 columns, string/int skipped
    with pytest.raises(ValueError, match="not consecutive"):
        tb.block(["a", "c"])
    with pytest.raises(ValueError, match="not consecutive"):
        tb.block(["b", "k"])
    tb.close()


def test_progress_is_reported_only_for_parts_on_disk(tmp_path):
    tb = ChunkedTable(tmp_path / "p.parquet", COLS, chunk_rows=3, labels=["x"], progress_column="t")
    seen = []
    for i in range(10):
        tb.append({"t": float(i), "id": 0, "a": 0.0, "b": 0.0, "k": 0, "c": 0.0}, 1)
        tb.wait()
        done = tb.written_up_to()
        if done is not None:
            seen.append(done)
            assert _read(tmp_path / "p.parquet")["t"].max() == done
    assert seen == [2.0, 5.0, 8.0]
    tb.close()
    assert _read(tmp_path / "p.parquet")["t"].tolist() == [float(i) for i in range(10)]


def test_a_failed_part_write_is_raised(tmp_path):
    """The directory vanishes under the writer: the error surfaces at the next write or at close."""
    import shutil
    tb = ChunkedTable(tmp_path / "f.parquet", COLS, chunk_rows=2, labels=["x"])
    shutil.rmtree(tmp_path / "f.parquet")
    with pytest.raises(OSError):
        for i in range(6):
            tb.append({"t": float(i), "id": 0, "a": 0.0, "b": 0.0, "k": 0, "c": 0.0}, 1)
        tb.close()


def test_an_empty_table_gets_a_zero_row_part_with_its_schema(tmp_path):
    tb = ChunkedTable(tmp_path / "e.parquet", COLS, chunk_rows=5)
    tb.close()
    df = _read(tmp_path / "e.parquet")
    assert len(df) == 0 and list(df.columns) == [c.name for c in COLS]
