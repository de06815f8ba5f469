"""The bundled scale case (scenarios/highway/motorway100.toml): what it is made of, read from the
file and the network without running it (its run takes minutes: benchmarks/scale.py runs it, and
it is left out of the golden set, tests/golden/make_golden.py NOT_GOLDEN)."""
from __future__ import annotations

from pathlib import Path

import pytest

from formation_traci.scenario import load_scenario
from formation_traci.sumo.traffic import populate_places

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "scenarios" / "highway" / "motorway100.toml"
V_LIMIT = 36.11  # motorway100's speed limit [m/s]


@pytest.fixture(scope="module")
def case():
    return load_scenario(CASE)


def test_the_road_is_populated_with_about_4000_vehicles_at_free_flow_density(case):
    """populate puts one vehicle every 3600 v / vph metres (all lanes) on the main route, none in
    an edge's last 50 m, with vph the demand the flow keeps (the formation flows take their
    penetration of it): on motorway100 at 0.85 x 4 x 1,550 veh/h that is (route - 100 m) / 24.7 m
    slots times the share of the road outside the edges' last 50 m, within 1 %; with every
    formation flow's first formation (due at once) 3,900-4,200 vehicles."""
    import sumolib

    from sumo_nets.motorway100 import main_route

    net = sumolib.net.readNet(str(ROOT / "sumo_nets" / "motorway100.net.xml"))
    lengths = [net.getEdge(e).getLength() for e in main_route()]
    (flow,) = case.traffic.flows
    assert flow.populate
    vph = 4 * flow.veh_per_hour_per_lane * (1.0 - sum(f.penetration for f in case.formation_flows))
    spacing = 3600.0 * V_LIMIT / vph
    usable = sum(max(L - 50.0, 0.0) for L in lengths) / sum(lengths)
    expected = (sum(lengths) - 100.0) / spacing * usable
    n = len(populate_places(vph, V_LIMIT, lengths, case.run.seed))
    assert n == pytest.approx(expected, rel=0.01)
    members = sum(len(f.formation.members) for f in case.formation_flows)
    assert 200 <= members <= 250
    assert 3900 <= n + members <= 4200
    assert case.traffic.warmup <= 120.0  # a short settling, not the road's travel time


def test_formation_flows_take_10_to_20_percent_in_several_shapes(case):
    """Penetration flows of the one traffic flow adding up to 10-20 %; formations of 3-4
    members; a column (one lane, slots one behind the other), three abreast (one row, three
    lanes) and a shape over two rows and lanes among them; starts spread over the road."""
    flows = case.formation_flows
    assert {f.of_flow for f in flows} == {"main"}
    assert 0.10 <= sum(f.penetration for f in flows) <= 0.20
    shapes = set()
    for f in flows:
        slots = [(m.slot.along, m.slot.lanes) for m in f.formation.members]
        assert 3 <= len(slots) <= 4
        alongs, lanes = {a for a, _ in slots}, {ln for _, ln in slots}
        shapes.add("column" if len(lanes) == 1 else "abreast" if len(alongs) == 1 else "rows and lanes")
    assert shapes == {"column", "abreast", "rows and lanes"}
    starts = sorted(f.start for f in flows)
    assert starts[0] < 5_000.0 and starts[-1] > 80_000.0 and len(flows) >= 50


def test_the_case_measures_the_step_without_drain_or_ssm(case):
    """No measurement sections (their drain would run SUMO alone with every vehicle for minutes
    after the run) and no SSM device (hundreds of members' devices would set SUMO's step)."""
    assert case.traffic.sections.enabled is False
    assert case.sumo.ssm == "off"
