"""Command line: ``formation-traci run|analyze|compare``; each a thin layer over a library call.

Every command ends with exit 0 (done), 1 (the run or the work failed; the reason is printed
and recorded), 2 (bad input: nothing created) or 130 (SIGINT/SIGTERM). No traceback reaches
the user unless ``--debug`` is given (docs/reliability.md).
"""
from __future__ import annotations

import os
import sys

from .core.interrupt import Interrupted, exit_130_on_signals, raising_signals

if __name__ == "__main__" or os.path.basename(sys.argv[0]) == "formation-traci":
    exit_130_on_signals()  # (formation_traci/__init__.py did so already, before any import)

import contextlib  # noqa: E402
import re  # noqa: E402
import traceback  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Optional  # noqa: E402

import typer  # noqa: E402
import typer.core  # noqa: E402

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Formation control experiments: run scenarios, analyse recordings.")
_DEBUG = {"on": False}


from .run.twins import TWIN_MODES  # noqa: E402


def _twin_mode_args(args: list[str]) -> list[str]:
    """A bare ``--baseline`` (not followed by a mode) means ``--baseline same``."""
    out = []
    for i, a in enumerate(args):
        out.append(a)
        if a == "--baseline" and (i + 1 == len(args) or args[i + 1] not in TWIN_MODES):
            out.append(TWIN_MODES[0])
    return out


class _TwinModeCommand(typer.core.TyperCommand):
    """A command whose ``--baseline`` takes an optional mode."""

    def parse_args(self, ctx, args):
        return super().parse_args(ctx, _twin_mode_args(list(args)))


def _print_version(value: bool) -> None:
    if value:
        from . import __version__
        typer.echo(f"formation-traci {__version__}")
        raise typer.Exit(0)


@app.callback()
def _group(debug: bool = typer.Option(False, "--debug", help="show the traceback of an error"),
           version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                        help="print the version and exit")) -> None:
    """Formation control experiments: run scenarios, analyse recordings."""
    _DEBUG["on"] = debug
    import warnings

    warnings.showwarning = _one_line_warning


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings (e.g. a damaged part file) as one line on stderr, without Python's source line."""
    typer.echo(f"warning: {message}", err=True)


_BAD_INPUT = (("run_contract.errors", "SweepError"), ("formation_traci.scenario.load", "ScenarioError"),
              ("run_contract.rundir", "RunDirError"), ("analysis.load.run_data", "NoTrajectoryData"))
"""(module, class) of the errors that are bad input (exit 2)."""


def _bad_input_types() -> tuple[type, ...]:
    """The bad-input error classes of the modules already imported: an error of a module never
    imported was never raised, and importing one here would cost a bad scenario the analysis
    package's ~1.7 s before its message."""
    return tuple(getattr(sys.modules[m], name) for m, name in _BAD_INPUT if m in sys.modules)


def _nonempty(value):
    """Typer callback of --out and directory arguments: an empty string is not the working
    directory (bad input, exit 2)."""
    if value is not None and str(value) == "":
        raise typer.BadParameter("is empty: give a directory")
    return value


@contextlib.contextmanager
def _outcome():
    """Map what a command raises to its exit code and a one-paragraph message; inside,
    SIGINT and SIGTERM raise Interrupted (a run turns them into its own stop flag)."""
    try:
        with raising_signals():
            yield
    except typer.Exit:
        raise
    except KeyboardInterrupt as exc:  # Interrupted too
        name = exc.signame if isinstance(exc, Interrupted) else "SIGINT"
        typer.echo(f"interrupted: {name} received", err=True)
        raise typer.Exit(130)
    except Exception as exc:
        if _DEBUG["on"]:
            traceback.print_exc()
        if isinstance(exc, _bad_input_types()):
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(2)
        what = f"{exc.strerror}: {exc.filename}" if isinstance(exc, OSError) and exc.filename else str(exc)
        typer.echo(f"error: {type(exc).__name__}: {what}" + ("" if _DEBUG["on"] else
                   "\n(run with --debug for the traceback)"), err=True)
        raise typer.Exit(1)


SET_HELP = ("set a scenario field by its dotted path, e.g. --set run.duration=20 --set "
            "traffic.flows.0.veh_per_hour_per_lane=1200 (repeatable; VALUE is read as TOML, "
            "else as text)")


