"""Fields that apply to one kind of scenario only: a free-space scenario (no [road]) given a
[sumo] or [traffic] field would run without it and without a word, so it is refused."""
from __future__ import annotations

ROAD_ONLY = ("sumo", "traffic")
"""Tables read by road scenarios only."""


def kind_problems(sc) -> list[tuple[str, str]]:
    """(dotted field, expectation) for every field given that the scenario's kind does not read.

    Parameters
    ----------
    sc : Scenario
        The validated scenario.

    Returns
    -------
    list of (str, str)
        One entry per field given in vain.
    """
    if sc.road is not None:
        return []
    out = []
    for table in ROAD_ONLY:
        for name in sorted(getattr(sc, table).model_fields_set):
            out.append((f"{table}.{name}", "applies to road scenarios only: this scenario has no [road] "
                                           "(free space), so it would be ignored"))
    return out
