"""Synthetic run directories for the analysis tests (no simulator needed).

The virtual car drives straight at constant speed ``v`` along ``heading``; each member's
desired position follows eq. 2.4 of the seed from its offset, and its actual position is
``desired - error`` with the error ``(e_lon, e_lat)`` given per member as a function of
time, so every formation metric has a closed form.
"""
from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from run_contract.columns import (BACKGROUND_COLUMNS, DEFAULT_FORMATION_ID, EVENT_COLUMNS, SSM_COLUMNS,
                                  TRAJECTORY_COLUMNS, VIRTUAL_CAR_ID)

Signal = Callable[[str, np.ndarray], np.ndarray]

OFFSETS: dict[str, tuple[float, float]] = {
    "m1": (0.0, 0.0),
    "m2": (-12.0, 0.0),
    "m3": (-24.0, 0.0),
    "m4": (-12.0, 3.5),
}
"""Default formation: a column m1 -> m2 -> m3 (dy = 0) and m4 in the left lane."""

LANE_WIDTH = 3.5
"""Lane width of the synthetic road [m]."""

REFERENCE_LANE = 1
"""Lane index of the reference line d = 0 on the synthetic road (lanes 0, 1, 2)."""

ROAD_META = {"scenario": {"name": "synthetic-road", "vehicle": {"preset": "passenger_car"}},
             "seed": 1, "baseline": False}
"""run.json keys of a synthetic road run (members are passenger cars)."""

TIRE_COLUMNS = ("steer", "steer_rate", "beta", "slip_front", "slip_rear", "traction_force",
                "traction_force_max")
CONTROLLER_COLUMNS = ("ex", "ey", "e_lon", "e_lat", "x_des", "y_des", "v_ref", "omega_ref")


def time_vector(dt: float, t_end: float) -> np.ndarray:
    """Sample times 0, dt, ..., t_end (inclusive), rounded to 1e-9 s."""
    return np.round(np.arange(0.0, t_end + dt / 2, dt), 9)


