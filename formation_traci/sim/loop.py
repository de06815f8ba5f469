"""The one step loop of every run, over a World (sim/world.py):

    sense -> reference (generator, then transforms) -> observe -> record -> [yield]
    -> stop? -> controllers and models (sim/fleet.py) -> actuate -> world step

Free space and SUMO differ only in the World and the reference generator they bring
(:func:`free_space_run`, run/road_parts.py ``road_run``). docs/architecture.md has the
picture and where a maneuver planner or a communication channel plugs in.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterator

import numpy as np

from run_contract.columns import DEFAULT_FORMATION_ID, VIRTUAL_CAR_ID

from ..comm.link import CommChannel
from ..control.reference import apply
from ..control.reference_free import FreeReference
from ..record.columns import SIGNAL_COLUMNS
from ..scenario.formations import formation_views
from ..scenario.schema import Scenario
from .fleet import Fleet, FleetState
from .formation_group import group_of
from .free_path import free_path
from .formation import (Formation, depart_due, join_configs, join_references, join_states,
                        formations_meta, merge_extra, retire_formation, virtual_car_id)
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
    """Everything the loop needs: the world, the run's members as one fleet and its state, and
    the formations (sim/formation.py: each its reference generator and transforms). A
    formation's transforms modify its Reference each step in order (one with a ``sense(k, t,
    sensed, kinematics, rec)`` method is told what the world sensed, the members' (pos, vel,
    heading) and the recorder first; one with ``error_against_truth`` has the formation error
    recorded against the true virtual car: comm/link.py)."""

    world: object  # a sim.world.World
    fleet: Fleet
    state: FleetState
    formations: list[Formation]
    timing: dict | None = None  # run.json timing_s, or None: not timed
    road_load: object = None  # sim/road_load.py: (state, sensed, ref) -> (drag ratio, grade)
    fused: object = None  # (parts, rec, sc, group) -> the run's compiled usual step or None
    # (sumo/fused_path.py on a road, sim/free_path.py in free space)


def one_formation(world, generator, fleet: Fleet, state: FleetState, transforms=(), **kw) -> RunParts:
    """The parts of a run with one formation (every member in it)."""
    f = Formation(DEFAULT_FORMATION_ID, slice(0, fleet.cfg.n), generator, list(transforms))
    return RunParts(world, fleet, state, [f], **kw)


def check_finite(state: FleetState, ids, t) -> None:
    if not np.all(np.isfinite(state.x)):
        bad = [ids[i] for i in np.flatnonzero(~np.all(np.isfinite(state.x), axis=1))]
        raise ModelRangeError(f"vehicle state became non-finite for {bad} at t = {t:.3f} s")


def free_space_run(sc: Scenario, rec=None) -> RunParts:
    """World, references and fleet of a free-space run (no [road]): one formation per
    scenario/formations.py ``formation_views`` entry."""
    run = sc.run
    n_ctrl = int(round(run.step / run.control_step))
    views = formation_views(sc)
    cfgs, states, forms, at = [], [], [], 0
    for fid, fsc in views:
        cfg = build_fleet(fsc)
        leader, pose = build_free_leader(fsc)
        states.append(build_initial_state(fsc, cfg, leader.sample(0.0, pose)))
        gen = FreeReference(leader, pose, offsets(fsc), run.step / n_ctrl, n_ctrl)
        forms.append(Formation(fid, slice(at, at + cfg.n), gen,
                               vc_id=virtual_car_id(fid, len(views))))
        cfgs.append(cfg)
        at += cfg.n
    vehicles = [v for _, fsc in views for v in member_vehicles(fsc)]
    return RunParts(FreeSpace(at, rec), Fleet(join_configs(cfgs)), join_states(states), forms,
                    road_load=road_load_part(sc, vehicles, rows=[f.members for f in forms]),
                    fused=_free_path)


def _free_path(parts, rec, sc, group=None):
    """The free-space run's usual step as one compiled call (sim/free_path.py), or None."""
    return free_path(parts, rec, sc, check_finite)


