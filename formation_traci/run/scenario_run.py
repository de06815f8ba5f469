"""Run one scenario headless and record it: the library call behind ``formation-traci run``.

The step loop itself is sim/loop.py (one loop over a World, docs/architecture.md). Rates
from the scenario (docs/scenarios.md): every outer ``step`` is ``step / control_step``
controller periods; each period evaluates the controllers once, holds the input and
integrates with RK4 sub-steps of at most ``physics_step``. One row per vehicle is recorded
at every outer step, from the first controller evaluation of the step.
"""
from __future__ import annotations

import datetime as _dt
import errno
import gc
import os
import platform
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from run_contract.rundir import RUN_FINISHED, RUN_SCHEMA, RunDirError, atomic_write_text, open_out_dir

from ..core.interrupt import Interrupted, stop_on_signals
from ..record.writer import atomic_write_json, json_text
from ..scenario.formations import formation_views
from ..scenario.load import ScenarioError
from ..scenario.schema import Scenario
from ..sim.formation import virtual_car_id
from ..sim.incidents import Incidents, verdict
from ..sim.loop import ModelRangeError, check_finite, free_space_run, step_loop  # noqa: F401
from ..sim.recorder import Recorder
from .twins import twin_mode
from ..sim.setup import member_vehicles, road_mu, with_comm
from ..core.versions import installed_versions, platform_name


@dataclass(frozen=True)
class RunResult:
    out_dir: Path
    status: str  # completed | completed_with_incidents | interrupted | failed
    reason: str | None
    t_end: float  # last simulated time [s]
    steps_done: int
    incidents: dict = field(default_factory=dict)  # run.json 'incidents' (sim/incidents.py)
    incident_summary: str | None = None  # one line, None: no incident of the verdict


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


RECORDED_DISTRIBUTIONS = ("formation-traci", "numpy", "pandas", "pyarrow", "pydantic", "scipy",
                          "eclipse-sumo", "libsumo", "sumolib")


def versions(more=()) -> dict[str, str]:
    """Versions of the package, its dependencies and Python, for run.json (and of the
    distributions ``more``, e.g. a sweep's executor)."""
    return {"python": platform.python_version(), "platform": platform_name(),
            **installed_versions(RECORDED_DISTRIBUTIONS + tuple(more))}


RESERVE_BYTES = 1 << 18
"""Space held back in the run directory (``.reserve``) from the start of a run, released to
write the final run.json when the disk is full [B]."""


def _members_meta(sc: Scenario, formation_id: str) -> list[dict]:
    """run.json's entries of one formation's members (``sc`` as that formation sees it)."""
    bodies = [{"length": v.length, "width": v.width, "a": v.a, "front_overhang": v.front_overhang}
              for v in member_vehicles(sc)]  # [m], analysis footprints read it
    return [{"id": m.id, "formation_id": formation_id,
             "offset": list(m.offset) if m.offset is not None else [m.slot.along, m.slot.across],
             "lanes": None if m.slot is None else m.slot.lanes,
             "frame": "vehicle" if m.offset is not None else "road", "body": bodies[i],
             "preset": m.preset or sc.vehicle.preset}
            for i, m in enumerate(sc.members)]


def run_meta(sc: Scenario, scenario_path: str | None) -> dict:
    return {
        "schema": RUN_SCHEMA,
        "status": "running",
        "reason": None,
        "scenario_path": scenario_path,
        "scenario": sc.model_dump(mode="json"),
        "seed": sc.run.seed,
        "model": sc.vehicle.model,
        "mu": road_mu(sc),
        "record_step": sc.run.step,
        "duration": sc.run.duration,
        "members": [m for fid, view in formation_views(sc) for m in _members_meta(view, fid)],
        "versions": versions(),
        "started": _now(),
        "finished": None,
        "t_end": 0.0,
        "steps_done": 0,
    }


