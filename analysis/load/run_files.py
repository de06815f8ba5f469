"""Reading the files of a run directory: ``run.json`` and Parquet tables (a dataset
directory of part files or a single file), each problem reported as an :class:`Issue`
instead of raised. :mod:`analysis.load.run_data` builds a whole run on these.
"""
from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow.parquet as pq

__all__ = ["RUN_JSON", "TRAJECTORIES", "REQUIRED_META_KEYS", "Issue", "DamagedPartWarning",
           "describe_issues", "read_table", "read_meta"]

RUN_JSON = "run.json"
TRAJECTORIES = "trajectories.parquet"
REQUIRED_META_KEYS = ("status", "reason", "t_end", "record_step", "model", "mu", "members",
                      "scenario")

class DamagedPartWarning(RuntimeWarning):
    """Some Parquet part files could not be read and were skipped."""


@dataclass(frozen=True, slots=True)
class Issue:
    """One thing missing or damaged in a run, or one caveat of the analysis."""

    severity: str  # "error" (data lost/damaged), "warning" (result caveat), "info"
    kind: str  # short machine-readable category, e.g. "corrupt_part"
    what: str  # the file, key, column or member concerned
    detail: str  # human-readable explanation

    def as_dict(self) -> dict[str, str]:
        """Plain-dict form for JSON.

        Returns
        -------
        dict
            Keys ``severity``, ``kind``, ``what``, ``detail``.
        """
        return {"severity": self.severity, "kind": self.kind, "what": self.what,
                "detail": self.detail}


def describe_issues(issues) -> str:
    """One line counting the run's data issues by severity, the same in the CLI and the report.

    Parameters
    ----------
    issues : iterable
        :class:`Issue` objects or dicts with a ``severity``.

    Returns
    -------
    str
        e.g. ``"3 data issue(s): 0 error(s), 1 warning(s), 2 note(s)"``.
    """
    sev = [i["severity"] if isinstance(i, dict) else getattr(i, "severity", None) for i in issues]
    return (f"{len(sev)} data issue(s): {sev.count('error')} error(s), {sev.count('warning')} "
            f"warning(s), {sev.count('info')} note(s)")



def _part_files(path: Path) -> list[Path]:
    if path.is_file():
        return [path]
    files = []
    for p in sorted(path.rglob("*")):
        rel = p.relative_to(path).parts
        if p.is_file() and not any(s.startswith((".", "_")) for s in rel):
            files.append(p)
    return files


def read_table(path: str | Path, name: str | None = None) -> tuple[pd.DataFrame | None, list[Issue]]:
    """Read a Parquet dataset directory (or single file), skipping unreadable parts.

    Parameters
    ----------
    path : str or Path
        Dataset directory of part files, or one Parquet file. Files and directories
        whose name starts with ``.`` or ``_`` are ignored, as pyarrow does.
    name : str, optional
        Name used in issues; default the path's name.

    Returns
    -------
    (DataFrame or None, list of Issue)
        The concatenated rows of every readable part (None if there are none) and the
        problems met: missing table, empty dataset, unreadable parts (each listed).
        Unreadable parts also raise a :class:`DamagedPartWarning`.
    """
    path = Path(path)
    name = name or path.name
    if not path.exists():
        return None, [Issue("info", "missing_table", name, f"{path.name} does not exist")]
    parts = _part_files(path)
    if not parts:
        return None, [Issue("error", "empty_table", name, f"{path.name} has no part files")]
    frames, bad, issues = [], [], []
    for p in parts:
        try:
            frames.append(pq.read_table(p).to_pandas())
        except Exception as exc:  # noqa: BLE001 - any reader failure means a damaged part
            rel = p.relative_to(path.parent)
            bad.append(str(rel))
            issues.append(Issue("error", "corrupt_part", str(rel),
                                f"unreadable, skipped ({type(exc).__name__}: "
                                f"{str(exc).splitlines()[0][:200] if str(exc) else ''})"))
    if bad:
        warnings.warn(f"{name}: skipped {len(bad)} unreadable part file(s): {', '.join(bad)}",
                      DamagedPartWarning, stacklevel=2)
    frames = [f for f in frames if len(f.columns)]
    if not frames:
        return None, issues
    union = set().union(*(f.columns for f in frames))
    partial = sorted(c for c in union if any(c not in f.columns for f in frames))
    if partial:
        issues.append(Issue("error", "schema_mismatch", name,
                            f"column(s) {', '.join(partial)} absent from some part files; "
                            "their rows there are NaN"))
    df = pd.concat(frames, ignore_index=True, sort=False) if len(frames) > 1 else frames[0]
    return df, issues


