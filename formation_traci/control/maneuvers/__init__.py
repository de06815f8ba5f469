"""Formation maneuvers: slot transitions, slot assignment, gap checks, triggers, the planner.

See docs/maneuvers.md. Everything here is pure (no SUMO, no clock): the planner turns the
scenario's schedule and what is sensed each step into a slot plan that the step kernels
evaluates into each step's Reference (control/maneuvers/generator.py, the seam of
docs/architecture.md).
"""

from .lane_shift import LaneShift  # noqa: E402  (the example transform)

__all__ = ["LaneShift"]
