"""The twins of a road run (``run --baseline``, ``sweep --baseline``; docs/metrics.md, "The
twins"): the same traffic and seed, the formation not driven by our controller.

* ``same`` (the default): the same demand, 0 % of it in formations: each member a vehicle of
  its type that SUMO drives, entering when and where the member would, on its route;
* ``absent``: the formation's vehicles left out (the vehicles cleared at its insertion stay
  cleared).
"""
from __future__ import annotations

TWIN_MODES = ("same", "absent")
"""The twin modes; the first is the default."""


def twin_mode(baseline, source=None) -> str | None:
    """``baseline`` as a twin mode: None/False (no twin), True (the default), or a name of
    :data:`TWIN_MODES`. Raises ScenarioError naming ``--baseline`` for another value."""
    if baseline is None or baseline is False:
        return None
    if baseline is True:
        return TWIN_MODES[0]
    if baseline not in TWIN_MODES:
        from ..scenario.load import ScenarioError

        raise ScenarioError(source or "<scenario>",
                            [("--baseline", f"expected one of {list(TWIN_MODES)}, got {baseline!r}")])
    return baseline
