"""A run of a scenario from its file to its directory (scenario_run.py) and its twins."""
