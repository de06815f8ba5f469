"""Fields that apply to one kind of scenario only: a free-space scenario (no [road]) given a
[sumo] or [traffic] field other than its default would run without it and without a word, so it
is refused (a run.json's scenario, which lists every default, loads again)."""
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
        spec = getattr(sc, table)
        given, default = spec.model_dump(), type(spec)().model_dump()  # a value equal to the default changes nothing
        for name in sorted(k for k in given if given[k] != default[k]):
            out.append((f"{table}.{name}", "applies to road scenarios only: this scenario has no [road] "
                                           "(free space), so it would be ignored"))
    return out
