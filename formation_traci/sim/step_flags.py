"""What the compiled steps (sim/free_step.py ``free_step``, sumo/fused_step.py ``fused_step``)
report to their drivers besides the new state, and the switch that sends every step through the
loop's own path instead."""
from __future__ import annotations

import os

OUT_OF_RANGE = 1
"""A recorded signal is beyond the recorder's limits (a model_range event)."""
NOT_FINITE = 2
"""The members' new state is not finite (sim/loop.py ModelRangeError)."""
SLOW = 4
"""A member stands while its speed reference does not (sim/incidents.py)."""
EMERGENCY = 8
"""The virtual car or a member is on emergency braking (road runs: sumo/events.py)."""

SWITCH = "FORMATION_TRACI_FUSED"
"""Environment variable: ``off`` runs every step through the loop's own path (a diagnostic:
the files are the same either way: tests/test_fused_step.py, tests/test_free_fused.py)."""


def switched_off() -> bool:
    """Does ``FORMATION_TRACI_FUSED`` say every step runs the loop's way?"""
    return os.environ.get(SWITCH, "").lower() in ("0", "off", "no")