def _set_overrides(pairs: Optional[list[str]], source: str) -> dict:
    """``KEY=VALUE`` strings -> {dotted path: value}; VALUE is a TOML value (``20``, ``1.5``,
    ``true``, ``"x"``, ``[1, 2]``, ``{ a = 1 }``), else the text itself. A malformed pair
    raises ScenarioError (exit 2, nothing created); the values are validated by the scenario
    schema when the scenario is loaded with them."""
    import tomllib

    from .scenario import ScenarioError
    from .sweep.spec import DOTTED

    out, problems = {}, []
    for pair in pairs or []:
        key, eq, text = pair.partition("=")
        key = key.strip()
        if not eq or not re.match(DOTTED, key):
            problems.append((f"--set {pair}", "expected KEY=VALUE with KEY a dotted scenario path "
                                              "(e.g. run.duration=20)"))
            continue
        try:
            doc = tomllib.loads(f"v = {text.strip()}")
        except tomllib.TOMLDecodeError:
            doc = {"v": text.strip()}
        if set(doc) != {"v"}:  # e.g. '1\n[x]': the value, then more TOML
            problems.append((f"--set {key}", "VALUE must be one TOML value; found more after it "
                                             f"({', '.join(k for k in doc if k != 'v')})"))
            continue
        if key in out:
            problems.append((f"--set {key}", "is given twice"))
        out[key] = doc["v"]
    if problems:
        raise ScenarioError(source, problems)
    return out


_OPTION_OF = {"run.duration": "--duration", "run.seed": "--seed", "vehicle.model": "--model",
              "sumo.backend": "--gui", "sumo.gui": "--gui"}


def _refuse_both(sets: dict, opts: dict, source: str) -> None:
    """ScenarioError (exit 2) for a field given both by a command-line option and by --set."""
    from .scenario import ScenarioError

    both = [k for k in opts if k in sets]
    if both:
        raise ScenarioError(source, [(f"--set {k}", f"is also given by {_OPTION_OF[k]}: give it once")
                                     for k in both])


def _refuse_new_road(sets: dict, scenario: Path) -> None:
    """ScenarioError (exit 2) for ``--set road.*`` on a scenario without [road]: --set changes
    a scenario's fields, it does not turn free space into a road run."""
    from .scenario import ScenarioError
    from .scenario.load import read_toml

    road = [k for k in sets if k.split(".")[0] == "road"]
    if road and Path(scenario).is_file() and read_toml(Path(scenario)).get("road") is None:
        raise ScenarioError(scenario, [(f"--set {k}", "the scenario has no [road] (free space): --set changes "
                                                      "its fields, it does not make it a road scenario") for k in road])