def _references(forms, world, k, t, sensed, fleet, state, rec):
    """The step's reference of every formation, joined for the fleet: (reference before the
    transforms, after them, the one to record the error against). ``forms``: (formation,
    its sensing transforms, its true_error) each."""
    kin = None
    if len(forms) == 1 and forms[0][0].status == "running" and not forms[0][0].depart:
        f, sensing, true_error = forms[0]
        for tr in sensing:
            kin = fleet.kinematics(state) if kin is None else kin  # once for every transform
            tr.sense(k, t, sensed, kin, rec)
        world.command(t, f.generator.plan(t, sensed), sensed, f.vc_id)
        ref0 = f.generator.reference(t, sensed)
        ref = apply(ref0, f.transforms)
        return ref0, ref, (ref0 if true_error and ref.vc is not ref0.vc else ref)
    raw, out, err, blocked = [], [], [], set()
    for f, sensing, true_error in forms:
        if f.status == "waiting" and t >= f.depart - 1e-9:  # due: its members enter
            depart_due(f, world, t, state, blocked)
        if f.status != "running":
            parked = f.parked(t)
            raw.append(parked), out.append(parked), err.append(parked)
            continue
        part = world.sensed_for(sensed, f.members)
        if sensing:
            kin = fleet.kinematics(state) if kin is None else kin
            for tr in sensing:
                tr.sense(k, t, part, tuple(a[f.members] for a in kin), rec)
            merge_extra(sensed, part, f.members)
        t_f = t - f.depart  # the formation's own time [s]
        world.command(t, _fleet_rows(f.generator.plan(t_f, part), f.members.start), part, f.vc_id)
        slot = part.extra.get("slot")
        ref0 = f.generator.reference(t_f, part)
        if part.extra.get("slot") is not slot:  # a maneuver's slots, recorded
            merge_extra(sensed, part, f.members)
        if f.depart:
            ref0 = ref0.with_(t=t)
        ref = apply(ref0, f.transforms)
        raw.append(ref0)
        out.append(ref)
        err.append(ref0 if true_error and ref.vc is not ref0.vc else ref)
    n_nb = None if sensed.nb is None else len(sensed.nb.ids)
    ref = join_references(out, n_nb)
    truth_ref = ref if all(e is o for e, o in zip(err, out)) else join_references(err, n_nb)
    return join_references(raw, n_nb), ref, truth_ref


def _fleet_rows(commands: list, first: int) -> list:
    """A formation's world commands with its member indices as the fleet's rows (its first
    row ``first``)."""
    if not first or not commands:
        return commands
    return [c if c.member < 0 else replace(c, member=c.member + first) for c in commands]


def _radio_links(forms, fleet: Fleet) -> list:
    """(the formation's fleet rows, its [comm] channel) of every formation with a radio: what
    :func:`_law_fallbacks` watches each step (none: nothing to do per step)."""
    rows = np.arange(fleet.cfg.n)
    return [(rows[f.members], tr) for f in forms for tr in f.transforms
            if isinstance(tr, CommChannel) and tr.law_fallback]


def _law_fallbacks(links, fleet: Fleet, t: float, rec) -> None:
    """CACC members whose beacons timed out this step run their ACC fallback, the others their
    own law (sim/fleet_laws.py); each switch is an event (law_fallback / law_recovered)."""
    for rows, tr in links:
        for i, fell in fleet.fall_back(rows, tr.timed_out()):
            rec.add_event(t, "law_fallback" if fell else "law_recovered", fleet.cfg.ids[i], "",
                          "beacons timed out: ACC at the controller.acc time gap" if fell
                          else "beacons back: its own law")


def step_loop(sc: Scenario, build, rec, meta: dict) -> Iterator[tuple[int, float]]:
    """Run the parts ``build()`` returns (built on the first ``next``, so that set-up and
    kernel compilation run under the caller's signal handling); yields (step index, time
    [s]) after recording each step."""
    parts: RunParts = build()
    world, fleet, state, forms = parts.world, parts.fleet, parts.state, parts.formations
    step, ids = sc.run.step, list(fleet.cfg.ids)
    n_steps = int(round(sc.run.duration / step))
    sig = np.full((fleet.cfg.n, len(SIGNAL_COLUMNS)), np.nan)
    sig_true = sig.copy()
    periods = np.empty((0, fleet.cfg.n, 3))  # step_recording's comfort buffer
    perfect = np.zeros(fleet.cfg.n)  # leader_age_s without a channel
    clock = PhaseClock({} if parts.timing is None else parts.timing)
    plans = [(f, f.sensing, f.true_error) for f in forms]  # the transforms are fixed now
    links = _radio_links(forms, fleet)
    group = group_of(forms, world)  # plain road formations: one compiled call for all
    fused = None if parts.fused is None else parts.fused(parts, rec, sc, group)
    try:
        world.start()  # inside: a signal or a failure during SUMO's start or warm-up closes SUMO
        for k in range(n_steps + 1):
            t = k * step
            clock.start()
            if fused is not None and fused.ready(k, t, state, clock):  # the usual step: one compiled call
                state = fused.step(k, t, state, clock)
                yield k, t
                fused.finish(k, t + step, state, clock)
                continue
            sensed = world.sense(k, t, state)
            sensed.extra.setdefault("leader_age_s", perfect)
            clock.lap("sumo_read")
            ref0, ref, ref_err = (_references(plans, world, k, t, sensed, fleet, state, rec) if group is None
                                  else group.references(world, k, t, sensed, state))
            if links:
                _law_fallbacks(links, fleet, t, rec)
            state = world.adopt(state, ref)  # vehicles the world handed to the formation (join)
            clock.lap("governor")
            world.observe(t, sensed, ref)
            if parts.road_load is not None:  # drag ratio and grade, held over the step
                fleet.set_road_load(*parts.road_load(state, sensed, ref))
            _record(world, fleet, rec, t, state, sensed, ref, ref_err, sig, sig_true)
            clock.lap("record")
            yield k, t
            clock.lap("record")  # the caller's share: the step's end, part files, progress (runner.py)
            if k == n_steps:
                break
            stop = _stop_reason(forms, world, t, state, rec, group, ref.active)
            if stop is not None:
                vc_id, (kind, detail, why) = stop
                if kind:
                    rec.add_event(t, kind, vc_id, "", detail)
                meta["stopped_early"] = why
                break
            clock.start()
            v_before = fleet.speed(state)
            if world.records_members:
                if periods.shape[0] != ref.n_ctrl:
                    periods = np.empty((ref.n_ctrl, fleet.cfg.n, 3))
                state = step_recording(fleet, state, ref, rec, periods)
            else:
                state = fleet.step(state, ref)
            _settle(forms, state) if group is None else group.settle(state)
            check_finite(state, ids, t + step)
            clock.lap("control_model")
            world.actuate(t + step, state, v_before)
            clock.lap("sumo_place")
            world.step(k, t + step)
            clock.lap("sumo_step")
        world.drain()  # a run that ended normally: the measurement sections' drain
    finally:
        if len(forms) > 1 or forms[0].depart:
            meta["formations"] = formations_meta(forms, getattr(world, "active", None))
        world.close()


