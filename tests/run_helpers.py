"""Scaffolding shared by the tests that run the tool: the free-space scenario text, the command
line (in this process or as a real process), run.json and polling. Importable because pytest puts
tests/ on sys.path (tests/conftest.py makes that explicit)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from typer.testing import CliRunner

from formation_traci.cli import app

CLI = [sys.executable, "-m", "formation_traci.cli"]


def free_toml(duration, *, name: str | None = None, step: float | None = None,
              model: str = "kinematic") -> str:
    """One member 'a' behind a 20 m/s leader in free space (no SUMO); duration and step in s."""
    head = f'name = "{name}"\n' if name else ""
    step_line = f"step = {step}\n" if step is not None else ""
    return (f"{head}[run]\nduration = {duration}\n{step_line}[vehicle]\nmodel = \"{model}\"\n"
            "[leader]\nspeed = 20.0\n[[members]]\nid = \"a\"\noffset = [0.0, 3.5]\n"
            "position = [-2.0, 2.0]\n")


def _runner() -> CliRunner:
    """A runner whose ``output`` holds stdout and stderr in the order they were written (click
    >= 8.2 always; before, with mix_stderr): the terminal's last lines are the last lines."""
    try:
        return CliRunner(mix_stderr=True)
    except TypeError:  # click >= 8.2: no mix_stderr, output is both streams in order
        return CliRunner()


def cli(*args, cwd=None):
    """The real command line in this process: (exit code, stdout + stderr)."""
    old = os.getcwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        res = _runner().invoke(app, [str(a) for a in args])
    finally:
        os.chdir(old)
    text = res.output  # stdout and stderr in the order a terminal shows them
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        text += f"\nTraceback: {type(res.exception).__name__}: {res.exception}"
    return res.exit_code, text


def spawn(*args, **kw) -> subprocess.Popen:
    """The command line as a real process, stdout and stderr as text pipes unless given."""
    kw.setdefault("stdout", subprocess.PIPE)
    kw.setdefault("stderr", subprocess.PIPE)
    return subprocess.Popen([*CLI, *map(str, args)], text=True, **kw)


def meta_of(out: Path) -> dict:
    """run.json of the run in out, {} while it is missing or half-written."""
    try:
        return json.loads((out / "run.json").read_text())
    except (OSError, ValueError):
        return {}


def wait_for(cond, timeout=120.0, every=0.05) -> bool:
    """Poll cond every `every` s until it holds (True) or timeout s pass (False)."""
    end = time.time() + timeout
    while time.time() < end:
        if cond():
            return True
        time.sleep(every)
    return False


RUN_KEYS = ("incidents", "incident_summary", "event_counts", "tables", "stopped_early", "t_end")
"""run.json entries two runs of one scenario must share (the compiled step against the loop's)."""


def same_run_files(a: Path, b: Path) -> set[str]:
    """Assert that the runs in ``a`` and ``b`` have the same run.json entries (:data:`RUN_KEYS`)
    and the same part files byte for byte; returns the parts' relative paths."""
    ma, mb = (json.loads((d / "run.json").read_text()) for d in (a, b))
    for key in RUN_KEYS:
        assert ma.get(key) == mb.get(key), key
    parts = {p.relative_to(a).as_posix() for p in a.rglob("*.parquet") if p.is_file()}
    assert parts == {p.relative_to(b).as_posix() for p in b.rglob("*.parquet") if p.is_file()}
    for part in sorted(parts):
        assert (a / part).read_bytes() == (b / part).read_bytes(), part
    return parts