def run_scenario(sc: Scenario, out_dir: Path, *, scenario_path: str | Path | None = None,
                 force: bool = False, progress: bool = True, baseline: bool | str = False,
                 step_hook=None, transforms=(), warm_cache: str | Path | None = None) -> RunResult:
    """Run ``sc`` (free space, or on a SUMO road when it has a [road]) and record it.

    Writes ``run.json`` (status ``running`` at once, updated whenever every table is on disk
    up to a later time, and at the end) and the tables (docs/outputs.md). Never raises for a
    failure inside the run (incl. disk full): the status says ``failed`` with the reason, and
    all rows on disk are kept and described (``run.json["tables"]``). SIGINT/SIGTERM at any
    moment give ``interrupted``. ``scenario_path`` resolves relative paths in the scenario
    (the network file). ``baseline`` (road scenarios): the twin run with the same traffic and
    seed (docs/metrics.md, "The twins"): ``"same"`` (or True) the same demand, every member a
    SUMO vehicle of its type entering when and where it would; ``"absent"`` without the
    formation's vehicles. ``step_hook(k, t, adapter)`` is called after every SUMO
    step (fault injection, extensions). ``transforms``: callables Reference -> Reference
    applied to every step's reference in order (maneuvers, communication channels;
    docs/architecture.md). ``warm_cache`` (road scenarios): a directory of shared warm-ups
    (sumo/warm_state.py): the run starts from the saved state of its warm-up key, simulated
    once (docs/sweeps.md, "The shared warm-up"); None: the warm-up is simulated in the run.

    Raises ScenarioError or RunDirError (bad input; nothing created or changed), or
    Interrupted if a signal arrives before the run directory exists. ``out_dir`` is locked
    for the whole run (run_contract/rundir.py); ``force`` replaces only a previous run.
    """
    baseline = twin_mode(baseline, scenario_path)
    if baseline and sc.road is None:
        raise ScenarioError(scenario_path or "<scenario>", [("road", "--baseline needs a road scenario")])
    src = None if scenario_path is None else Path(scenario_path)
    with stop_on_signals() as stop:
        plan = None
        protect = [src] if src is not None else []
        if sc.road is not None:  # road, route, lanes and slots are checked before anything runs
            from ..sumo.plan import prepare
            from ..sumo.ssm import warn_memory
            plan = prepare(sc, src)
            warn_memory(sc, plan)
            protect.append(plan.road.net_file)
            if "," in os.path.abspath(out_dir):
                raise RunDirError(f"{out_dir}: SUMO splits file names at commas; choose an output "
                                  "directory without ',' for a road scenario")
            if warm_cache is not None:  # never a link, a file, or inside a run (sumo/warm_entry.py)
                from ..sumo.warm_entry import check_cache
                warm_cache = check_cache(warm_cache, Path(out_dir))
        lock = open_out_dir(Path(out_dir), force, protect)
        run_sc = sc if plan is None or plan.scenario is None else plan.scenario  # flows' formations in
        try:
            return _run_in(run_sc, Path(out_dir), src, plan, baseline, step_hook, transforms, progress,
                           stop, shown=sc, warm_cache=warm_cache)
        finally:
            lock.release()


