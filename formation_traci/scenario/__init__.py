"""Scenario files: schema and loader (``load_scenario``)."""
from .load import ScenarioError, load_scenario, parse_scenario
from .schema import Scenario

__all__ = ["Scenario", "ScenarioError", "load_scenario", "parse_scenario"]
