"""One sweep case in this process: load, run, analyse, summarise.

``python -m formation_traci.sweep.case SPEC_JSON`` is how every executor runs a case (one
process per case, so one libsumo simulation per process). The process writes the case's
row to ``<case_dir>/case.json`` and exits 0 whatever happened to the run; a non-zero exit
means the process itself broke (the launcher records that).
"""
from __future__ import annotations

import json
import math
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict

from run_contract.rundir import RUN_FINISHED, DirLock, clear_run

from .expand import Case
from .row import empty_row, metric_values, traffic_only_values, twin_values

CASE_JSON = "case.json"
"""Per-case record in the case directory: ``{"spec": ..., "row": ...}``."""


class CaseSpec(BaseModel):
    """Everything a case process needs: the case, the base scenario, where to write."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    case: Case
    base: str  # absolute path of the scenario file
    case_dir: str  # absolute path of DIR/cases/<id>
    log_path: str  # absolute path of DIR/logs/<id>.log (written by the launcher)
    twin_dir: str | None = None  # absolute path of DIR/twins/<id> when the case's twin runs too
    twin_mode: Literal["same", "absent"] = "same"  # which twin (runner.run_scenario's baseline)
    warm_dir: str | None = None  # absolute path of DIR/warmups: the shared warm-ups (None: off)


def _plain(x: Any) -> Any:
    """NaN/inf -> None, numpy scalars -> Python, so the row is strict JSON."""
    if hasattr(x, "item") and not isinstance(x, (list, dict, str)):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def write_case_json(case_dir: Path, spec: CaseSpec, row: dict) -> None:
    """Write ``case.json`` atomically (spec and row; NaN stored as null).

    Parameters
    ----------
    case_dir : Path
        Case directory (created if needed).
    spec : CaseSpec
        The case as run.
    row : dict
        Its summary row.

    Returns
    -------
    None
    """
    from ..record.writer import atomic_write_json

    case_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_json(case_dir / CASE_JSON, {"spec": spec.model_dump(mode="json"),
                                             "row": {k: _plain(v) for k, v in row.items()}})


def run_case(case_spec: dict | CaseSpec) -> dict[str, Any]:
    """Run one case here: load the scenario with the overrides, run, analyse, summarise.

    Parameters
    ----------
    case_spec : dict or CaseSpec
        The case (id, values, seed, overrides), the base scenario path and the case
        directory (replaced if it exists).

    Returns
    -------
    dict
        The summary row (docs/sweeps.md, "summary.parquet"); also written to
        ``<case_dir>/case.json``. Never raises for a failing case: an invalid scenario,
        a failed run or a failed analysis gives ``status = "failed"`` and the reason.
    """
    spec = CaseSpec.model_validate(case_spec)
    case = spec.case.model_dump(mode="json")
    out = Path(spec.case_dir)
    row = empty_row(case, "failed", None)
    try:
        if out.exists():  # the case directory belongs to the sweep: a retry starts clean
            with DirLock(out):  # RunDirBusy if the case still runs in another process
                clear_run(out)
        from ..scenario import ScenarioError, load_scenario
        from ..run.scenario_run import run_scenario

        try:
            sc = load_scenario(spec.base, **spec.case.overrides)
        except ScenarioError as exc:
            row["reason"] = str(exc)
            return row
        res = run_scenario(sc, out, scenario_path=spec.base, force=True, progress=False,
                           warm_cache=spec.warm_dir)
        row.update(status=res.status, reason=res.reason, t_end_s=res.t_end)
        twin = _run_twin(sc, spec, row, res.status) if spec.twin_dir is not None else None
        row.update(_analyse(out, row, twin))
    except KeyboardInterrupt as exc:  # SIGINT/SIGTERM before the run stepped (set-up, warm-up)
        row.update(status="interrupted", reason=str(exc) or "SIGINT received",
                   t_end_s=row.get("t_end_s") if row.get("t_end_s") is not None else 0.0)
    except Exception as exc:  # anything else: recorded, never lost
        row.update(status="failed", reason=f"{type(exc).__name__}: {exc}")
        traceback.print_exc()
    finally:
        write_case_json(out, spec, row)
    return row


def _run_twin(sc, spec: CaseSpec, row: dict, status: str) -> Path | None:
    """The case's twin (same scenario and seed; ``spec.twin_mode``) into ``spec.twin_dir``,
    after the formation run in this process (one libsumo simulation at a time), whatever the
    case's status (but interrupted). Its outcome goes to the row's ``twin_status`` and
    ``twin_reason``; a twin that did not reach its end leaves the case's paired columns NaN
    and its status as it was. Returns the twin's directory when it can be compared."""
    from ..run.scenario_run import run_scenario

    if status == "interrupted":
        row.update(twin_status="not run", twin_reason="the case was interrupted")
        return None
    twin = Path(spec.twin_dir)
    try:
        if twin.exists():
            with DirLock(twin):
                clear_run(twin)
        if _shared_warmup(Path(spec.case_dir)):  # SUMO's state loads as in a fresh process only
            t_status, reason = _twin_process(spec)
        else:
            res = run_scenario(sc, twin, scenario_path=spec.base, force=True, progress=False,
                               baseline=spec.twin_mode)
            t_status, reason = res.status, res.reason
    except KeyboardInterrupt:
        raise
    except Exception as exc:  # the twin's failure is the twin's, recorded with the case
        t_status, reason = "failed", f"{type(exc).__name__}: {exc}"
    row.update(twin_status=t_status, twin_reason=reason)
    if t_status == "interrupted":  # the sweep is stopping: the case runs again on a rerun
        row.update(status="interrupted", reason=f"its twin was interrupted: {reason}")
    return twin if t_status in RUN_FINISHED else None


