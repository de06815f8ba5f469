"""Run a scenario from Python: ``run_scenario(scenario, out_dir)`` (formation_traci/run/scenario_run.py).

The library's entry point for a run, as the command line's ``formation-traci run`` uses it."""
from .run.scenario_run import RunResult, run_scenario, versions

__all__ = ["RunResult", "run_scenario", "versions"]
