"""Bounds from cost: schema-legal values that no run could finish are refused as bad input.

Each bound says what it protects: the number of sub-steps per simulated second (one step of
1e-9 s took 200 s), SUMO's sublane count (1e-6 m lanes took 2.3 GB), the step counter (1e308 s
overflowed), SUMO's seed range, and run.json's size (the description is copied into it).
"""
from __future__ import annotations

from .schema import Scenario

MAX_SUBSTEPS_PER_S = 10_000
"""Control periods or RK4 sub-steps per simulated second, at most [1/s]."""
MIN_STEP = 0.001
"""Smallest outer step: SUMO's clock counts milliseconds [s]."""
MIN_LATERAL_RESOLUTION = 0.1
"""Narrowest SUMO sublane [m]."""
MAX_STEPS = 2**31 - 1
"""Outer steps of a run, warm-up included (SUMO's step counter, a 32-bit signed integer)."""
MAX_SEED = 2**31 - 1
"""SUMO's --seed is a 32-bit signed integer."""
MAX_TEXT = 4096
"""Longest name or description copied into run.json [characters]."""
MAX_VEH_PER_HOUR_PER_LANE = 10_000.0
"""Demand of a flow per lane, at most [veh/h]: four times a motorway lane's capacity; beyond
it SUMO refuses the repetition rate (1e9) or the vehicle count overflows (1e308)."""
MAX_VEH_PER_HOUR = 100_000.0
"""Total demand of a flow, at most [veh/h] (ten lanes at the bound above)."""


def cost_problems(sc: Scenario) -> list[tuple[str, str]]:
    """(dotted field, expectation (got value)) for every value beyond a bound."""
    run, out = sc.run, []
    min_sub = 1.0 / MAX_SUBSTEPS_PER_S
    if run.step < MIN_STEP:
        out.append(("run.step", f"must be at least {MIN_STEP} s (SUMO counts milliseconds) (got {run.step!r})"))
    for name in ("control_step", "physics_step"):
        v = getattr(run, name)
        if v < min_sub:
            out.append((f"run.{name}", f"must be at least {min_sub:g} s: more than {MAX_SUBSTEPS_PER_S} "
                                       f"sub-steps per simulated second cannot finish (got {v!r})"))
    steps = (run.duration + sc.traffic.warmup) / max(run.step, MIN_STEP)
    if steps > MAX_STEPS:
        field = "run.duration" if run.duration >= sc.traffic.warmup else "traffic.warmup"
        out.append((field, f"duration + warm-up must be at most {MAX_STEPS} steps of run.step "
                           f"(got {steps:.3g} steps)"))
    if run.seed > MAX_SEED:
        out.append(("run.seed", f"must be at most {MAX_SEED} (SUMO's seed range) (got {run.seed})"))
    if sc.sumo.lateral_resolution < MIN_LATERAL_RESOLUTION:
        out.append(("sumo.lateral_resolution", f"must be at least {MIN_LATERAL_RESOLUTION} m "
                                               f"(got {sc.sumo.lateral_resolution!r})"))
    out += _flow_problems(sc)
    for name in ("name", "description"):
        n = len(getattr(sc, name))
        if n > MAX_TEXT:
            out.append((name, f"at most {MAX_TEXT} characters (got {n})"))
    return out


def _flow_problems(sc: Scenario) -> list[tuple[str, str]]:
    """Demand beyond :data:`MAX_VEH_PER_HOUR_PER_LANE` / :data:`MAX_VEH_PER_HOUR`, a flow
    that ends before it begins (SUMO refuses both only after it started), and a formation flow
    whose window is empty (it would insert nothing)."""
    out = []
    for i, f in enumerate(sc.traffic.flows):
        for name, cap in (("veh_per_hour_per_lane", MAX_VEH_PER_HOUR_PER_LANE), ("veh_per_hour", MAX_VEH_PER_HOUR)):
            v = getattr(f, name)
            if v is not None and v > cap:
                out.append((f"traffic.flows.{i}.{name}", f"at most {cap:g} veh/h (got {v!r})"))
        if f.end is not None and f.end <= f.begin:
            out.append((f"traffic.flows.{i}.end", f"must be after begin = {f.begin:g} s (got {f.end!r})"))
    for j, f in enumerate(sc.formation_flows):  # an empty window would insert no formation, silently
        if f.end is not None and f.end <= f.begin:
            out.append((f"formation_flows.{j}.end", f"must be after begin = {f.begin:g} s (got {f.end!r})"))
        elif f.begin >= sc.run.duration:
            out.append((f"formation_flows.{j}.begin", f"must be before the end of the run (run.duration = "
                                                      f"{sc.run.duration:g} s) (got {f.begin!r})"))
    return out
