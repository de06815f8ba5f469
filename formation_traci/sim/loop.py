"""The one step loop of every run, over a World (sim/world.py):

    sense -> reference (generator, then transforms) -> observe -> record -> [yield]
    -> stop? -> controllers and models (sim/fleet.py) -> actuate -> world step

Free space and SUMO differ only in the World and the reference generator they bring
(:func:`free_space_run`, sim/sumo_world.py ``road_run``). docs/architecture.md has the
picture and where a maneuver planner or a communication channel plugs in.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from ..control.reference import apply
from ..control.reference_free import FreeReference
from ..record.columns import SIGNAL_COLUMNS
from ..scenario.schema import Scenario
from .fleet import Fleet, FleetState
from .setup import build_fleet, build_free_leader, build_initial_state, offsets
from .timing import PhaseClock
from .world import FreeSpace


class ModelRangeError(RuntimeError):
    """A vehicle state became non-finite: the model left its valid range."""


@dataclass
class RunParts:
    """Everything the loop needs; ``transforms`` modify each step's Reference in order."""

    world: object  # a sim.world.World
    generator: object  # FreeReference or RoadReference
    fleet: Fleet
    state: FleetState
    transforms: list = field(default_factory=list)
    timing: dict | None = None  # run.json timing_s, or None: not timed


def check_finite(state: FleetState, ids, t) -> None:
    if not np.all(np.isfinite(state.x)):
        bad = [ids[i] for i in np.flatnonzero(~np.all(np.isfinite(state.x), axis=1))]
        raise ModelRangeError(f"vehicle state became non-finite for {bad} at t = {t:.3f} s")


def free_space_run(sc: Scenario) -> RunParts:
    """World, reference and fleet of a free-space run (no [road])."""
    run = sc.run
    n_ctrl = int(round(run.step / run.control_step))
    cfg = build_fleet(sc)
    leader, pose = build_free_leader(sc)
    state = build_initial_state(sc, cfg, leader.sample(0.0, pose))
    gen = FreeReference(leader, pose, offsets(sc), run.step / n_ctrl, n_ctrl)
    return RunParts(FreeSpace(cfg.n), gen, Fleet(cfg), state)


def step_loop(sc: Scenario, build, rec, meta: dict) -> Iterator[tuple[int, float]]:
    """Run the parts ``build()`` returns (built on the first ``next``, so that set-up and
    kernel compilation run under the caller's signal handling); yields (step index, time
    [s]) after recording each step."""
    parts: RunParts = build()
    world, gen, fleet, state = parts.world, parts.generator, parts.fleet, parts.state
    step, ids = sc.run.step, list(fleet.cfg.ids)
    n_steps = int(round(sc.run.duration / step))
    sig = np.full((fleet.cfg.n, len(SIGNAL_COLUMNS)), np.nan)
    clock = PhaseClock({} if parts.timing is None else parts.timing)
    world.start()
    try:
        for k in range(n_steps + 1):
            t = k * step
            clock.start()
            sensed = world.sense(k, t, state)
            clock.lap("sumo_read")
            ref = apply(gen.reference(t, sensed), parts.transforms)
            clock.lap("governor")
            world.observe(t, sensed, ref)
            if world.records_members:
                rec.add_signal_rows(t, fleet.signals(state, ref, out=sig), sensed.extra,
                                    mask=ref.active)
            rec.add_vc(t, ref.leader(), s=float(ref.truth[7]))
            clock.lap("record")
            yield k, t
            if k == n_steps:
                return
            stop = gen.stop_reason(t) or world.stop_reason(t)
            if stop is not None:
                kind, detail, why = stop
                if kind:
                    rec.add_event(t, kind, "vc", "", detail)
                meta["stopped_early"] = why
                return
            clock.start()
            v_before = fleet.speed(state)
            state = fleet.step(state, ref)
            gen.commit()
            check_finite(state, ids, t + step)
            clock.lap("control_model")
            world.actuate(t + step, state, v_before)
            clock.lap("sumo_place")
            world.step(k, t + step)
            clock.lap("sumo_step")
    finally:
        world.close()
