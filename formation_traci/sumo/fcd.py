"""SUMO's FCD output, ``sumo/fcd.parquet``, rewritten after the run with one naming of its
columns in both frames (run_contract/columns.py FCD_COLUMNS) and each column's unit in the Parquet
field metadata (as the tables of the recorder; file metadata ``frame``: ``sumo`` or
``formation``).

``sumo.fcd_frame = "sumo"``: SUMO's values as SUMO wrote them: ``t`` SUMO's time label (warm-up
included; the state after the step that began then), ``x``/``y`` the front bumper, ``heading``
degrees clockwise from north, ``v`` SUMO's speed. ``"formation"``: the frame of
trajectories.parquet: ``t`` = the formation time of the state, the very float of the
trajectories' ``t`` (k * run.step with k = round((label + step - warm-up) / step): SUMO labels
the state after a step with the step's start), ``x``/``y`` the centre of gravity of members and
the body centre of other vehicles [m], ``heading`` [rad, CCW from +x], and the members' ``v``
their true speed (the model's, as recorded; SUMO's is the mean over the step it infers from the
distance moved). In both: ``edge`` filled from the lane where SUMO leaves it empty.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from run_contract.columns import FCD_COLUMNS, FCD_SUMO_UNITS

from ..record.writer import atomic_write_parquet
from .adapter import sumo_to_cog
from .traffic import BASE_TYPES

RENAME = {"timestep_time": "t", "vehicle_id": "vehicle_id", "vehicle_type": "type",
          "vehicle_x": "x", "vehicle_y": "y", "vehicle_angle": "heading", "vehicle_speed": "v",
          "vehicle_lane": "lane", "vehicle_edge": "edge", "vehicle_pos": "lane_pos",
          "vehicle_slope": "slope"}
"""SUMO's FCD column -> ours; any other ``vehicle_*`` column loses the prefix."""


def rewrite_fcd(path: Path, frame: str, t0: float, member_d_front: dict[str, float],
                step: float, member_v: dict[str, np.ndarray] | None = None) -> None:
    """Rewrite ``path`` (SUMO's FCD Parquet) in ``frame`` (module docstring), in place.

    Parameters
    ----------
    path : Path
        ``sumo/fcd.parquet``.
    frame : str
        ``"sumo"`` or ``"formation"``.
    t0 : float
        Warm-up [s].
    member_d_front : dict
        Member id -> CoG to front bumper [m].
    step : float
        SUMO's step length [s] (= run.step).
    member_v : dict, optional
        Member id -> its true speed [m/s] at every step index k (NaN where it was not in the
        run); the formation frame's ``v`` of members.
    """
    if not path.exists():
        return
    df = pd.read_parquet(path)
    df = df.rename(columns={c: RENAME.get(c, c.removeprefix("vehicle_")) for c in df.columns})
    if "edge" not in df:
        df["edge"] = pd.Series([None] * len(df), dtype=object)
    if "lane" in df:
        lane = df["lane"].astype(object)
        edge = lane.where(lane.isna(), lane.astype(str).str.rsplit("_", n=1).str[0])
        df["edge"] = df["edge"].astype(object).where(df["edge"].notna(), edge)
    if frame == "formation":
        df = _formation(df, t0, member_d_front, step, member_v or {})
    order = [c.name for c in FCD_COLUMNS if c.name in df] + \
        [c for c in df.columns if c not in {c.name for c in FCD_COLUMNS}]
    _write(df[order], path, frame)


def true_speeds(by_step: dict | None, ids) -> dict | None:
    """Member id -> its speed [m/s] at every step index (NaN: not recorded) from
    ``by_step`` (step index -> the members' speeds), for sumo/fcd.py."""
    if not by_step:
        return None
    v = np.full((max(by_step) + 1, len(ids)), np.nan)
    for k, row in by_step.items():
        v[k] = row
    return {m: v[:, i] for i, m in enumerate(ids)}


def _formation(df: pd.DataFrame, t0: float, member_d_front, step: float, member_v) -> pd.DataFrame:
    ids = df["vehicle_id"].astype(str)
    types = df["type"].astype(str) if "type" in df else pd.Series([""] * len(df))
    half = np.full(len(df), np.nan)
    for kind, spec in BASE_TYPES.items():
        half[types.str.endswith(f"_{kind}").to_numpy()] = float(spec["length"]) / 2
    d = ids.map(member_d_front).to_numpy(dtype=float)
    d = np.where(np.isnan(d), half, d)
    x, y, psi = sumo_to_cog(df["x"].to_numpy(float), df["y"].to_numpy(float),
                            df["heading"].to_numpy(float), np.nan_to_num(d))
    k = np.round((df["t"].to_numpy(float) + step - t0) / step).astype(np.int64)
    df = df.assign(t=k.astype(float) * step, x=x, y=y, heading=psi)  # t: k * step, as the loop's
    v = df["v"].to_numpy(float).copy() if "v" in df else np.full(len(df), np.nan)
    for mid, vs in member_v.items():
        rows = np.flatnonzero((ids == mid).to_numpy() & (k >= 0) & (k < len(vs)))
        true = vs[k[rows]]
        v[rows] = np.where(np.isnan(true), v[rows], true)
    return df.assign(v=v)


def _write(df: pd.DataFrame, path: Path, frame: str) -> None:
    import pyarrow as pa

    spec = {c.name: c for c in FCD_COLUMNS}
    fields = []
    for name in df.columns:
        col = df[name]
        typ = pa.string() if col.dtype == object or str(col.dtype) in ("string", "str") \
            else pa.from_numpy_dtype(col.dtype)
        c = spec.get(name)
        unit = (FCD_SUMO_UNITS.get(name, c.unit) if frame == "sumo" else c.unit) if c else ""
        fields.append(pa.field(name, typ, metadata={"unit": unit, "doc": c.doc if c else "SUMO's"}))
    table = pa.Table.from_pandas(df, schema=pa.schema(fields), preserve_index=False)
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), b"frame": frame.encode()})
    atomic_write_parquet(path, table, tmp=path.with_suffix(".tmp.parquet"))


def cut_fcd(path: Path, t0: float, step: float, t_max: float) -> None:
    """Leave out the FCD rows of states after formation time ``t_max`` [s] (the measurement
    sections' drain after the run), in place, in SUMO's frame (before
    :func:`rewrite_fcd`)."""
    if not path.exists() or not np.isfinite(t_max):
        return
    df = pd.read_parquet(path)
    keep = df["timestep_time"].to_numpy(float) + step - t0 <= t_max + 1e-9
    if keep.all():
        return
    atomic_write_parquet(path, df[keep], tmp=path.with_suffix(".tmp.parquet"))