_NUMBER = (int, float)
META_TYPES = {"status": (str,), "reason": (str, type(None)), "t_end": _NUMBER, "record_step": _NUMBER,
              "model": (str,), "mu": _NUMBER, "members": (list,), "scenario": (dict,), "duration": _NUMBER,
              "seed": (int,), "steps_done": (int,), "tables": (dict,), "event_counts": (dict,),
              "sumo": (dict,), "baseline": (bool,), "versions": (dict,)}
"""The JSON type of each run.json key the analysis reads; a key of another type is dropped
(listed as damage) and the analysis goes on as if it were missing."""


def _typed_meta(meta: dict[str, Any]) -> tuple[dict[str, Any], list[Issue]]:
    """``meta`` without the keys (and members) of the wrong JSON type, and an issue for each."""
    issues, out = [], dict(meta)
    for k, types in META_TYPES.items():
        v = out.get(k)
        if k in out and (not isinstance(v, types) or (types is _NUMBER and isinstance(v, bool))):
            issues.append(Issue("error", "invalid_meta_value", f"{RUN_JSON}:{k}",
                                f"expected {' or '.join(t.__name__ for t in types)}, got "
                                f"{type(v).__name__} ({str(v)[:40]}); ignored"))
            del out[k]
    if isinstance(out.get("members"), list):
        good = [m for m in out["members"] if isinstance(m, dict) and isinstance(m.get("id"), str)]
        if len(good) < len(out["members"]):
            issues.append(Issue("error", "invalid_meta_value", f"{RUN_JSON}:members",
                                f"{len(out['members']) - len(good)} member(s) without an object and "
                                "a string id; ignored"))
            out["members"] = good
    return out, issues


def read_meta(run_dir: str | Path) -> tuple[dict[str, Any], list[Issue]]:
    """Read and check ``run.json``.

    Parameters
    ----------
    run_dir : str or Path
        Run directory.

    Returns
    -------
    (dict, list of Issue)
        The parsed content (``{}`` when missing or unreadable) and the problems found:
        missing or invalid file, missing keys of :data:`REQUIRED_META_KEYS`, run status
        other than ``"completed"``.
    """
    p = Path(run_dir) / RUN_JSON
    if not p.is_file():
        return {}, [Issue("error", "missing_file", RUN_JSON,
                          "run.json is missing: status, model, mu, record_step and member "
                          "offsets are unknown; they are inferred from the trajectories "
                          "where possible")]
    try:
        meta = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return {}, [Issue("error", "invalid_file", RUN_JSON, f"unreadable: {exc}")]
    if not isinstance(meta, dict):
        return {}, [Issue("error", "invalid_file", RUN_JSON,
                          f"top level is {type(meta).__name__}, expected an object")]
    issues = [Issue("error", "missing_meta_key", f"{RUN_JSON}:{k}", f"key '{k}' is missing")
              for k in REQUIRED_META_KEYS if k not in meta]
    meta, type_issues = _typed_meta(meta)
    issues += type_issues
    status = meta.get("status")
    if status is not None and status not in ("completed", "completed_with_incidents"):
        why = {"interrupted": "the run was interrupted",
               "failed": "the run failed",
               "running": "the run has not finished (or died without writing its status)"}
        issues.append(Issue("warning", "run_status", f"{RUN_JSON}:status",
                            f"status '{status}': {why.get(status, 'unknown status')}"
                            + (f"; reason: {meta.get('reason')}" if meta.get("reason") else "")))
    return meta, issues