def _run_in(sc, out_dir, src, plan, baseline, step_hook, transforms, progress, stop,
            shown=None, warm_cache=None) -> RunResult:
    """The run in its locked directory (see :func:`run_scenario`); ``shown``: the scenario as
    given (run.json 'scenario'), ``sc`` with its formation flows' formations."""
    stop.raising = False  # the record is set up whole: a signal now only sets the flag
    meta = run_meta(sc, None if src is None else str(src))
    if shown is not None and shown is not sc:
        meta["scenario"] = shown.model_dump(mode="json")
    meta["baseline"] = bool(baseline)
    if baseline:
        meta["baseline_mode"] = baseline
    if warm_cache is not None and sc.road is not None:
        from ..sumo.warm_state import not_shareable
        meta["warm_state"] = {"cache": str(Path(warm_cache).resolve()), "shared": False,
                              "unshared": not_shareable(sc)}
    meta_path = out_dir / "run.json"
    atomic_write_json(meta_path, meta)
    _reserve(out_dir, len(json_text(meta)))  # after run.json: on a small disk, all that is left
    rec = _recorder(sc, out_dir)
    n_steps = int(round(sc.run.duration / sc.run.step))

    status, reason, t, k = "completed", None, 0.0, 0
    bar = steps = None
    try:
        stop.raising = True  # compiling, starting SUMO, warm-up: a signal ends them at once
        if stop.is_set():
            raise Interrupted(stop.signame)
        if sc.open_loop is not None:
            from ..sim.open_loop import open_loop_steps
            steps = open_loop_steps(sc, rec, out_dir)
        else:
            if sc.road is None:
                build = lambda: with_comm(sc, free_space_run(sc, rec))  # noqa: E731
            else:
                from .road_parts import road_run
                build = lambda: with_comm(sc, road_run(sc, plan, rec, out_dir, meta, baseline,  # noqa: E731
                                                       step_hook, stop.is_set), baseline)
            steps = step_loop(sc, _with_transforms(build, transforms), rec, meta)
        for k, t in steps:
            stop.raising = False  # from the first step on, a signal ends the run after its step
            rec.end_step(k, t, lambda done: _progress_meta(  # every table on disk up to done [s]
                meta_path, meta, done, int(round(done / sc.run.step))))
            if bar is not None:
                bar.update(1)
            elif progress and k == 1:
                # the bar from the first step on: its ETA counts steps only (not compilation or
                # SUMO's warm-up), and tqdm's import (~25 ms) is not part of the start-up
                from tqdm import tqdm
                bar = tqdm(total=n_steps, initial=1, unit="step", desc=sc.name or "run", mininterval=0.5)
            if stop.is_set():
                break
    except Interrupted:
        pass  # stop.signame says which signal
    except ScenarioError:
        raise
    except Exception as exc:  # recorded, never lost: the status says what happened
        status, reason = "failed", describe_failure(exc)
        _try_write(out_dir / "error.txt", traceback.format_exc())
    finally:
        stop.raising = False
        if stop.is_set() and status == "completed":
            status, reason = "interrupted", f"{stop.signame} received"
        if bar is not None:
            bar.close()
        status, reason = _finish(meta_path, meta, rec, steps, status, reason, t, k)
    if status in RUN_FINISHED:
        from ..sim.warm import compile_every_kind
        compile_every_kind()  # a cold cache: the other scenario kinds' kernels too (sim/warm.py)
    return RunResult(out_dir, status, reason, float(meta["t_end"]), int(meta["steps_done"]),
                     meta["incidents"], meta["incident_summary"])


def _finish(meta_path, meta, rec, steps, status, reason, t, k):
    """Close SUMO, write what is buffered and the final run.json; never raises for a write
    that fails (disk full): the status and reason say so, the data on disk is described."""
    problems = []
    try:
        if steps is not None:
            steps.close()  # a SUMO loop closes SUMO here (SUMO completes its outputs)
    except Exception as exc:
        problems.append(("SUMO", exc))
    problems += rec.flush(t_end=float(t))
    on_disk = rec.on_disk()
    if problems and status != "failed":
        status, reason = "failed", "; ".join(f"{n}: {describe_failure(e)}" for n, e in problems)
    if status == "failed":
        done = [v["complete_to_s"] for v in on_disk.values()]
        if any(d is None for d in done) or any(d < t for d in done):  # not everything reached the disk
            t = min([0.0 if d is None else d for d in done], default=0.0)  # None: nothing of it on disk
            k = int(round(t / meta["record_step"]))
            reason += f"; the tables on disk are complete up to t = {t:.2f} s (run.json 'tables')"
    incidents = rec.incidents.counts()
    status, summary = verdict(status, incidents)  # completed -> completed_with_incidents
    if meta.get("baseline"):  # no member in the twin: the ghost virtual car's brakes are no incident
        status, summary = ("completed" if status == "completed_with_incidents" else status), None
    else:  # who, when and where (sim/incident_log.py)
        incidents.update(rec.incident_log.meta())
    meta.update(status=status, reason=reason, finished=_now(), t_end=float(t),
                steps_done=int(k), rows_written=rec.traj.rows_on_disk)
    meta["incidents"], meta["incident_summary"] = incidents, summary
    meta["tables"] = on_disk
    meta["event_counts"] = rec.event_counts
    lost = _write_final(meta_path, meta)
    if lost is not None:  # the terminal says it: run.json could not
        status, reason = "failed", f"{reason or status}; run.json not written: {lost}"
    return status, reason


