"""Command line: ``formation-traci run|analyze|compare``; each a thin layer over a library call."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Formation control experiments: run scenarios, analyse recordings.")


@app.callback()
def _group() -> None:
    """Formation control experiments: run scenarios, analyse recordings."""


@app.command()
def run(
    scenario: Path = typer.Argument(..., help="scenario TOML file"),
    out: Path = typer.Option(..., "--out", "-o", help="run directory to create"),
    duration: Optional[float] = typer.Option(None, help="override run.duration [s]"),
    seed: Optional[int] = typer.Option(None, help="override run.seed"),
    model: Optional[str] = typer.Option(None, help="override vehicle.model: dynamic | kinematic"),
    force: bool = typer.Option(False, "--force", help="replace an existing run directory"),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="show a progress bar"),
    baseline: bool = typer.Option(False, "--baseline", help="road scenarios: the twin run with the same traffic and seed but no formation"),
) -> None:
    """Run SCENARIO headless and record it under OUT (run.json, trajectories.parquet, ...)."""
    from .scenario import ScenarioError, load_scenario
    from .sim.runner import RunDirExists, run_scenario

    try:
        sc = load_scenario(scenario, **{"run.duration": duration, "run.seed": seed,
                                        "vehicle.model": model})
        res = run_scenario(sc, out, scenario_path=scenario, force=force, progress=progress, baseline=baseline)
    except (ScenarioError, RunDirExists) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    typer.echo(f"{res.status}: t_end={res.t_end:.2f} s, steps={res.steps_done}, out={res.out_dir}"
               + (f"\nreason: {res.reason}" if res.reason else ""))
    if res.status != "completed":
        raise typer.Exit(1 if res.status == "failed" else 130)


@app.command()
def analyze(
    run_dir: Path = typer.Argument(..., help="run directory (run.json, trajectories.parquet)"),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="where to write; default RUN_DIR"),
    figures: bool = typer.Option(True, "--figures/--no-figures", help="write PNG figures and report.html"),
    baseline: Optional[Path] = typer.Option(None, "--baseline", help="twin run from `run --baseline` (same traffic and seed, no formation)"),
) -> None:
    """Compute metrics of a recorded run: metrics.json, metrics.csv, figures/, report.html."""
    from analysis.api import analyze_run
    from analysis.load import NoTrajectoryData

    try:
        res = analyze_run(run_dir, out, figures=figures, baseline=baseline)
    except NoTrajectoryData as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    for name, path in res.files.items():
        typer.echo(f"{name}: {path}")
    if len(res.issues):
        typer.echo(f"{len(res.issues)} issue(s) noted in metrics.json (missing or damaged data)")


@app.command()
def compare(
    run_dirs: list[Path] = typer.Argument(..., help="two or more run directories"),
    out: Path = typer.Option(..., "--out", "-o", help="directory for compare.csv, figures and report.html"),
) -> None:
    """Overlay several runs (e.g. kinematic vs dynamic model) and tabulate key metrics."""
    from analysis.api import compare_runs
    from analysis.load import NoTrajectoryData

    try:
        res = compare_runs(run_dirs, out)
    except NoTrajectoryData as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    for name, path in res.files.items():
        typer.echo(f"{name}: {path}")


@app.command()
def sweep(
    sweep_file: Path = typer.Argument(..., help="sweep TOML file (docs/sweeps.md)"),
    out: Path = typer.Option(..., "--out", "-o", help="study directory (summary.parquet, cases/)"),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Dask scheduler tcp://HOST:PORT or scheduler file"),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, help="local cases at once (default: cores)"),
    progress: bool = typer.Option(True, "--progress/--no-progress"),
) -> None:
    """Run every case of a sweep (each in its own process), analyse each, write summary.parquet.

    Re-running the same command skips finished cases and retries failed ones."""
    from .sweep import SweepError, run_sweep

    try:
        res = run_sweep(sweep_file, out, scheduler=scheduler, workers=workers, progress=progress)
    except SweepError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    except KeyboardInterrupt as exc:
        typer.echo(f"interrupted: {exc}; run the same command again to finish", err=True)
        raise typer.Exit(130)
    typer.echo(f"{res.n_cases} cases: {res.n_completed} completed, {res.n_failed} not completed "
               f"({res.n_run} run now, {res.n_skipped} done before); summary: {res.files['summary']}")
    if res.n_failed:
        raise typer.Exit(1)


@app.command("analyze-sweep")
def analyze_sweep_cmd(
    sweep_dir: Path = typer.Argument(..., help="study directory written by `sweep`"),
    metric: Optional[list[str]] = typer.Option(None, "--metric", "-m", help="metric column(s) to plot"),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="where to write; default SWEEP_DIR"),
    spread: str = typer.Option("minmax", help="spread over seeds: minmax | std"),
) -> None:
    """Plot metrics against the swept values (spread over seeds) and write sweep_report.html."""
    from analysis.sweep_report import analyze_sweep

    from .sweep import SweepError

    try:
        rep = analyze_sweep(sweep_dir, metrics=metric or None, out=out, spread=spread)
    except SweepError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2)
    for name, path in rep.files.items():
        typer.echo(f"{name}: {path}")


def main() -> None:  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
