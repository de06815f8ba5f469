"""The usual step as one compiled call (sumo/fused_path.py, issue 33 item 1) writes the files
the loop's own step writes, byte for byte, whatever happens in the run: real SUMO through
libsumo, each case run twice, with the fused step and with ``FORMATION_TRACI_FUSED=off``.

Each case also checks that the fused step took most of the run's steps (a fused path that
silently never ran would pass the comparison) and that the run had the events the case is
about (a case that no longer provokes them would test nothing)."""
from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest

from formation_traci.runner import run_scenario
from formation_traci.scenario import load_scenario
from formation_traci.sim import recorder as recorder_module
from formation_traci.sumo import fused_path
from formation_traci.sumo.plan import MEMBER_VCLASS
from run_helpers import same_run_files

ROOT = Path(__file__).resolve().parents[1]
LIGHT = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"
MEDIUM = ROOT / "scenarios" / "highway" / "straight_3lane_medium.toml"
HEAVY = ROOT / "scenarios" / "highway" / "straight_wedge5_heavy.toml"
THREE = ROOT / "scenarios" / "highway" / "three_formations.toml"
FLOW = ROOT / "scenarios" / "highway" / "penetration_motorway.toml"
ONRAMP = ROOT / "scenarios" / "highway" / "onramp_merge.toml"


def _cut_in(k, t, ad):
    """At step 40 a SUMO car is put beside the formation 25 m ahead of the right member; at
    step 60 it changes into that member's lane."""
    api = ad.api
    if k == 40:
        car = [v for v in api.vehicle.getIDList() if v not in ad.members][0]
        x, y = api.vehicle.getPosition("right")
        ang = api.vehicle.getAngle("right")
        dx, dy = math.sin(math.radians(ang)), math.cos(math.radians(ang))
        api.vehicle.setLaneChangeMode(car, 0)
        api.vehicle.moveToXY(car, "", -1, x + 25 * dx - 3.5 * dy, y + 25 * dy + 3.5 * dx, ang, 1)
        api.vehicle.setSpeed(car, api.vehicle.getSpeed("right"))
        _cut_in.car = car
    if k == 60:
        api.vehicle.changeLane(_cut_in.car, api.vehicle.getLaneIndex("right"), 3.0)


def _brake_the_cars_ahead(k, t, ad):
    """At step 40 the SUMO car ahead of each member brakes to a stop at 8 m/s^2."""
    if k == 40:
        for m in ad.members:
            lead = ad.api.vehicle.getLeader(m, 150.0)
            if lead and lead[0] not in ad.members:
                ad.api.vehicle.setDecel(lead[0], 8.0)
                ad.api.vehicle.setEmergencyDecel(lead[0], 9.0)
                ad.api.vehicle.slowDown(lead[0], 0.0, 3.0)


def _remove_left(k, t, ad):
    if k == 40:
        ad.remove_vehicle("left")


def _car_onto_centre(k, t, ad):
    if k == 30:
        api = ad.api
        other = [v for v in api.vehicle.getIDList() if v not in ad.members][0]
        x, y = api.vehicle.getPosition("centre")
        api.vehicle.moveToXY(other, "", -1, x - 1.0, y, api.vehicle.getAngle("centre"), 1)


def _close_two_lanes(k, t, ad):
    if k == 20:
        cls = MEMBER_VCLASS["passenger_car"]
        for i in range(3):
            ad.api.lane.setDisallowed(f"main_{i}", [cls])
        ad.api.lane.setAllowed("main_0", [cls])


# name: (scenario, overrides, step hook, events the run must have, recorder speed limit
# [m/s], steps per part file)
MOST = 0.6
"""The share of a case's steps the fused step must take at least ..."""
FEWER = {"refused moves, placement mismatch": 15 / 120}
"""... but there the centre member, snapped to the edge of the open lane, reaches into the
next lane from step 21 on: those steps are the loop's (sumo/adapter/__init__.py place's moveTo hint)."""