def describe_failure(exc: BaseException) -> str:
    """One line for run.json: what failed; disk full said so plainly."""
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        where = f" writing {exc.filename}" if exc.filename else ""
        return f"disk full (no space left on device){where}"
    text = "; ".join(ln.strip() for ln in str(exc).splitlines() if ln.strip())  # one line (error.txt: all)
    return f"{type(exc).__name__}: {text}"


def _reserve(out_dir: Path, meta_bytes: int = 0) -> None:
    """Hold back :data:`RESERVE_BYTES`, or four times the first run.json (its members and
    scenario; the final one adds the tables and events) if that is more [B]; on a disk with
    less free, as much as there is (the run's tables then fail sooner, its run.json does not)."""
    left = max(RESERVE_BYTES, 4 * meta_bytes)
    block = b"\0" * (1 << 16)
    try:
        with open(out_dir / ".reserve", "wb", buffering=0) as f:  # unbuffered: each write lands or fails
            while left > 0:
                left -= f.write(block[:left])
    except OSError:
        pass  # what was written stays held


def _try_write(path: Path, text: str) -> None:
    try:
        path.write_text(text)
    except OSError:
        path.unlink(missing_ok=True)


def _write_final(meta_path: Path, meta: dict) -> str | None:
    """The final run.json into the space held back; never raises: on a disk too full even for
    that, run.json without its indentation, then in place of the previous one (its space
    freed first), so that it never stays 'running'. Returns why it could not be written."""
    (meta_path.parent / ".reserve").unlink(missing_ok=True)  # the space held back is for this write
    try:
        atomic_write_json(meta_path, meta)
        return None
    except OSError:
        text = json_text(meta, indent=None)
    try:
        atomic_write_text(meta_path, text)
        return None
    except OSError:
        pass
    try:
        with open(meta_path, "w") as f:
            f.write(text)
        return None
    except OSError as exc:
        return describe_failure(exc)


def _recorder(sc: Scenario, out_dir: Path) -> Recorder:
    """The run's tables: every formation's members, then one virtual car each."""
    views = formation_views(sc)
    vc_ids = [virtual_car_id(fid, len(views)) for fid, _ in views]
    formation_of = {m.id: fid for fid, view in views for m in view.members}
    formation_of.update({vc: fid for vc, (fid, _) in zip(vc_ids, views)})
    ids = [m.id for _, view in views for m in view.members]
    rec = Recorder(out_dir, ids, with_sumo=sc.road is not None,
                   periods_per_step=int(round(sc.run.step / sc.run.control_step)),
                   formation_of=formation_of, vc_ids=vc_ids)
    rec.incidents = Incidents(rec, ids, [v for _, view in views for v in member_vehicles(view)],
                              pairs=not (sc.run.independent_members and sc.road is None))
    return rec


def _with_transforms(build, transforms):
    def built():
        parts = build()
        if transforms and len(parts.formations) > 1:
            raise ValueError("transforms= apply to a run of one formation")
        parts.formations[0].transforms.extend(transforms)
        return parts
    return built


def _progress_meta(path, meta, t, k):
    meta.update(t_end=float(t), steps_done=int(k))
    atomic_write_json(path, meta)


# The objects of every module imported so far (numba, pydantic, the package) live as
# long as the process: moved out of the garbage collector's generations, no collection of the
# run and none of the interpreter's exit walks them again (0.2-0.4 s of a short run's start
# and exit). Objects that become garbage are freed as before (reference counts).
gc.freeze()
