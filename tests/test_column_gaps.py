"""Column gaps from each member's capability (issue 32, item 2; sim/column_gaps.py): slots whose
bodies overlap in a column are refused, gaps below what the follower needs to stop behind the
member ahead (braking by their speed laws from the leader's top speed) are warned about."""
import json

import numpy as np
import pytest

from formation_traci.control.schedule import GAIN_PRESETS, law_peak
from formation_traci.models.params import PASSENGER_CAR, SMALL_TRUCK
from formation_traci.scenario import load_scenario
from formation_traci.scenario.load import ScenarioError
from formation_traci.sim.column_gaps import check_column_bodies, column_pairs, needed_gap
from formation_traci.runner import run_scenario

CAR_REAR = PASSENGER_CAR.length - PASSENGER_CAR.cog_to_front_bumper  # CoG to rear bumper, 2.279 m
TRUCK_FRONT = SMALL_TRUCK.cog_to_front_bumper  # 3.0 m


def _peak(name):
    g = GAIN_PRESETS[name]
    return law_peak(g.g_min, g.g_max, g.k_min)


def test_column_pairs_take_the_nearest_member_ahead_whose_body_overlaps_sideways():
    """A car at (0, 0), a car at (0, 3.5) (the next lane: 1.8 m bodies do not overlap), a truck
    at (-8, 0) and a car at (-30, 0.5): the truck follows the first car, bumper gap
    8 - 3.0 - 2.279 = 2.721 m; the last car follows the truck (the nearest ahead),
    30 - 8 - 2.321 - 4.5 = 15.179 m."""
    slots = np.array([[0.0, 0.0], [0.0, 3.5], [-8.0, 0.0], [-30.0, 0.5]])
    veh = [PASSENGER_CAR, PASSENGER_CAR, SMALL_TRUCK, PASSENGER_CAR]
    pairs = column_pairs(slots, np.ones(4, bool), veh)
    assert [(i, j) for i, j, _ in pairs] == [(2, 0), (3, 2)]
    assert pairs[0][2] == pytest.approx(8.0 - TRUCK_FRONT - CAR_REAR)
    assert pairs[1][2] == pytest.approx(22.0 - PASSENGER_CAR.cog_to_front_bumper - (7.5 - 3.0))
    assert column_pairs(slots, np.array([True, True, False, True]), veh)[0][:2] == (3, 0)


def test_needed_gap_is_the_difference_of_the_stopping_distances_plus_reaction_and_min_gap():
    """From 30 m/s: a follower at 0.5 m/s^2 behind a leader at 3 m/s^2 needs
    450 (2 - 1/3) = 750 m, + 30 x 0.05 + 2; a follower braking harder needs no more than the
    reaction and the standstill gap."""
    assert needed_gap(30.0, 0.5, 3.0, 0.05, 2.0) == pytest.approx(750.0 + 1.5 + 2.0)
    assert needed_gap(30.0, 3.0, 0.5, 0.05, 2.0) == pytest.approx(3.5)


def test_overlapping_bodies_in_a_column_are_refused_naming_both():
    class Sc:
        members = [type("M", (), {"id": "car"}), type("M", (), {"id": "truck"})]

    slots = np.array([[0.0, 0.0], [-4.0, 0.0]])  # gap 4 - 3.0 - 2.279 = -1.279 m
    with pytest.raises(ScenarioError) as ei:
        check_column_bodies(Sc, slots, np.ones(2, bool), [PASSENGER_CAR, SMALL_TRUCK], "x.toml")
    (field, msg), = ei.value.problems
    assert field == "members.1.slot" and "'truck'" in msg and "'car'" in msg and "1.28 m" in msg


COLUMN = """name = "column"
[run]
duration = 0.5
step = 0.05
[road]
net = "straight3"
lane = 1
start = 300.0
[leader]
speed = 30.0
[[members]]
id = "car"
slot = {{ along = 0.0, lanes = 0 }}
[[members]]
id = "{rear}"
{preset}
slot = {{ along = {along}, lanes = 0 }}
"""


def _meta(tmp_path, text, name):
    p = tmp_path / f"{name}.toml"
    p.write_text(text)
    run_scenario(load_scenario(p), tmp_path / name, scenario_path=p, progress=False)
    return json.loads((tmp_path / name / "run.json").read_text())


def test_a_truck_8_m_behind_a_car_at_30_m_s_is_warned_with_the_numbers(tmp_path, capfd):
    """Bumper gap 2.72 m; the truck brakes at 0.513 m/s^2 by Table 3.6, the car at its Table
    3.4 law's peak: (900 / 2)(1 / 0.513 - 1 / b_car) + 30 x 0.05 + 2 m needed (about 3/4 km).
    A car 20 m behind the car (15.40 m) needs only 30 x 0.05 + 2 = 3.5 m: no warning."""
    text = COLUMN.format(rear="truck", preset='preset = "small_truck"\nspeed_gains = "table_3_6"', along=-8.0)
    meta = _meta(tmp_path, text, "truck")
    b_t, b_c = _peak("table_3_6"), _peak("table_3_4")
    need = 450.0 * (1 / b_t - 1 / b_c) + 1.5 + 2.0
    assert 700.0 < need < 800.0
    ours = [w for w in meta["warnings"] if "in their column" in w]
    assert ours == [f"member 'truck' is 2.72 m behind 'car' in their column; to stop behind it from "
                    f"the leader's top speed 30.00 m/s it needs {need:.2f} m ('truck' brakes at "
                    f"{b_t:.3f} m/s^2, 'car' at {b_c:.3f} m/s^2 by their speed laws): in an emergency "
                    "stop of the virtual car the formation cannot be held (docs/model.md, 'Mixed formations')"]
    assert "warning: member 'truck' is 2.72 m behind 'car'" in capfd.readouterr().err
    meta = _meta(tmp_path, COLUMN.format(rear="car2", preset="", along=-20.0), "cars")
    assert not any("in their column" in w for w in meta.get("warnings", []))


def test_a_slot_overlapping_the_one_ahead_is_refused_when_read_even_if_the_member_starts_elsewhere(tmp_path):
    """The truck's slot 4 m behind the car's (bumper gap -1.28 m) while it starts 40 m back
    (``position``: the members do not overlap at t = 0): refused before anything runs."""
    from formation_traci.sumo.plan import prepare
    truck = 'preset = "small_truck"\nspeed_gains = "table_3_6"'
    ok = tmp_path / "ok.toml"
    ok.write_text(COLUMN.format(rear="truck", preset=truck, along=-40.0))
    x, y = (float(q) for q in prepare(load_scenario(ok), ok).pos0[1])
    p = tmp_path / "bad.toml"
    p.write_text(COLUMN.format(rear="truck", preset=f"{truck}\nposition = [{x!r}, {y!r}]", along=-4.0))
    with pytest.raises(ScenarioError) as ei:
        run_scenario(load_scenario(p), tmp_path / "out", scenario_path=p, progress=False)
    assert [f for f, _ in ei.value.problems] == ["members.1.slot"] and "overlap" in str(ei.value)
    assert not (tmp_path / "out").exists()