def _shared_warmup(run_dir: Path) -> bool:
    """The run in ``run_dir`` started from a shared warm-up (run.json ``warm_state``)."""
    try:
        meta = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return bool((meta.get("warm_state") or {}).get("shared"))


def _twin_process(spec: CaseSpec) -> tuple[str, str | None]:
    """The twin of a case whose warm-up was shared, in a process of its own (``--twin``): a
    process that ran a simulation loads SUMO's state differently (sumo/warm_state.py)."""
    import subprocess

    res = subprocess.run([sys.executable, "-m", "formation_traci.sweep.case", "--twin",
                          spec.model_dump_json()], capture_output=True, text=True)
    if res.returncode != 0:
        return "failed", f"twin process exit {res.returncode}: {(res.stderr or res.stdout).strip()[-1000:]}"
    doc = json.loads(res.stdout.strip().splitlines()[-1])
    return doc["status"], doc["reason"]


def twin_main(spec_json: str) -> int:
    """``--twin``: the case's twin here, from the shared warm-up; prints its status as JSON.

    Parameters
    ----------
    spec_json : str
        The case's CaseSpec as JSON text.

    Returns
    -------
    int
        Exit code: 0 once the twin ran (whatever its status).
    """
    from ..scenario import load_scenario
    from ..run.scenario_run import run_scenario

    spec = CaseSpec.model_validate_json(spec_json)
    sc = load_scenario(spec.base, **spec.case.overrides)
    res = run_scenario(sc, Path(spec.twin_dir), scenario_path=spec.base, force=True, progress=False,
                       baseline=spec.twin_mode, warm_cache=spec.warm_dir)
    print(json.dumps({"status": res.status, "reason": res.reason}))
    return 0


def _analyse(run_dir: Path, row: dict, twin: Path | None = None) -> dict[str, Any]:
    from analysis.api import analyze_run
    from analysis.load.run_data import NoTrajectoryData
    from analysis.runs.traffic_only import no_formation_entered

    try:
        a = analyze_run(run_dir, figures=False, baseline=twin)
    except NoTrajectoryData as exc:
        if row["status"] not in RUN_FINISHED:
            return {}
        return {"status": "failed", "reason": f"analysis: {exc}"}
    meta = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
    if no_formation_entered(meta) and a.members.empty:  # e.g. a penetration study's 0 %: traffic alone
        out = traffic_only_values(run_dir, meta)
    else:
        out = metric_values(run_dir, a.members, meta, _formations(run_dir))
    if twin is not None:
        out.update(twin_values(_traffic_run(run_dir)))
    return out


def _formations(run_dir: Path) -> list:
    """metrics.json's ``formations`` records as written by the analysis."""
    try:
        return json.loads((run_dir / "metrics.json").read_text(encoding="utf-8")).get("formations") or []
    except (OSError, ValueError):
        return []


def _traffic_run(run_dir: Path) -> dict:
    """metrics.json's ``traffic.run`` as written by the analysis."""
    try:
        doc = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
        return (doc.get("traffic") or {}).get("run") or {}
    except (OSError, ValueError):
        return {}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the case process: ``SPEC_JSON`` is the CaseSpec as JSON text.

    Parameters
    ----------
    argv : list of str, optional
        ``[SPEC_JSON]``; default ``sys.argv[1:]``.

    Returns
    -------
    int
        Exit code: 0 once the row is written (whatever the run's status), 2 for bad usage.
    """
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) == 2 and argv[0] == "--twin":
        return twin_main(argv[1])
    if len(argv) != 1:
        print("usage: python -m formation_traci.sweep.case SPEC_JSON", file=sys.stderr)
        return 2
    t0 = time.monotonic()
    row = run_case(json.loads(argv[0]))
    print(f"{row['case_id']}: {row['status']} in {time.monotonic() - t0:.1f} s"
          + (f"\n{row['reason']}" if row["reason"] else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
