"""Run one scenario headless and record it: the library call behind ``formation-traci run``.

Loop structure (rates from the scenario, see docs/scenarios.md): every outer ``step`` is
``step / control_step`` controller periods; each period evaluates the controllers once,
holds the input and integrates with RK4 sub-steps of at most ``physics_step``. One row per
vehicle is recorded at every outer step, from the first controller evaluation of the step.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import importlib.metadata
import platform
import shutil
import signal
import threading
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..control.formation import rigid_targets
from ..record.columns import TRAJECTORY_COLUMNS, VIRTUAL_CAR_ID
from ..record.writer import ChunkedTable, atomic_write_json
from ..scenario.schema import Scenario
from . import fleet as fl
from .setup import build_fleet, build_free_leader, build_initial_state, offsets, road_mu

STEPS_PER_CHUNK = 1200
"""Outer steps per Parquet part file (60 s of simulated time at the default 0.05 s step)."""


class RunDirExists(FileExistsError):
    """The output directory exists and --force was not given."""


class ModelRangeError(RuntimeError):
    """A vehicle state became non-finite: the model left its valid range."""


@dataclass(frozen=True)
class RunResult:
    out_dir: Path
    status: str  # completed | interrupted | failed
    reason: str | None
    t_end: float  # last simulated time [s]
    steps_done: int


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def versions() -> dict[str, str]:
    """Versions of the package, its dependencies and Python, for run.json."""
    out = {"python": platform.python_version(), "platform": platform.platform()}
    for dist in ("formation-traci", "numpy", "pandas", "pyarrow", "pydantic", "scipy",
                 "eclipse-sumo", "libsumo", "sumolib"):
        try:
            out[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def prepare_out_dir(out_dir: Path, force: bool) -> Path:
    """Create ``out_dir``; an existing non-empty one is refused unless ``force``."""
    out_dir = Path(out_dir)
    if out_dir.exists() and any(out_dir.iterdir()):
        if not force:
            raise RunDirExists(f"{out_dir} exists and is not empty; pass --force to replace it")
        shutil.rmtree(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return out_dir


@contextlib.contextmanager
def stop_on_signals():
    """SIGINT/SIGTERM set a flag that the loop checks after every step (main thread only)."""
    flag = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    previous = {}

    def handler(signum, frame):
        flag.set()
        flag.signame = signal.Signals(signum).name

    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, handler)
    try:
        yield flag
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h)


def run_meta(sc: Scenario, scenario_path: str | None) -> dict:
    return {
        "status": "running",
        "reason": None,
        "scenario_path": scenario_path,
        "scenario": sc.model_dump(mode="json"),
        "seed": sc.run.seed,
        "model": sc.vehicle.model,
        "mu": road_mu(sc),
        "record_step": sc.run.step,
        "duration": sc.run.duration,
        "members": [{"id": m.id, "offset": list(m.offset), "frame": "vehicle"} for m in sc.members],
        "versions": versions(),
        "started": _now(),
        "finished": None,
        "t_end": 0.0,
        "steps_done": 0,
    }


def run_scenario(sc: Scenario, out_dir: Path, *, scenario_path: str | None = None,
                 force: bool = False, progress: bool = True) -> RunResult:
    """Run ``sc`` in free space and record it under ``out_dir``.

    Writes ``run.json`` (status ``running`` at once, updated at every part file and at the
    end) and the ``trajectories.parquet`` dataset. Never raises for a failure inside the
    run: the status says ``failed`` with the reason, and all rows recorded so far are kept.
    """
    out_dir = prepare_out_dir(out_dir, force)
    meta = run_meta(sc, scenario_path)
    meta_path = out_dir / "run.json"
    atomic_write_json(meta_path, meta)

    run = sc.run
    n_steps = int(round(run.duration / run.step))
    n_ctrl = int(round(run.step / run.control_step))
    dt_c = run.step / n_ctrl
    ids = [m.id for m in sc.members]
    n = len(ids)
    table = ChunkedTable(out_dir / "trajectories.parquet", TRAJECTORY_COLUMNS,
                         chunk_rows=(n + 1) * STEPS_PER_CHUNK, labels=ids + [VIRTUAL_CAR_ID])
    member_codes = np.arange(n, dtype=np.int32)
    vc_code = n

    status, reason, t, k = "completed", None, 0.0, 0
    bar = None
    try:
        cfg = build_fleet(sc)
        leader, pose = build_free_leader(sc)
        d = offsets(sc)
        state = build_initial_state(sc, cfg, leader.sample(0.0, pose))
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=n_steps, unit="step", desc=sc.name or "run", mininterval=0.5)
        with stop_on_signals() as stop:
            for k in range(n_steps + 1):
                t = k * run.step
                for j in range(n_ctrl):
                    tc = t + j * dt_c
                    vc = leader.sample(tc, pose)
                    targets = rigid_targets(vc, d)
                    u, fo = fl.control(cfg, state, targets)
                    if j == 0:
                        _record(table, tc, cfg, state, u, fo, targets, vc, member_codes, vc_code)
                        if table.rows_buffered == 0:  # a part file was just written
                            _progress_meta(meta_path, meta, tc, k)
                    if k == n_steps:
                        break
                    state = fl.advance(cfg, state, u, fo, dt_c)
                    pose = leader.advance(tc, pose, dt_c)
                if k == n_steps:
                    break
                if not np.all(np.isfinite(state.x)):
                    bad = [ids[i] for i in np.flatnonzero(~np.all(np.isfinite(state.x), axis=1))]
                    raise ModelRangeError(f"vehicle state became non-finite for {bad} "
                                          f"at t = {t + run.step:.3f} s")
                if bar is not None:
                    bar.update(1)
                if stop.is_set():
                    status = "interrupted"
                    reason = f"{getattr(stop, 'signame', 'signal')} received"
                    break
    except Exception as exc:  # recorded, never lost: the status says what happened
        status = "failed"
        reason = f"{type(exc).__name__}: {exc}"
        (out_dir / "error.txt").write_text(traceback.format_exc())
    finally:
        if bar is not None:
            bar.close()
        try:
            table.flush()
        finally:
            meta.update(status=status, reason=reason, finished=_now(),
                        t_end=float(t), steps_done=int(k),
                        rows_written=table.rows_written)
            atomic_write_json(meta_path, meta)
    return RunResult(out_dir, status, reason, float(t), int(k))


def _progress_meta(path, meta, t, k):
    meta.update(t_end=float(t), steps_done=int(k))
    atomic_write_json(path, meta)


def _record(table, t, cfg, state, u, fo, targets, vc, member_codes, vc_code):
    sig = fl.member_signals(cfg, state, u, fo, targets, vc.theta)
    sig["t"] = t
    sig["vehicle_id"] = member_codes
    table.append(sig, cfg.n)
    table.append(_vc_row(t, vc, vc_code), 1)


_VC_NAN = {c.name: np.nan for c in TRAJECTORY_COLUMNS if c.dtype == "float64"}


def _vc_row(t, vc, code):
    row = dict(_VC_NAN)
    row.update(t=t, vehicle_id=code, x=vc.x, y=vc.y, heading=vc.theta, v=vc.v,
               yaw_rate=vc.omega, a_lon=vc.v_dot, a_lat=vc.v * vc.omega)
    return row
