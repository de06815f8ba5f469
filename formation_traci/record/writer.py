"""Chunked Parquet recording that survives crashes.

A table is a Parquet *dataset directory* (``trajectories.parquet/part-00000.parquet``, ...)
readable as one table by ``pandas.read_parquet(dir)``, pyarrow.dataset, polars or duckdb.
Rows are buffered in preallocated numpy arrays and each full buffer is written as one part
file under a temporary name (leading '.', which dataset readers ignore) and then renamed,
so a killed process leaves only complete part files.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Sequence

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .columns import Column


def atomic_write_text(path: Path, text: str) -> None:
    """Write text to ``path`` via a temporary file and a rename (never half-written)."""
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def atomic_write_json(path: Path, obj) -> None:
    atomic_write_text(path, json.dumps(obj, indent=2, default=_json_default) + "\n")


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


class ChunkedTable:
    """Append rows column-wise into fixed buffers; flush full buffers as part files.

    String columns are stored as integer codes into ``labels`` while buffered.
    """

    def __init__(self, directory: Path, columns: Sequence[Column], chunk_rows: int = 50_000,
                 labels: Sequence[str] = ()):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.columns = tuple(columns)
        self.chunk_rows = int(chunk_rows)
        self.labels = list(labels)
        self._label_index = {s: i for i, s in enumerate(self.labels)}
        self._buf = {
            c.name: np.empty(self.chunk_rows, dtype=np.int32 if c.dtype == "string" else c.dtype)
            for c in self.columns
        }
        self._n = 0
        self.parts_written = 0
        self.rows_written = 0
        self._schema = pa.schema([
            pa.field(c.name, pa.string() if c.dtype == "string" else pa.from_numpy_dtype(np.dtype(c.dtype)),
                     metadata={"unit": c.unit, "doc": c.doc})
            for c in self.columns
        ])

    def code(self, label: str) -> int:
        """Integer code of a string value (added on first use)."""
        i = self._label_index.get(label)
        if i is None:
            i = self._label_index[label] = len(self.labels)
            self.labels.append(label)
        return i

    def append(self, block: dict[str, np.ndarray | float | int], n: int) -> None:
        """Append ``n`` rows; scalars broadcast, string columns take integer codes."""
        start = 0
        while start < n:
            take = min(n - start, self.chunk_rows - self._n)
            sl = slice(self._n, self._n + take)
            for name, buf in self._buf.items():
                val = block[name]
                if np.ndim(val) == 0:
                    buf[sl] = val
                else:
                    buf[sl] = val[start:start + take]
            self._n += take
            start += take
            if self._n == self.chunk_rows:
                self.flush()

    def close(self) -> None:
        """Flush; a table that got no row at all gets one empty part file, so readers find
        a table (with its schema) of zero rows rather than an empty directory."""
        self.flush()
        if self.parts_written == 0:
            self.flush(allow_empty=True)

    def flush(self, allow_empty: bool = False) -> None:
        """Write buffered rows (if any) as the next part file."""
        if self._n == 0 and not allow_empty:
            return
        labels = np.array(self.labels, dtype=object)
        arrays = []
        for c in self.columns:
            data = self._buf[c.name][: self._n]
            arrays.append(pa.array(labels[data], type=pa.string()) if c.dtype == "string" else pa.array(data))
        table = pa.Table.from_arrays(arrays, schema=self._schema)
        name = f"part-{self.parts_written:05d}.parquet"
        tmp = self.directory / f".{name}.tmp"
        pq.write_table(table, tmp, compression="zstd")
        os.replace(tmp, self.directory / name)
        self.parts_written += 1
        self.rows_written += self._n
        self._n = 0

    @property
    def rows_buffered(self) -> int:
        return self._n