@app.command(cls=_TwinModeCommand)
def run(
    scenario: Path = typer.Argument(..., help="scenario TOML file"),
    out: str = typer.Option(..., "--out", "-o", help="run directory to create", callback=_nonempty),
    duration: Optional[float] = typer.Option(None, help="override run.duration [s]"),
    seed: Optional[int] = typer.Option(None, help="override run.seed"),
    model: Optional[str] = typer.Option(None, help="override vehicle.model: dynamic | kinematic"),
    force: bool = typer.Option(False, "--force", help="replace an existing run directory"),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="show a progress bar"),
    baseline: Optional[str] = typer.Option(None, "--baseline", metavar="[same|absent]", help="road scenarios: run the twin instead (same traffic and seed): 'same' (the default) the same demand, each member a SUMO-driven vehicle of its type entering where it would; 'absent' without the formation's vehicles (docs/metrics.md, 'The twins')"),
    gui: bool = typer.Option(False, "--gui", help="road scenarios: watch in sumo-gui (traci backend; the view follows the formation)"),
    sets: Optional[list[str]] = typer.Option(None, "--set", metavar="KEY=VALUE", help=SET_HELP),
    warm_cache: Optional[str] = typer.Option(None, "--warm-cache", metavar="DIR", callback=_nonempty, help="road scenarios: start from the shared warm-up of this scenario's traffic in DIR, simulated once and saved there by the first run (docs/sweeps.md, 'The shared warm-up')"),
    strict: bool = typer.Option(False, "--strict", help="exit 1 when the run completed with incidents (a member collision, removed, stranded member or emergency brake)"),
) -> None:
    """Run SCENARIO headless and record it under OUT (run.json, trajectories.parquet, ...).

    Exit 0 for ``completed`` and ``completed_with_incidents`` (1 with --strict), 1 for
    ``failed``, 130 for ``interrupted`` (docs/reliability.md)."""
    with _outcome():
        from .scenario import ScenarioError, load_scenario
        from .runner import run_scenario

        opts = {"run.duration": duration, "run.seed": seed, "vehicle.model": model,
                **({"sumo.backend": "traci", "sumo.gui": True} if gui else {})}
        given = _set_overrides(sets, str(scenario))
        _refuse_both(given, {k: v for k, v in opts.items() if v is not None}, str(scenario))
        _refuse_new_road(given, scenario)
        sc = load_scenario(scenario, **{**given, **{k: v for k, v in opts.items() if v is not None}})
        if warm_cache is not None and sc.road is None:
            raise ScenarioError(scenario, [("--warm-cache", "needs a road scenario (SUMO's warm-up): this "
                                                            "scenario has no [road]")])
        if progress and sc.road is not None and sc.traffic.warmup > 0:
            typer.echo(f"SUMO simulates {sc.traffic.warmup:g} s of traffic before the formation enters ...", err=True)
        res = run_scenario(sc, Path(out), scenario_path=scenario, force=force, progress=progress, baseline=baseline,
                           warm_cache=warm_cache)
    typer.echo(f"{res.status}: t_end={res.t_end:.2f} s, steps={res.steps_done}, out={res.out_dir}"
               + (f"\nreason: {res.reason}" if res.reason else "")
               + (f"\nINCIDENTS: {res.incident_summary} (run.json 'incidents', events.parquet)"
                  + _first_incidents(res.incidents) if res.incident_summary else ""))
    if res.status == "completed_with_incidents" and strict:
        raise typer.Exit(1)
    if res.status not in ("completed", "completed_with_incidents"):
        raise typer.Exit(1 if res.status == "failed" else 130)


@app.command()
def analyze(
    run_dir: Path = typer.Argument(..., help="run directory (run.json, trajectories.parquet)"),
    out: Optional[str] = typer.Option(None, "--out", "-o", help="where to write; default RUN_DIR",
                                      callback=_nonempty),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="write PNG figures and report.html"),
    baseline: Optional[Path] = typer.Option(None, "--baseline", help="twin run from `run --baseline` (same traffic and seed, no formation)"),
) -> None:
    """Compute metrics of a recorded run: metrics.json, metrics.csv, figures/, report.html."""
    with _outcome():
        from analysis.api import analyze_run
        from run_contract.rundir import require_run_dir

        if baseline is not None:  # a baseline that is not a run (missing, a file, empty) is bad input (exit 2)
            from run_contract.rundir import RunDirError, looks_like_run

            if not looks_like_run(require_run_dir(baseline)):
                raise RunDirError(f"{baseline}: is not a run directory (no run.json and no trajectories.parquet)")

        res = analyze_run(run_dir, None if out is None else Path(out), figures=figures, baseline=baseline)
    for name, path in res.files.items():
        typer.echo(f"{name}: {path}")
    if len(res.issues):
        from analysis.load.run_data import describe_issues

        typer.echo(f"{describe_issues(res.issues.to_dict('records'))}; listed in metrics.json and report.html")


@app.command()
def compare(
    run_dirs: list[Path] = typer.Argument(..., help="two or more run directories"),
    out: str = typer.Option(..., "--out", "-o", help="directory for compare.csv, figures and report.html",
                            callback=_nonempty),
) -> None:
    """Overlay several runs (e.g. kinematic vs dynamic model) and tabulate key metrics."""
    with _outcome():
        from analysis.api import compare_runs
        from run_contract.rundir import RunDirError

        if len(run_dirs) < 2:
            raise RunDirError(f"compare needs two or more run directories (got {len(run_dirs)})")

        res = compare_runs(run_dirs, Path(out))
    for name, path in res.files.items():
        typer.echo(f"{name}: {path}")