_ERROR_COLS = [SIGNAL_COLUMNS.index(c) for c in ERROR_COLUMNS]


def _record(world, fleet: Fleet, rec, t, state, sensed, ref, ref_err, sig, sig_true) -> None:
    """The step's rows at t [s]: the members' signals (into ``sig``; with the error against
    the true virtual car when ``ref_err`` is not ``ref``), the road columns, the virtual cars,
    the members' incidents; a twin records its virtual cars only."""
    if world.records_members:
        true_vc = ref_err is not ref
        rows = None if true_vc else rec.signal_rows(ref.active)  # rows in the same call
        written = fleet.signals_into(state, ref, sig, t, rows)
        if true_vc:  # the error against the true virtual car
            fleet.signals(state, ref.with_(vc=ref_err.vc), out=sig_true)
            sig[:, _ERROR_COLS] = sig_true[:, _ERROR_COLS]
        rec.add_step(t, sig, sensed.extra, ref.active, ref.truth, written)
        if rec.incidents is not None:  # collisions between members, stranded members
            rec.incidents.step(t, sig, ref.active)
            if rec.incidents.lane_watch is not None:  # lane departures (road runs)
                rec.incidents.lanes(t, sensed.extra["d"], ref.active)
    elif ref.truth.ndim == 1:
        rec.add_vc(t, ref.leader(), s=float(ref.truth[7]))
    else:  # a twin of several formations: their virtual cars on the road
        rec.add_vcs(t, ref.truth)


def _settle(forms, state: FleetState) -> None:
    """After the members' step: the running formations' generators commit it; the members of
    a parked formation (waiting to depart, or done) are held where they are."""
    for f in forms:
        if f.status == "running":
            f.generator.commit()
        else:
            state.hold(f.members, f.held)


def _stop_reason(forms, world, t, state: FleetState, rec, group=None, active=None):
    """(virtual car id, (event kind, detail, why)) of the first formation whose generator
    ends the run (end of road), or of the world (no member left); None: go on. With several
    formations, one that reaches the end of its route is retired (its members leave the
    world, its event recorded, no more rows of it in ``active``: the step's reference's) and the
    run goes on while another runs or waits to depart."""
    if group is not None:
        if group.stop(world, t, state, rec, active):
            return VIRTUAL_CAR_ID, ("", "", f"every formation reached the end of its route by t = {t:.2f} s")
    elif len(forms) == 1 and not forms[0].depart:
        stop = forms[0].generator.stop_reason(t)
        if stop is not None:
            return forms[0].vc_id, stop
    else:
        for f in forms:
            stop = f.generator.stop_reason(t) if f.status == "running" else None
            if stop is not None:
                retire_formation(f, world, t, state, rec, stop, active)
        if all(f.status == "done" for f in forms):
            return VIRTUAL_CAR_ID, ("", "", f"every formation reached the end of its route by t = {t:.2f} s")
    stop = world.stop_reason(t)
    return None if stop is None else (VIRTUAL_CAR_ID, stop)


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