CASES = {
    "a cut-in, tables cut every 10 steps": (
        LIGHT, {"run.duration": 8.0, "traffic.warmup": 20.0}, _cut_in,
        {"lane_change", "cut_in", "emergency_brake"}, None, 10),
    "three formations, one departing at 10 s": (  # 60 s of warm-up (the file's 120 s: 4x
        # the SUMO work) still brings the lane changes and cut-ins, and emergency brakes
        THREE, {"run.duration": 20.0, "traffic.warmup": 60.0}, None, {"lane_change", "cut_in"},
        None, None),
    "heavy traffic": (HEAVY, {"run.duration": 10.0, "traffic.warmup": 40.0}, None, {"lane_change"},
                      None, None),
    "emergency braking": (
        MEDIUM, {"run.duration": 12.0, "traffic.warmup": 30.0}, _brake_the_cars_ahead,
        {"emergency_brake", "emergency_end"}, None, None),
    "member removed by SUMO": (
        LIGHT, {"run.duration": 6.0, "traffic.warmup": 20.0}, _remove_left, {"member_removed"}, None, None),
    "collision with a SUMO car": (
        LIGHT, {"run.duration": 6.0, "traffic.warmup": 20.0}, _car_onto_centre, {"collision"}, None, None),
    "refused moves, placement mismatch": (
        LIGHT, {"run.duration": 6.0, "traffic.warmup": 20.0}, _close_two_lanes,
        {"move_refused", "placement_mismatch"}, None, None),
    "signals out of range": (
        LIGHT, {"run.duration": 8.0, "traffic.warmup": 20.0, "leader.speed": 31.0}, None,
        {"model_range"}, 30.5, None),
    "a formation flow's formation due and waiting for room": (  # near capacity: most steps
        # have a due formation without room (formation_shortfall at the end), the others run on
        FLOW, {"run.duration": 20.0, "traffic.warmup": 60.0, "formation_flows.0.penetration": 0.3},
        None, {"formation_shortfall", "cleared_at_insertion"}, None, None),
    "ramp traffic, open_gap yields": (  # the steps near the join: the caps (and their
        # events) from the members' sense before the compiled call
        ONRAMP, {"run.duration": 45.0, "traffic.warmup": 150.0, "traffic.flows.1.veh_per_hour": 900.0,
                 "cooperation.merge": "open_gap"}, None, {"merge_yield_start", "merge_yield_end"}, None, None),
    "resistances with the drag interaction, among SUMO's cars": (  # the drag ratios in the step
        LIGHT.parent / "column_energy.toml", {"run.duration": 10.0, "traffic.warmup": 20.0}, None,
        set(), None, None),
    "end of the route": (
        LIGHT, {"run.duration": 60.0, "traffic.warmup": 20.0, "road.start": 5550.0}, None,
        {"end_of_road"}, None, None),
}


NO_DRAIN = {"traffic.sections.drain_max": 0.0}
"""Every case ends at the formation's last step: SUMO's drain of the measurement stretch after
it (sumo/sections.py: the members leave, SUMO alone runs on, up to minutes of SUMO time) is the
same code after either kind of step and steps no member; the sections are still placed and
their passages during the run compared."""


def _run(tmp_path, name, case, monkeypatch, fused: bool):
    path, overrides, hook, _, v_max, chunk = case
    overrides = {**overrides, **NO_DRAIN}
    if v_max is not None:
        monkeypatch.setattr(recorder_module, "MAX_SPEED", v_max)
    if chunk is not None:
        monkeypatch.setattr(recorder_module, "STEPS_PER_CHUNK", chunk)
    monkeypatch.setenv(fused_path.SWITCH, "on" if fused else "off")
    out = tmp_path / name
    res = run_scenario(load_scenario(path, **overrides), out, scenario_path=path, progress=False,
                       step_hook=hook)
    return res, out


@pytest.mark.parametrize("name", list(CASES))
def test_fused_steps_write_the_files_of_the_loops_own_steps(tmp_path, monkeypatch, name):
    case = CASES[name]
    taken = []
    step = fused_path.FusedPath.step
    monkeypatch.setattr(fused_path.FusedPath, "step",
                        lambda self, *a: taken.append(a[0]) or step(self, *a))
    fused, a = _run(tmp_path, "fused", case, monkeypatch, True)
    n_fused = len(taken)
    loop, b = _run(tmp_path, "loop", case, monkeypatch, False)
    assert len(taken) == n_fused  # the switch turned the fused path off
    assert n_fused > FEWER.get(name, MOST) * fused.steps_done, f"only {n_fused} of {fused.steps_done} steps fused"
    ev = pd.read_parquet(a / "events.parquet")
    assert case[3] <= set(ev.kind), f"the case provoked {sorted(set(ev.kind))}"
    assert (fused.status, fused.reason, fused.steps_done) == (loop.status, loop.reason, loop.steps_done)
    same_run_files(a, b)