@app.command(cls=_TwinModeCommand)
def sweep(
    sweep_file: Path = typer.Argument(..., help="sweep TOML file (docs/sweeps.md)"),
    out: str = typer.Option(..., "--out", "-o", help="study directory (summary.parquet, cases/)",
                            callback=_nonempty),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Dask scheduler tcp://HOST:PORT or scheduler file"),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, help="local cases at once (default: cores)"),
    progress: bool = typer.Option(True, "--progress/--no-progress"),
    baseline: Optional[str] = typer.Option(None, "--baseline", metavar="[same|absent]", help="run each case's twin too (same traffic and seed; 'same', the default: the same demand with each member a SUMO-driven vehicle of its type; 'absent': without the formation's vehicles) and summarise formation minus twin"),
    sets: Optional[list[str]] = typer.Option(None, "--set", metavar="KEY=VALUE", help=SET_HELP + "; set in every case"),
    shared_warmup: bool = typer.Option(False, "--shared-warmup/--no-shared-warmup", help="opt-in: road cases (and twins) with the same traffic, seed and SUMO set-up start from one saved SUMO state of their warm-up (DIR/warmups; docs/sweeps.md, 'The shared warm-up'); --no-shared-warmup: each case simulates its own"),
) -> None:
    """Run every case of a sweep (each in its own process), analyse each, write summary.parquet.

    Re-running the same command skips finished cases and retries failed ones."""
    from .sweep import run_sweep

    try:
        with _outcome():
            res = run_sweep(sweep_file, Path(out), scheduler=scheduler, workers=workers,
                            progress=progress, baseline=baseline,
                            sets=_set_overrides(sets, str(sweep_file)), shared_warmup=shared_warmup)
    except typer.Exit as exc:
        if exc.exit_code == 130:
            typer.echo("run the same command again to finish the sweep", err=True)
        raise
    n_inc = int((res.summary["status"] == "completed_with_incidents").sum()) if len(res.summary) else 0
    typer.echo(f"{res.n_cases} cases: {res.n_completed} completed, {res.n_failed} not completed "
               f"({res.n_run} run now, {res.n_skipped} done before); summary: {res.files['summary']}"
               + (f"\nINCIDENTS: {n_inc} of the completed cases completed with incidents (summary "
                  "columns member_collisions, member_removed, emergency_brakes, stranded)" if n_inc else "")
               + _twins_failed(res.summary))
    if res.n_failed:
        raise typer.Exit(1)


def _first_incidents(incidents: dict) -> str:
    """The terminal's lines naming the run's first three incidents (who, when, where)."""
    from .sim.incident_log import describe

    events = (incidents or {}).get("events") or []
    lines = [f"\n  {describe(ev)}" for ev in events[:3]]
    more = int((incidents or {}).get("events_total") or len(events)) - len(lines)
    return "".join(lines) + (f"\n  and {more} more (run.json 'incidents.events')" if more > 0 else "")


def _twins_failed(summary) -> str:
    """The terminal's line naming the twins that did not reach their end ('' if none)."""
    if "twin_status" not in summary or not len(summary):
        return ""
    bad = summary[summary["twin_status"].notna()
                  & ~summary["twin_status"].isin(["completed", "completed_with_incidents"])]
    if not len(bad):
        return ""
    def why(reason) -> str:
        lines = str(reason or "").strip().splitlines()
        return lines[-1].strip()[:160] if lines else ""

    named = ", ".join(f"{r.case_id} ({r.twin_status}: {why(r.twin_reason)})" for r in bad.head(3).itertuples())
    more = f" and {len(bad) - 3} more" if len(bad) > 3 else ""
    return (f"\nTWINS FAILED: {len(bad)}: {named}{more}; their cases have no paired effects "
            "(summary columns twin_status, twin_reason)")


@app.command("analyze-sweep")
def analyze_sweep_cmd(
    sweep_dir: Path = typer.Argument(..., help="study directory written by `sweep`"),
    metric: Optional[list[str]] = typer.Option(None, "--metric", "-m", help="metric column(s) to plot"),
    out: Optional[str] = typer.Option(None, "--out", "-o", help="where to write; default SWEEP_DIR",
                                      callback=_nonempty),
    spread: str = typer.Option("minmax", help="spread over seeds: minmax | std"),
) -> None:
    """Plot metrics against the swept values (spread over seeds) and write sweep_report.html."""
    with _outcome():
        from analysis.report.sweep_report import analyze_sweep

        rep = analyze_sweep(sweep_dir, metrics=metric or None, out=None if out is None else Path(out), spread=spread)
    for name, path in rep.files.items():
        typer.echo(f"{name}: {path}")


def main() -> None:  # pragma: no cover
    """Console entry point: SIGTERM handled like Ctrl-C (exit 130) from the start."""
    try:
        app()
    except KeyboardInterrupt:  # a signal between two commands' handlers (e.g. at start-up)
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()
