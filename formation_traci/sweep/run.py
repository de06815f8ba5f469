"""``run_sweep``: expand a sweep file, run the cases not yet done, keep the summary current.

Layout of the sweep directory (docs/sweeps.md): ``sweep.json``, ``summary.parquet``,
``cases/<case-id>/`` (the run, its metrics and ``case.json``), ``logs/<case-id>.log``.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import fcntl
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from run_contract.errors import SweepError
from run_contract.rundir import RUN_FINISHED

from ..core.interrupt import raising_signals
from ..record.writer import atomic_write_json, atomic_write_parquet
from .case import CASE_JSON, CaseSpec
from .executors import run_dask, run_local
from .expand import Sweep, load_sweep
from .row import METRICS, WALL_COLUMNS, summary_frame, swept_dtypes
from ..run.twins import twin_mode

SCHEMA = "formation-traci/sweep/1"
SWEEP_JSON = "sweep.json"
SUMMARY = "summary.parquet"
CASES_DIR = "cases"
LOGS_DIR = "logs"
TWINS_DIR = "twins"
WARMUPS_DIR = "warmups"
"""The shared warm-ups: SUMO's saved state per warm-up key (sumo/warm_state.py)."""
EFFECTS_CSV = "effects.csv"
MEANS_CSV = "means.csv"
"""Per grid point the section measures' mean over the seeds and 95 % interval (road sweeps)."""
TIMINGS = "timings.parquet"
"""Per case the wall-clock columns (``row.WALL_COLUMNS``): kept out of summary.parquet, so the
same sweep gives the same summary.parquet byte for byte however often it was stopped and resumed."""
LOCK_FILE = ".sweep.lock"
WRITE_EVERY_S = 2.0
"""The summary is rewritten at most this often while cases finish, and always at the end [s]."""


@dataclass(frozen=True)
class SweepResult:
    """What :func:`run_sweep` did."""

    out_dir: Path
    summary: pd.DataFrame  # one row per case with a result, by case index (summary.parquet + timings.parquet)
    n_cases: int  # cases of the sweep
    n_completed: int  # rows with status completed (this and earlier invocations)
    n_failed: int  # rows with status failed or interrupted (not completed)
    n_skipped: int  # completed earlier with the same overrides: not run again
    n_run: int  # cases run by this invocation
    files: dict[str, Path]  # "sweep_json", "summary"


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


SWEEP_FILES = frozenset({SWEEP_JSON, SUMMARY, TIMINGS, CASES_DIR, LOGS_DIR, LOCK_FILE, WARMUPS_DIR, TWINS_DIR,
                         EFFECTS_CSV, MEANS_CSV, "sweep_report.html", "sweep_stats.csv", "sweep_figures"})
"""Names a sweep (and ``analyze-sweep``) writes at the top of its directory."""


def _check_sweep_dir(out: Path) -> Path:
    """``out`` (absolute) if a sweep may write there: missing, empty, or an earlier sweep of
    this tool holding only its files (a rerun finishes it); else SweepError, nothing written."""
    from run_contract.rundir import TOOL_TEMP, RunDirError, check_path

    try:
        absolute = check_path(out)
    except RunDirError as exc:
        raise SweepError(out, [("--out", str(exc))]) from None
    if not absolute.is_dir():
        return absolute
    entries = sorted(absolute.iterdir())
    if not [p for p in entries if p.name != LOCK_FILE]:
        return absolute
    try:
        ours = json.loads((absolute / SWEEP_JSON).read_text(encoding="utf-8")).get("schema") == SCHEMA
    except (OSError, ValueError, AttributeError):
        ours = False
    if not ours and not all(p.name in SWEEP_FILES and not p.is_symlink() for p in entries):
        raise SweepError(out, [("--out", "is not empty and not an earlier sweep of formation-traci (no "
                                         "sweep.json written by it): nothing written; choose another directory")])
    foreign = [p.name for p in entries if p.is_symlink() or (p.name not in SWEEP_FILES and not TOOL_TEMP.match(p.name))]
    if foreign:
        raise SweepError(out, [("--out", f"holds files formation-traci did not write ({', '.join(foreign[:5])}): "
                                         "nothing written; choose another directory")])
    return absolute.resolve()