def trajectories(*, dt: float = 0.01, t_end: float = 20.0, v: float = 20.0,
                 heading: float = 0.0, offsets: Mapping[str, tuple[float, float]] = OFFSETS,
                 error: Callable[[str, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
                 columns: Mapping[str, Signal] | None = None,
                 model: str = "dynamic", road: bool = False) -> pd.DataFrame:
    """Trajectory table with every contract column, one row per vehicle per step.

    ``road=True`` makes it a road run on a straight road along +x whose reference line is
    y = 0 (so ``s = x``, ``d = y``; needs ``heading = 0``); ``lane_index`` is
    ``round(d / LANE_WIDTH) + REFERENCE_LANE`` for members.
    """
    t = time_vector(dt, t_end)
    n = t.size
    c, s = np.cos(heading), np.sin(heading)
    x_vc, y_vc = v * t * c, v * t * s
    nan = np.full(n, np.nan)
    frames = [pd.DataFrame({
        "t": t, "vehicle_id": VIRTUAL_CAR_ID, "x": x_vc, "y": y_vc,
        "heading": np.full(n, heading), "v": np.full(n, v), "yaw_rate": np.zeros(n),
        "a_lon": np.zeros(n), "a_lat": np.zeros(n),
        **{k: nan for k in CONTROLLER_COLUMNS + TIRE_COLUMNS + ("friction_usage",)},
    })]
    for mid, (dx, dy) in offsets.items():
        e_lon, e_lat = error(mid, t) if error else (np.zeros(n), np.zeros(n))
        e_lon = np.broadcast_to(np.asarray(e_lon, float), (n,)).copy()
        e_lat = np.broadcast_to(np.asarray(e_lat, float), (n,)).copy()
        x_des, y_des = x_vc + c * dx - s * dy, y_vc + s * dx + c * dy
        ex, ey = c * e_lon - s * e_lat, s * e_lon + c * e_lat
        cols: dict[str, Any] = {
            "t": t, "vehicle_id": mid, "x": x_des - ex, "y": y_des - ey,
            "heading": np.full(n, heading), "v": np.full(n, v), "yaw_rate": np.zeros(n),
            "a_lon": np.zeros(n), "a_lat": np.zeros(n), "ex": ex, "ey": ey,
            "e_lon": e_lon, "e_lat": e_lat, "x_des": x_des, "y_des": y_des,
            "v_ref": np.full(n, v), "omega_ref": np.zeros(n), "steer": np.zeros(n),
            "steer_rate": np.zeros(n), "beta": np.zeros(n),
            "slip_front": np.full(n, 0.01), "slip_rear": np.full(n, 0.01),
            "traction_force": np.full(n, 500.0), "traction_force_max": np.full(n, 8000.0),
        }
        for name, fn in (columns or {}).items():
            cols[name] = np.broadcast_to(np.asarray(fn(mid, t), float), (n,)).copy()
        if "friction_usage" not in (columns or {}):
            cols["friction_usage"] = np.hypot(cols["a_lon"], cols["a_lat"]) / 9.81
        if model == "kinematic":
            for k in TIRE_COLUMNS:
                cols[k] = nan
        frames.append(pd.DataFrame(cols))
    df = pd.concat(frames, ignore_index=True)
    df["formation_id"] = DEFAULT_FORMATION_ID
    for col in TRAJECTORY_COLUMNS:  # contract columns this helper does not model: NaN
        if col.name not in df.columns:
            df[col.name] = np.nan
    if road:
        if heading != 0.0:
            raise ValueError("road=True needs heading = 0 (road along +x)")
        df["s"], df["d"] = df["x"], df["y"]
        mem = df["vehicle_id"] != VIRTUAL_CAR_ID
        df.loc[mem, "lane_index"] = np.round(df.loc[mem, "d"] / LANE_WIDTH) + REFERENCE_LANE
    return df[[col.name for col in TRAJECTORY_COLUMNS]]


def arrow_schema(columns) -> pa.Schema:
    types = {col.name: (pa.string() if col.dtype == "string" else pa.float64())
             for col in TRAJECTORY_COLUMNS}
    return pa.schema([(name, types.get(name, pa.float64())) for name in columns])


def write_run(path: Path, df: pd.DataFrame, *, n_parts: int = 3,
              offsets: Mapping[str, tuple[float, float]] = OFFSETS,
              meta: Mapping[str, Any] | None = None, write_meta: bool = True,
              single_file: bool = False) -> Path:
    """Write ``run.json`` and ``trajectories.parquet`` (dataset of time-chunked parts)."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    t = np.sort(df["t"].unique())
    dt = round(float(np.median(np.diff(t))), 12) if t.size > 1 else 0.01
    if write_meta:
        content = {
            "status": "completed", "reason": None, "t_end": float(t[-1]),
            "record_step": dt, "model": "dynamic", "mu": 1.0,
            "members": [{"id": k, "offset": list(v), "frame": "vehicle"}
                        for k, v in offsets.items()],
            "scenario": {"name": "synthetic"}, "versions": {"formation_traci": "test"},
        }
        content.update(meta or {})
        (path / "run.json").write_text(json.dumps(content, indent=2))
    schema = arrow_schema(df.columns)
    target = path / "trajectories.parquet"
    if single_file:
        pq.write_table(pa.Table.from_pandas(df, schema=schema, preserve_index=False), target)
        return path
    target.mkdir(exist_ok=True)
    for k, chunk in enumerate(np.array_split(t, n_parts)):
        part = df[df["t"].isin(chunk)]
        table = pa.Table.from_pandas(part, schema=schema, preserve_index=False)
        pq.write_table(table, target / f"part-{k:05d}.parquet")
    return path


def make_run(path: Path, *, n_parts: int = 3, meta: Mapping[str, Any] | None = None,
             offsets: Mapping[str, tuple[float, float]] = OFFSETS, **kwargs) -> Path:
    """Build trajectories with :func:`trajectories` and write them with :func:`write_run`."""
    df = trajectories(offsets=offsets, **kwargs)
    meta = dict(meta or {})
    meta.setdefault("model", kwargs.get("model", "dynamic"))
    return write_run(path, df, n_parts=n_parts, offsets=offsets, meta=meta)


def exp_error(e0: Mapping[str, float], tau: float = 2.0):
    """Error functions ``e_lon = e0[id] exp(-t/tau)``, ``e_lat = 0``."""
    def fn(mid: str, t: np.ndarray):
        return e0.get(mid, 0.0) * np.exp(-t / tau), np.zeros_like(t)
    return fn


_ARROW = {"float64": pa.float64(), "string": pa.string(), "int32": pa.int32(),
          "bool": pa.bool_()}


def write_table(path: Path, name: str, df: pd.DataFrame, contract, *, n_parts: int = 1) -> Path:
    """Write ``<name>.parquet`` as a dataset directory following a column contract."""
    target = Path(path) / f"{name}.parquet"
    target.mkdir(parents=True, exist_ok=True)
    types = {c.name: _ARROW[c.dtype] for c in contract}
    schema = pa.schema([(c, types.get(c, pa.float64())) for c in df.columns])
    df = df.copy()
    for c in df.columns:
        kind = types.get(c)
        if kind == pa.string():
            df[c] = df[c].astype(str)
        elif kind == pa.int32():
            df[c] = df[c].astype("int32")
        elif kind == pa.bool_():
            df[c] = df[c].astype(bool)
    for k, chunk in enumerate(np.array_split(np.arange(len(df)), max(1, n_parts))):
        part = df.iloc[chunk] if len(df) else df
        pq.write_table(pa.Table.from_pandas(part, schema=schema, preserve_index=False),
                       target / f"part-{k:05d}.parquet")
        if not len(df):
            break
    return target


def background(t: np.ndarray, vehicles: Mapping[str, Mapping[str, Any]]) -> pd.DataFrame:
    """Background rows on the synthetic road (``s = x``, ``d = y``, heading 0).

    ``vehicles`` maps an id to ``s0`` [m] (centre at t = 0), ``d`` [m], ``v`` [m/s] and
    optionally ``length`` (4.5), ``width`` (1.8), ``type`` ("main_car"), ``s`` (a
    function of t replacing ``s0 + v t``) and ``d_of_t`` (a function of t).
    """
    frames = []
    for vid, spec in vehicles.items():
        t = np.asarray(t, float)
        s = spec["s"](t) if "s" in spec else spec["s0"] + spec["v"] * t
        d = spec["d_of_t"](t) if "d_of_t" in spec else np.full(t.size, float(spec["d"]))
        v = np.gradient(s, t) if "s" in spec and t.size > 1 else np.full(t.size, float(spec["v"]))
        lane = np.round(d / LANE_WIDTH).astype(int) + REFERENCE_LANE
        frames.append(pd.DataFrame({
            "t": t, "vehicle_id": vid, "type": spec.get("type", "main_car"), "x": s, "y": d,
            "heading": 0.0, "v": v, "a": 0.0, "length": spec.get("length", 4.5),
            "width": spec.get("width", 1.8), "lane": [f"main_{k}" for k in lane],
            "lane_index": lane, "s": s, "d": d}))
    cols = [c.name for c in BACKGROUND_COLUMNS]
    if not frames:
        return pd.DataFrame({c: [] for c in cols})
    return pd.concat(frames, ignore_index=True)[cols]


def events(rows) -> pd.DataFrame:
    """Events table from ``(t, kind, vehicle_id, other_id, detail)`` tuples (formation_id:
    the one formation's for members and the virtual car, else empty, as the recorder writes)."""
    cols = [c.name for c in EVENT_COLUMNS if c.name != "formation_id"]
    df = pd.DataFrame(list(rows), columns=cols)
    df.insert(cols.index("vehicle_id") + 1, "formation_id",
              [DEFAULT_FORMATION_ID if v == VIRTUAL_CAR_ID or v in OFFSETS else ""
               for v in df["vehicle_id"]])
    return df


def ssm(rows) -> pd.DataFrame:
    """SSM table from ``(begin, end, ego, foe, member_involved, min_ttc, min_ttc_time,
    max_drac, max_drac_time, pet[, min_ttc_type, min_ttc_s, min_ttc_d])`` tuples (the last
    three NaN when left out)."""
    cols = [c.name for c in SSM_COLUMNS]
    return pd.DataFrame([tuple(r) + (np.nan,) * (len(cols) - len(r)) for r in rows], columns=cols)


def write_traffic(path: Path, *, background_df: pd.DataFrame | None = None,
                  events_df: pd.DataFrame | None = None, ssm_df: pd.DataFrame | None = None,
                  n_parts: int = 1) -> Path:
    """Write whichever of ``background``/``events``/``ssm`` tables are given."""
    for name, df, contract in (("background", background_df, BACKGROUND_COLUMNS),
                               ("events", events_df, EVENT_COLUMNS),
                               ("ssm", ssm_df, SSM_COLUMNS)):
        if df is not None:
            write_table(path, name, df, contract, n_parts=n_parts)
    return Path(path)
