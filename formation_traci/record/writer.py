"""Chunked Parquet recording that survives crashes.

A table is a Parquet *dataset directory* (``trajectories.parquet/part-00000.parquet``, ...)
readable as one table by ``pandas.read_parquet(dir)``, pyarrow.dataset, polars or duckdb.
Rows are buffered in preallocated numpy arrays and each full buffer is written, by a
background thread, as one part file under a temporary name (leading '.', which dataset
readers ignore) and then renamed, so a killed process leaves only complete part files.
pyarrow is imported by that thread when it writes the first part, not before a run's first
step (~40-50 ms of every start).
"""
from __future__ import annotations

import json
import os
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Sequence

import numpy as np

from run_contract.rundir import atomic_write_text

from run_contract.columns import Column


def _arrow(data: np.ndarray):
    """A 1-D numpy array (numbers or bool) as a pyarrow array without nulls, the values
    ``pa.array(data)`` gives. Built from its buffers: ``pa.array`` imports pandas on its first
    call (about 1 s), which a run does not otherwise need."""
    import pyarrow as pa

    n = len(data)
    if data.dtype == np.bool_:
        return pa.Array.from_buffers(pa.bool_(), n, [None, pa.py_buffer(np.packbits(data, bitorder="little"))])
    return pa.Array.from_buffers(pa.from_numpy_dtype(data.dtype), n,
                                 [None, pa.py_buffer(np.ascontiguousarray(data))])


def _arrow_strings(labels: Sequence[str]):
    """A list of str as a pyarrow string array (from its buffers, as :func:`_arrow`)."""
    import pyarrow as pa

    enc = [s.encode("utf-8") for s in labels]
    offsets = np.zeros(len(enc) + 1, dtype=np.int32)
    np.cumsum([len(b) for b in enc], out=offsets[1:])
    return pa.Array.from_buffers(pa.string(), len(enc), [None, pa.py_buffer(offsets),
                                                          pa.py_buffer(b"".join(enc))])


