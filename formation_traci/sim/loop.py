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
from .road_load import road_load_part
from .setup import build_fleet, build_free_leader, build_initial_state, member_vehicles, offsets
from .timing import PhaseClock
from .world import FreeSpace


ERROR_COLUMNS = ("ex", "ey", "e_lon", "e_lat", "x_des", "y_des")
"""Recorded against the true virtual car when a transform that says so
(``error_against_truth = True``: comm/link.py) changed the members' copies of it: the
formation error the member really has. Otherwise against the member's own copy."""


class ModelRangeError(RuntimeError):
    """A vehicle state became non-finite: the model left its valid range."""


@dataclass
class RunParts:
    """Everything the loop needs; ``transforms`` modify each step's Reference in order (one
    with a ``sense(k, t, sensed, kinematics, rec)`` method is told what the world sensed, the
    members' (pos, vel, heading) and the recorder first; one with ``error_against_truth`` has
    the formation error recorded against the true virtual car: comm/link.py)."""

    world: object  # a sim.world.World
    generator: object  # FreeReference or RoadReference
    fleet: Fleet
    state: FleetState
    transforms: list = field(default_factory=list)
    timing: dict | None = None  # run.json timing_s, or None: not timed
    road_load: object = None  # sim/road_load.py: (state, sensed, ref) -> (drag ratio, grade)


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
    return RunParts(FreeSpace(cfg.n), gen, Fleet(cfg), state,
                    road_load=road_load_part(sc, member_vehicles(sc)))


def step_loop(sc: Scenario, build, rec, meta: dict) -> Iterator[tuple[int, float]]:
    """Run the parts ``build()`` returns (built on the first ``next``, so that set-up and
    kernel compilation run under the caller's signal handling); yields (step index, time
    [s]) after recording each step."""
    parts: RunParts = build()
    world, gen, fleet, state = parts.world, parts.generator, parts.fleet, parts.state
    step, ids = sc.run.step, list(fleet.cfg.ids)
    n_steps = int(round(sc.run.duration / step))
    sig = np.full((fleet.cfg.n, len(SIGNAL_COLUMNS)), np.nan)
    sig_true = sig.copy()
    periods = np.empty((0, fleet.cfg.n, 3))  # step_recording's comfort buffer
    err_cols = [SIGNAL_COLUMNS.index(c) for c in ERROR_COLUMNS]
    perfect = np.zeros(fleet.cfg.n)  # leader_age_s without a channel
    sensing = [tr for tr in parts.transforms if hasattr(tr, "sense")]
    true_error = any(getattr(tr, "error_against_truth", False) for tr in parts.transforms)
    clock = PhaseClock({} if parts.timing is None else parts.timing)
    adopt = getattr(world, "adopt", None)
    try:
        world.start()  # inside: a signal or a failure during SUMO's start or warm-up closes SUMO
        for k in range(n_steps + 1):
            t = k * step
            clock.start()
            sensed = world.sense(k, t, state)
            sensed.extra.setdefault("leader_age_s", perfect)
            clock.lap("sumo_read")
            if sensing:
                kin = fleet.kinematics(state)  # once for every sensing transform
                for tr in sensing:
                    tr.sense(k, t, sensed, kin, rec)
            ref0 = gen.reference(t, sensed)
            ref = apply(ref0, parts.transforms)
            if adopt is not None:  # vehicles the world handed to the formation (join)
                state = adopt(state, ref)
            clock.lap("governor")
            world.observe(t, sensed, ref)
            if parts.road_load is not None:  # drag ratio and grade, held over the step
                fleet.set_road_load(*parts.road_load(state, sensed, ref))
            if world.records_members:
                true_vc = true_error and ref.vc is not ref0.vc
                rows = None if true_vc else rec.signal_rows(ref.active)  # rows in the same call
                written = fleet.signals_into(state, ref, sig, t, rows)
                if true_vc:  # the error against the true virtual car
                    fleet.signals(state, ref.with_(vc=ref0.vc), out=sig_true)
                    sig[:, err_cols] = sig_true[:, err_cols]
                rec.add_step(t, sig, sensed.extra, ref.active, ref.truth, written)
                if rec.incidents is not None:  # collisions between members, stranded members
                    rec.incidents.step(t, sig, ref.active)
            else:
                rec.add_vc(t, ref.leader(), s=float(ref.truth[7]))
            clock.lap("record")
            yield k, t
            clock.lap("record")  # the caller's share: the step's end, part files, progress (sim/runner.py)
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
            if world.records_members:
                if periods.shape[0] != ref.n_ctrl:
                    periods = np.empty((ref.n_ctrl, fleet.cfg.n, 3))
                state = step_recording(fleet, state, ref, rec, periods)
            else:
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


def step_recording(fleet: Fleet, state: FleetState, ref, rec, comfort: np.ndarray) -> FleetState:
    """``fleet.step(state, ref)``, recording the members' speed and accelerations at the
    start of periods 1 .. n_ctrl - 1 into ``comfort.parquet`` (period 0 is recorded with the
    step's trajectory row): the comfort analysis gets the control rate, 100 Hz by default.
    One compiled call for the whole step (sim/fleet.py step_members), the values those of
    ``fleet.signals`` at each period, bit for bit. ``comfort``: a (n_ctrl, n, 3) buffer the
    step writes whole (reused from step to step)."""
    rows = rec.period_rows(ref.n_ctrl, ref.active)  # the table rows in the same call
    state = fleet.step(state, ref, comfort, rows)
    rec.add_periods(ref.t, ref.dt, comfort, mask=ref.active, written=rows is not None)
    return state
