"""See the package docstring of formation_traci."""