def atomic_write_parquet(path: Path, data, tmp: Path | None = None, **options) -> None:
    """``data`` (a pyarrow Table, or a pandas DataFrame without its index, the bytes of
    ``DataFrame.to_parquet``) to ``path`` through ``tmp`` (default ``.{name}.tmp`` beside it)
    and a rename; ``options``: pyarrow's ``write_table`` (e.g. ``compression``). On a failure
    (disk full) the temporary file is closed and removed here: pyarrow's own sink stays open
    while the failed write's traceback lives (an error kept for run.json), holding the deleted
    file's space."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp") if tmp is None else tmp
    try:
        with pa.OSFile(str(tmp), "wb") as sink:
            if isinstance(data, pa.Table):
                pq.write_table(data, sink, **options)
            else:
                data.to_parquet(sink, index=False, **options)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def json_text(obj, indent: int | None = 2) -> str:
    """``obj`` as the tool's JSON files hold it (numpy numbers and arrays, paths); ``indent``
    None: without indentation or spaces (a full disk's last resort, runner.py)."""
    seps = None if indent is not None else (",", ":")
    return json.dumps(obj, indent=indent, separators=seps, default=_json_default) + "\n"


def atomic_write_json(path: Path, obj) -> None:
    atomic_write_text(path, json_text(obj))


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


class ChunkedTable:
    """Append rows into preallocated buffers; write each full buffer as a part file.

    Columns of one storage dtype share a 2-D buffer (one contiguous row per column), so a
    block of consecutive columns is filled with one assignment (:meth:`rows` and
    :meth:`block`). String columns are stored as integer codes into ``labels`` while
    buffered. Part files are written by one background thread (Parquet encoding and
    compression release the GIL, so they overlap the simulation); :meth:`close` waits for
    them and re-raises a failed write.

    ``progress_column``: the last value of this column in each part file written is kept
    (:meth:`written_up_to`), so a caller reports only progress that is on disk.

    A column with ``derived_from`` (e.g. ``formation_id`` from ``vehicle_id``) has no buffer:
    the writer maps every value of its source column through ``derived`` (a label -> label
    dict the caller keeps up to date; "" where it has no entry) when it writes a part, so
    recording it costs nothing per row.
    """

    def __init__(self, directory: Path, columns: Sequence[Column], chunk_rows: int = 50_000,
                 labels: Sequence[str] = (), progress_column: str | None = None,
                 derived: dict[str, str] | None = None):
        self.directory = Path(directory)
        self.derived = {} if derived is None else derived
        self.directory.mkdir(parents=True, exist_ok=True)
        self.columns = tuple(columns)
        self.chunk_rows = int(chunk_rows)
        self.labels = list(labels)
        self._label_index = {s: i for i, s in enumerate(self.labels)}
        groups: dict[str, list[str]] = {}
        for c in self.columns:
            if not c.derived_from:
                groups.setdefault(_storage_dtype(c), []).append(c.name)
        self._blocks: dict[str, np.ndarray] = {}
        self._where: dict[str, tuple[str, int]] = {}  # column -> (storage dtype, row in its block)
        self._buf: dict[str, np.ndarray] = {}  # column -> its row of the block (a view)
        for dt, names in groups.items():
            blk = self._blocks[dt] = np.empty((len(names), self.chunk_rows), dtype=dt)
            for j, name in enumerate(names):
                self._where[name] = (dt, j)
                self._buf[name] = blk[j]
        self._n = 0
        self.parts_written = 0  # parts handed to the writer (written or being written)
        self.rows_written = 0
        self.progress_column = progress_column
        self._done: list[float] = []  # progress value of each part on disk, in order
        self.parts_on_disk = 0  # part files completely written
        self.rows_on_disk = 0
        self.last_on_disk: float | None = None  # progress value (or mark) of the last part on disk
        self._failed: BaseException | None = None  # first failed write, seen by the caller
        self._broken = False  # a write failed: the writer thread writes no later part
        self._pool: ThreadPoolExecutor | None = None
        self._pending: list[Future] = []
        self._schema = None  # the Arrow schema, built with the first part (:meth:`_arrow_schema`)

    def code(self, label: str) -> int:
        """Integer code of a string value (added on first use)."""
        i = self._label_index.get(label)
        if i is None:
            i = self._label_index[label] = len(self.labels)
            self.labels.append(label)
        return i

    def codes(self, labels: Sequence[str]) -> np.ndarray:
        """Integer codes (int32) of string values, as :meth:`code` gives them one by one."""
        get = self._label_index.get
        out = [get(label) for label in labels]
        if None in out:
            out = [self.code(label) for label in labels]
        return np.array(out, dtype=np.int32)

    def append(self, block: dict[str, np.ndarray | float | int], n: int) -> None:
        """Append ``n`` rows; scalars broadcast, string columns take integer codes."""
        start = 0
        while start < n:
            take = min(n - start, self.chunk_rows - self._n)
            sl = slice(self._n, self._n + take)
            whole = start == 0 and take == n
            for name, buf in self._buf.items():
                val = block[name]
                if isinstance(val, np.ndarray) and val.ndim:
                    buf[sl] = val if whole else val[start:start + take]
                else:
                    buf[sl] = val
            self._n += take
            start += take
            if self._n == self.chunk_rows:
                self.flush()

    def rows(self, n: int) -> slice:
        """Room for ``n`` more rows in the buffer (writing the buffer first if it cannot take
        them; a part may then hold fewer than ``chunk_rows`` rows). Fill every column of the
        returned slice (:meth:`block`, :meth:`column`), then call :meth:`commit`."""
        if n > self.chunk_rows:
            raise ValueError(f"{n} rows do not fit a buffer of {self.chunk_rows}")
        if self._n + n > self.chunk_rows:
            self.flush()
        return slice(self._n, self._n + n)

    def commit(self, n: int) -> None:
        """The ``n`` rows of the last :meth:`rows` slice are filled."""
        self._n += n
        if self._n == self.chunk_rows:
            self.flush()

    def column(self, name: str) -> np.ndarray:
        """The buffer of one column (codes for a string column)."""
        return self._buf[name]

    def block(self, names: Sequence[str]) -> np.ndarray:
        """The buffers of columns ``names`` as one (len(names), chunk_rows) view; they must
        have one dtype and follow each other among the table's columns of that dtype."""
        dt, j = self._where[names[0]]
        if any(self._where.get(nm) != (dt, j + m) for m, nm in enumerate(names)):
            raise ValueError(f"columns {list(names)} are not consecutive {dt} columns of the table")
        return self._blocks[dt][j:j + len(names)]

    def close(self) -> None:
        """Write the rest and wait for every part; a table that got no row at all gets one
        empty part file, so readers find a table (with its schema) of zero rows rather than
        an empty directory."""
        try:
            self.flush()
            if self.parts_written == 0:
                self.flush(allow_empty=True)
        finally:
            try:
                self.wait()
            finally:
                if self._pool is not None:
                    self._pool.shutdown(wait=True)
                    self._pool = None

    def wait(self) -> None:
        """Block until every part handed to the writer is on disk; re-raise a failed write."""
        pending, self._pending = self._pending, []
        for fut in pending:
            fut.result()

    def written_up_to(self) -> float | None:
        """The ``progress_column`` value of the last row on disk, if a part was completed since
        the last call (else None)."""
        done, self._done = self._done, []  # one swap: the writer thread appends to the new list
        return done[-1] if done else None

    def flush(self, allow_empty: bool = False, mark: float | None = None) -> None:
        """Hand the buffered rows (if any) to the writer thread as the next part file.

        ``mark``: the table is complete up to this time [s]; once everything handed over so
        far is on disk, :meth:`written_up_to` reports it (a table with no part yet gets an
        empty one, so a reader finds the table)."""
        if self._n == 0 and not allow_empty:
            if mark is None:
                return
            if self.parts_written:
                self._submit(self._mark_only, mark)
                return
        n = self._n
        blocks = {dt: blk[:, :n].copy() for dt, blk in self._blocks.items()}
        tag = float(self._buf[self.progress_column][n - 1]) if self.progress_column and n else None
        tag = mark if mark is not None else tag
        name = f"part-{self.parts_written:05d}.parquet"
        self._submit(self._write, blocks, list(self.labels), name, tag, n, dict(self.derived))
        self.parts_written += 1
        self.rows_written += n
        self._n = 0

    def _submit(self, fn, *args) -> None:
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="parquet-writer")
        for fut in [f for f in self._pending if f.done()]:
            self._pending.remove(fut)
            if fut.exception() is not None and self._failed is None:
                self._failed = fut.exception()
        if self._failed is not None:
            raise self._failed  # a failed earlier part stops the run here, not at the end
        self._pending.append(self._pool.submit(fn, *args))

    def _mark_only(self, tag: float) -> None:
        if self._broken:
            return
        self.last_on_disk = tag
        self._done.append(tag)

    def _arrow_schema(self):
        """The table's Arrow schema: column names, types and each column's unit and doc."""
        if self._schema is None:
            import pyarrow as pa

            self._schema = pa.schema([
                pa.field(c.name, pa.string() if c.dtype == "string" else pa.from_numpy_dtype(np.dtype(c.dtype)),
                         metadata={"unit": c.unit, "doc": c.doc})
                for c in self.columns
            ])
        return self._schema

    def _write(self, blocks, labels, name, tag, n, derived=None) -> None:
        import pyarrow as pa

        if self._broken:  # never a part after a hole: the table stays a prefix of the run
            raise OSError(f"{self.directory.name}: {name} not written after an earlier part failed")
        mapped = None
        if any(c.derived_from for c in self.columns):
            mapped = _arrow_strings([(derived or {}).get(label, "") for label in labels])
        labels = _arrow_strings(labels)
        arrays = []
        for c in self.columns:
            dt, j = self._where[c.derived_from or c.name]
            data = blocks[dt][j]
            if c.derived_from:
                arrays.append(pa.DictionaryArray.from_arrays(_arrow(data), mapped).dictionary_decode())
            elif c.dtype == "string":
                arrays.append(pa.DictionaryArray.from_arrays(_arrow(data), labels).dictionary_decode())
            else:
                arrays.append(_arrow(data))
        table = pa.Table.from_arrays(arrays, schema=self._arrow_schema())
        try:
            atomic_write_parquet(self.directory / name, table, compression="zstd")
        except BaseException:
            self._broken = True  # e.g. disk full: the space freed, the parts before kept
            raise
        self.parts_on_disk += 1
        self.rows_on_disk += n
        if tag is not None:
            self.last_on_disk = tag
            self._done.append(tag)

    @property
    def rows_buffered(self) -> int:
        return self._n

    @property
    def news(self) -> bool:
        """True when a part was completed since the last :meth:`written_up_to`."""
        return bool(self._done)


def _storage_dtype(c: Column) -> str:
    return "int32" if c.dtype == "string" else c.dtype
