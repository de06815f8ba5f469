"""Run one scenario headless and record it: the library call behind ``formation-traci run``.

The step loop itself is sim/loop.py (one loop over a World, docs/architecture.md). Rates
from the scenario (docs/scenarios.md): every outer ``step`` is ``step / control_step``
controller periods; each period evaluates the controllers once, holds the input and
integrates with RK4 sub-steps of at most ``physics_step``. One row per vehicle is recorded
at every outer step, from the first controller evaluation of the step.
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



from ..record.writer import atomic_write_json
from ..scenario.load import ScenarioError
from ..scenario.schema import Scenario
from .loop import ModelRangeError, check_finite, free_space_run, step_loop  # noqa: F401
from .recorder import Recorder
from .setup import member_vehicles, road_mu


class RunDirExists(FileExistsError):
    """The output directory exists and --force was not given."""


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
    bodies = [{"length": v.length, "width": v.width, "a": v.a, "front_overhang": v.front_overhang}
              for v in member_vehicles(sc)]  # [m], analysis footprints read it
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
        "members": [{"id": m.id,
                     "offset": list(m.offset) if m.offset is not None else [m.slot.along, m.slot.across],
                     "lanes": None if m.slot is None else m.slot.lanes,
                     "frame": "vehicle" if m.offset is not None else "road", "body": bodies[i],
                     "preset": m.preset or sc.vehicle.preset}
                    for i, m in enumerate(sc.members)],
        "versions": versions(),
        "started": _now(),
        "finished": None,
        "t_end": 0.0,
        "steps_done": 0,
    }


def run_scenario(sc: Scenario, out_dir: Path, *, scenario_path: str | Path | None = None,
                 force: bool = False, progress: bool = True, baseline: bool = False,
                 step_hook=None, transforms=()) -> RunResult:
    """Run ``sc`` (free space, or on a SUMO road when it has a [road]) and record it.

    Writes ``run.json`` (status ``running`` at once, updated at every trajectory part file
    and at the end) and the tables (docs/outputs.md). Never raises for a failure inside
    the run: the status says ``failed`` with the reason, and all rows recorded so far are
    kept. ``scenario_path`` resolves relative paths in the scenario (the network file).
    ``baseline`` (road scenarios): the twin run with the same traffic and seed but without
    the formation, for ``formation-traci analyze RUN --baseline TWIN``. ``step_hook(k, t,
    adapter)`` is called after every SUMO step (fault injection, extensions).
    ``transforms``: callables Reference -> Reference applied to every step's reference in
    order (maneuvers, communication channels; docs/architecture.md).
    """
    if baseline and sc.road is None:
        raise ScenarioError(scenario_path or "<scenario>", [("road", "--baseline needs a road scenario")])
    src = None if scenario_path is None else Path(scenario_path)
    plan = None
    if sc.road is not None:  # road, route, lanes and slots are checked before anything runs
        from .sumo_plan import prepare
        plan = prepare(sc, src)
    out_dir = prepare_out_dir(out_dir, force)
    meta = run_meta(sc, None if scenario_path is None else str(scenario_path))
    meta["baseline"] = baseline
    meta_path = out_dir / "run.json"
    atomic_write_json(meta_path, meta)
    rec = Recorder(out_dir, [m.id for m in sc.members], with_sumo=sc.road is not None)
    n_steps = int(round(sc.run.duration / sc.run.step))

    status, reason, t, k = "completed", None, 0.0, 0
    bar = None
    steps = None
    try:
        if sc.road is None:
            build = lambda: free_space_run(sc)  # noqa: E731
        else:
            from .sumo_world import road_run
            build = lambda: road_run(sc, plan, rec, out_dir, meta, baseline, step_hook)  # noqa: E731
        steps = step_loop(sc, _with_transforms(build, transforms), rec, meta)
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=n_steps, unit="step", desc=sc.name or "run", mininterval=0.5)
        with stop_on_signals() as stop:
            for k, t in steps:
                done = rec.written_up_to()  # a part file is on disk up to this time [s]
                if done is not None:
                    _progress_meta(meta_path, meta, done, int(round(done / sc.run.step)))
                if bar is not None and k > 0:
                    bar.update(1)
                if stop.is_set():
                    status = "interrupted"
                    reason = f"{getattr(stop, 'signame', 'signal')} received"
                    break
    except ScenarioError:
        raise
    except Exception as exc:  # recorded, never lost: the status says what happened
        status = "failed"
        reason = f"{type(exc).__name__}: {exc}"
        (out_dir / "error.txt").write_text(traceback.format_exc())
    finally:
        if bar is not None:
            bar.close()
        try:
            if steps is not None:
                steps.close()  # a SUMO loop closes SUMO and converts its outputs here
        finally:
            rec.flush()
            meta.update(status=status, reason=reason, finished=_now(), t_end=float(t),
                        steps_done=int(k), rows_written=rec.traj.rows_written)
            meta["event_counts"] = rec.event_counts
            atomic_write_json(meta_path, meta)
    return RunResult(out_dir, status, reason, float(t), int(k))


def _with_transforms(build, transforms):
    def built():
        parts = build()
        parts.transforms.extend(transforms)
        return parts
    return built


def _progress_meta(path, meta, t, k):
    meta.update(t_end=float(t), steps_done=int(k))
    atomic_write_json(path, meta)