@contextlib.contextmanager
def _lock(out: Path):
    try:
        fd = os.open(out / LOCK_FILE, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise SweepError(out, [("(directory)", f"cannot open {LOCK_FILE}: {exc.strerror} (a symbolic "
                                               "link is never followed)")]) from None
    with os.fdopen(fd, "a+") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise SweepError(out, [("(directory)", "another sweep is running in this directory")]) from None
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def case_spec(sweep: Sweep, index: int, out: Path, baseline: bool | str = False,
              shared_warmup: bool = False) -> CaseSpec:
    """The :class:`CaseSpec` of one case.

    Parameters
    ----------
    sweep : Sweep
        The loaded sweep.
    index : int
        Case index.
    out : Path
        Sweep directory (absolute).
    baseline : bool or str
        The case's twin runs too, into ``out/twins/<id>``: ``"same"`` (or True) or ``"absent"``
        (formation_traci/run/twins.py).
    shared_warmup : bool
        Road cases start from their warm-up's saved state in ``out/warmups`` (simulated once
        per warm-up key; docs/sweeps.md, "The shared warm-up").

    Returns
    -------
    CaseSpec
        The case with its scenario, case directory and log paths.
    """
    case = sweep.cases[index]
    return CaseSpec(case=case, base=str(sweep.base), case_dir=str(out / CASES_DIR / case.id),
                    log_path=str(out / LOGS_DIR / f"{case.id}.log"),
                    twin_dir=str(out / TWINS_DIR / case.id) if baseline else None,
                    twin_mode=twin_mode(baseline) or "same",
                    warm_dir=str(out / WARMUPS_DIR) if shared_warmup else None)


def _previous(spec: CaseSpec) -> tuple[dict | None, bool]:
    """The stored row of this case if it was run with the same scenario and overrides,
    and whether it counts as done (row and run.json both completed)."""
    d = Path(spec.case_dir)
    try:
        doc = json.loads((d / CASE_JSON).read_text(encoding="utf-8"))
        old = CaseSpec.model_validate(doc["spec"])
        row = doc["row"]
    except Exception:
        return None, False
    if old.case != spec.case or old.base != spec.base or old.twin_dir != spec.twin_dir \
            or (spec.twin_dir is not None and old.twin_mode != spec.twin_mode) \
            or (old.warm_dir is None) != (spec.warm_dir is None) \
            or row.get("case_id") != spec.case.id:
        return None, False
    try:
        run_ok = json.loads((d / "run.json").read_text(encoding="utf-8")).get("status") in RUN_FINISHED
    except (OSError, ValueError):
        run_ok = False
    twin_ok = spec.twin_dir is None or row.get("twin_status") in RUN_FINISHED  # a failed twin: again
    return row, bool(run_ok and row.get("status") in RUN_FINISHED and twin_ok)


def _versions() -> dict[str, str]:
    from ..run.scenario_run import versions

    return versions(("dask", "distributed"))


def _write_summary(path: Path, rows: dict[str, dict], swept: dict[str, str],
                   effects: Path | None = None) -> pd.DataFrame:
    """summary.parquet and timings.parquet (atomically); with ``effects``, the paired effects
    over the seeds there too (sweeps with twins, analysis/report/effects.py). Returns the
    summary with the wall-clock columns."""
    df = summary_frame(list(rows.values()), swept)
    atomic_write_parquet(path, df.drop(columns=list(WALL_COLUMNS)))
    atomic_write_parquet(path.with_name(TIMINGS), df[["case_id", *WALL_COLUMNS]])
    from analysis.report.effects import write_effects, write_means

    if effects is not None:
        write_effects(df, list(swept), effects)
    write_means(df, list(swept), path.with_name(MEANS_CSV))
    return df


def run_sweep(sweep_path: str | Path, out_dir: str | Path, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True, baseline: bool | str = False,
              sets: dict | None = None, shared_warmup: bool = False) -> SweepResult:
    """Run every case of a sweep file that is not done yet and summarise them.

    Parameters
    ----------
    sweep_path : str or Path
        Sweep TOML file (docs/sweeps.md).
    out_dir : str or Path
        Sweep directory, created if needed. Running again into the same directory skips
        the cases whose ``cases/<id>/run.json`` and stored row say completed with the
        same overrides, and runs the others (failed, interrupted, new or changed).
    scheduler : str, optional
        Dask scheduler address (``tcp://HOST:PORT``) or scheduler-file path; default: a
        local pool on this machine. Workers need this package installed and ``out_dir``
        on a shared filesystem at the same path.
    workers : int, optional
        Local pool only: cases run at once (default ``os.cpu_count()``).
    progress : bool
        Show a progress bar (cases done, failed, remaining).
    baseline : bool or str
        Also run each case's twin (``"same"``/True, ``"absent"``; default the sweep file's) into ``twins/<id>/``, analyse the case
        against it (the paired ``fx_*`` summary columns) and write ``effects.csv``.
    sets : dict, optional
        Dotted path -> value set in every case (``--set``), checked before anything is created.
    shared_warmup : bool
        Cases and twins of a warm-up key start from its SUMO state in ``warmups/`` (docs/sweeps.md).

    Returns
    -------
    SweepResult
        The summary table and counts. ``summary.parquet`` holds one row per case with a
        result (see docs/sweeps.md for the columns).

    Raises
    ------
    SweepError
        If the sweep file is invalid, another sweep is running in ``out_dir``, or the Dask
        scheduler cannot be reached.
    Interrupted
        On Ctrl-C or SIGTERM, after the running cases stopped and the summary was written.
    """
    sweep = load_sweep(sweep_path, sets)
    baseline = baseline or sweep.spec.baseline or False  # the sweep file's twin unless given
    _refuse_on_free_space(sweep, {"--baseline": baseline, "--shared-warmup": shared_warmup})
    out = _make_sweep_dir(Path(out_dir))
    with raising_signals(), _lock(out):  # SIGTERM stops the cases like Ctrl-C
        specs = [case_spec(sweep, i, out, baseline, shared_warmup) for i in range(len(sweep.cases))]
        swept = swept_dtypes([c.model_dump(mode="json") for c in sweep.cases], sweep.spec.swept())
        rows, todo = _resume(specs)
        n_skipped = len(specs) - len(todo)
        meta = _sweep_meta(sweep, swept, scheduler, workers, len(specs), n_skipped, len(todo), baseline, shared_warmup)
        atomic_write_json(out / SWEEP_JSON, meta)
        summary_path = out / SUMMARY
        _write_summary(summary_path, rows, swept)
        bar = _progress_bar(sweep, len(specs), n_skipped) if progress else None
        on_row = _RowSink(rows, len(todo), bar, summary_path, swept)

        interrupted = None  # stays None if the executor raised (e.g. no scheduler there)
        try:
            if scheduler:
                interrupted = run_dask(todo, scheduler, sweep.spec.timeout_s, on_row)
            else:
                interrupted = run_local(todo, workers, sweep.spec.timeout_s, on_row)
        finally:
            if bar is not None:
                bar.close()
            df = _write_summary(summary_path, rows, swept, out / EFFECTS_CSV if baseline else None)
            n_ok = int(df["status"].isin(RUN_FINISHED).sum())
            _finish_meta(meta, df, interrupted, on_row.ok + on_row.failed, len(specs))
            atomic_write_json(out / SWEEP_JSON, meta)
    if interrupted:
        from ..core.interrupt import Interrupted
        raise Interrupted(interrupted if isinstance(interrupted, str) else "SIGINT")
    files = {"sweep_json": out / SWEEP_JSON, "summary": summary_path, "effects": out / EFFECTS_CSV}
    return SweepResult(out_dir=out, summary=df, n_cases=len(specs), n_completed=n_ok, n_failed=len(df) - n_ok,
                       n_skipped=n_skipped, n_run=on_row.ok + on_row.failed,
                       files={k: v for k, v in files.items() if k != "effects" or baseline})


def _refuse_on_free_space(sweep: Sweep, options: dict[str, bool]) -> None:
    """SweepError before anything is created: ``--baseline`` (a twin without the formation in
    the same traffic) or ``--shared-warmup`` given for a base scenario without a [road] that no
    case gives one (free space has neither: the option would be ignored)."""
    from ..scenario.load import read_toml

    given = [name for name, on in options.items() if on]
    paths = set(sweep.spec.overrides) | set(sweep.sets) | set(sweep.spec.swept())
    if given and read_toml(sweep.base).get("road") is None and not any(p.split(".")[0] == "road" for p in paths):
        raise SweepError(sweep.path, [(name, f"needs a road scenario (SUMO's traffic): {sweep.base} has no "
                                             "[road]") for name in given])


def _make_sweep_dir(out: Path) -> Path:
    """The sweep directory, checked like a run's (:func:`_check_sweep_dir`) and created."""
    out = _check_sweep_dir(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SweepError(out, [("(directory)", f"cannot be created: {exc.strerror}")]) from None
    return out


def _resume(specs: list[CaseSpec]) -> tuple[dict[str, dict], list[CaseSpec]]:
    """Rows stored by earlier invocations (by case id), and the cases still to run."""
    rows: dict[str, dict] = {}
    todo = []
    for s in specs:
        row, done = _previous(s)
        if row is not None:
            rows[s.case.id] = row
        if not done:
            todo.append(s)
    return rows, todo


def _sweep_meta(sweep: Sweep, swept: dict[str, str], scheduler: str | None, workers: int | None,
                n_cases: int, n_skipped: int, n_todo: int, baseline: bool = False,
                shared_warmup: bool = False) -> dict:
    """The content of ``sweep.json`` when the sweep starts (status running)."""
    return {"schema": SCHEMA, "status": "running", "sweep_file": str(sweep.path),
            "sweep_text": sweep.path.read_text(encoding="utf-8"), "sweep": sweep.raw,
            "base": str(sweep.base), "swept": sweep.spec.swept(), "grid_keys": list(sweep.spec.grid),
            "random_keys": list(sweep.random_keys), "sets": sweep.sets,
            "baseline": bool(baseline), "baseline_mode": twin_mode(baseline), "shared_warmup": shared_warmup, "dtypes": swept,
            "metrics": {k: {"unit": u, "meaning": m} for k, (u, m) in METRICS.items()},
            "executor": {"kind": "dask" if scheduler else "local", "scheduler": scheduler,
                         "workers": None if scheduler else (workers or os.cpu_count())},
            "cases": [c.model_dump(mode="json") for c in sweep.cases],
            "versions": _versions(), "started": _now(), "finished": None,
            "counts": {"cases": n_cases, "skipped": n_skipped, "to_run": n_todo}}


def _progress_bar(sweep: Sweep, n_cases: int, n_skipped: int):
    from tqdm import tqdm

    return tqdm(total=n_cases, initial=n_skipped, unit="case",
                desc=sweep.spec.name or sweep.path.stem)


def _finish_meta(meta: dict, df: pd.DataFrame, interrupted: bool | str | None, n_run: int,
                 n_cases: int) -> None:
    """``sweep.json`` at the end: final status (error when the executor raised), finish
    time and counts per status."""
    meta.update(status="error" if interrupted is None else "interrupted" if interrupted else "completed",
                finished=_now())
    if interrupted:
        meta["reason"] = f"{interrupted if isinstance(interrupted, str) else 'SIGINT'} received"
    meta["counts"].update(run=n_run, pending=n_cases - len(df),
                          **{s: int((df["status"] == s).sum())
                             for s in ("completed", "completed_with_incidents", "failed",
                                       "interrupted")},
                          twins_failed=int((df["twin_status"].notna()
                                            & ~df["twin_status"].isin(RUN_FINISHED)).sum()))


class _RowSink:
    """Takes each finished case's row: keeps it, counts it, moves the progress bar and
    rewrites the summary at most every :data:`WRITE_EVERY_S`."""

    def __init__(self, rows: dict[str, dict], n_todo: int, bar, summary_path: Path,
                 swept: dict[str, str]):
        self.rows, self.n_todo, self.bar = rows, n_todo, bar
        self.summary_path, self.swept = summary_path, swept
        self.ok = self.failed = 0
        self.written = time.monotonic()

    def __call__(self, spec: CaseSpec, row: dict) -> None:
        self.rows[spec.case.id] = row
        if row["status"] in RUN_FINISHED:
            self.ok += 1
        else:
            self.failed += 1
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(done=self.ok, failed=self.failed,
                                 remaining=self.n_todo - self.ok - self.failed)
        if time.monotonic() - self.written >= WRITE_EVERY_S:
            _write_summary(self.summary_path, self.rows, self.swept)
            self.written = time.monotonic()
