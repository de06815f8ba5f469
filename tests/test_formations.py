"""Several formations in one run (sim/formation.py): each formation's rows carry its id, each
has its own virtual car, and the formations share no state: every formation's rows equal, bit
for bit, those of a run of that formation alone."""
import numpy as np
import pandas as pd
import pytest

import toy_law
from formation_traci.control.laws import register_law
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.sim.runner import run_scenario

RUN = '[run]\nduration = 6.0\n[vehicle]\nmodel = "{model}"\n'
WEST = ('[leader]\nspeed = 20.0\n'
        '[[members]]\nid = "a"\noffset = [0.0, 3.5]\nposition = [-2.0, 2.0]\n'
        '[[members]]\nid = "b"\noffset = [-8.0, 0.0]\nposition = [-10.0, 1.0]\n')
EAST_TOP = ('[leader]\nx = 0.0\ny = 200.0\nspeed = 15.0\nyaw_rate_deg_s = 3.0\n'
            '[[members]]\nid = "c"\noffset = [0.0, -3.5]\nposition = [1.0, 195.0]\n'
            '[[members]]\nid = "d"\noffset = [-8.0, 0.0]\nposition = [-9.0, 201.0]\n'
            '[controller]\nlaw = "{law}"\nk = 1.5\n')
EAST_LIST = ('[[formations]]\nid = "east"\ncontroller = {{ law = "{law}", k = 1.5 }}\n'
             '[formations.leader]\nx = 0.0\ny = 200.0\nspeed = 15.0\nyaw_rate_deg_s = 3.0\n'
             '[[formations.members]]\nid = "c"\noffset = [0.0, -3.5]\nposition = [1.0, 195.0]\n'
             '[[formations.members]]\nid = "d"\noffset = [-8.0, 0.0]\nposition = [-9.0, 201.0]\n')


def _run(tmp_path, name, text):
    p = tmp_path / f"{name}.toml"
    p.write_text(text)
    res = run_scenario(load_scenario(p), tmp_path / name, force=True, progress=False)
    assert res.status == "completed"
    return (pd.read_parquet(tmp_path / name / "trajectories.parquet"),
            pd.read_parquet(tmp_path / name / "comfort.parquet"))


def _rows(df, ids):
    out = df[df.vehicle_id.isin(ids)].sort_values(["vehicle_id", "t"], kind="stable")
    return out.drop(columns=["vehicle_id", "formation_id"]).reset_index(drop=True)


@pytest.mark.parametrize("model,law", [("kinematic", "virtual_structure"),
                                       ("dynamic", "virtual_structure"),
                                       ("dynamic", "toy_constant_speed")])
def test_two_formations_in_free_space_keep_their_ids_and_share_no_state(tmp_path, model, law):
    register_law("toy_constant_speed", toy_law)
    both, both_cf = _run(tmp_path, "both", RUN.format(model=model) + WEST + EAST_LIST.format(law=law))
    west, west_cf = _run(tmp_path, "west", RUN.format(model=model) + WEST)
    east, east_cf = _run(tmp_path, "east", RUN.format(model=model) + EAST_TOP.format(law=law))
    ids = both.groupby("vehicle_id").formation_id.unique().map(list).to_dict()
    assert ids == {"a": ["f0"], "b": ["f0"], "vc:f0": ["f0"],
                   "c": ["east"], "d": ["east"], "vc:east": ["east"]}
    assert set(both_cf.formation_id) == {"f0", "east"}
    # each formation's rows equal the rows of that formation run alone, bit for bit
    pd.testing.assert_frame_equal(_rows(both, ["a", "b"]), _rows(west, ["a", "b"]), check_exact=True)
    pd.testing.assert_frame_equal(_rows(both, ["c", "d"]), _rows(east, ["c", "d"]), check_exact=True)
    pd.testing.assert_frame_equal(_rows(both, ["vc:f0"]), _rows(west, ["vc"]), check_exact=True)
    pd.testing.assert_frame_equal(_rows(both, ["vc:east"]), _rows(east, ["vc"]), check_exact=True)
    pd.testing.assert_frame_equal(_rows(both_cf, ["c", "d"]), _rows(east_cf, ["c", "d"]),
                                  check_exact=True)
    # the two virtual cars are two: straight at 20 m/s, and turning at 3 deg/s at 15 m/s
    vc0 = both[both.vehicle_id == "vc:f0"].sort_values("t")
    assert np.allclose(vc0.x, 20.0 * vc0.t, atol=1e-9) and np.allclose(vc0.y, 0.0)
    vc1 = both[both.vehicle_id == "vc:east"].sort_values("t")
    w, R = np.deg2rad(3.0), 15.0 / np.deg2rad(3.0)  # circle of radius v / omega
    assert np.allclose(vc1.x, R * np.sin(w * vc1.t), atol=1e-6)
    assert np.allclose(vc1.y, 200.0 + R * (1 - np.cos(w * vc1.t)), atol=1e-6)
    if law == "toy_constant_speed":  # the east members run the toy law, the west ones the seed's
        last = both[both.t == both.t.max()].set_index("vehicle_id")
        assert last.loc["c", "v"] == pytest.approx(toy_law.V_SET, abs=1e-3)  # 15 -> 12.5 m/s, tau 0.5 s
        assert last.loc["a", "v"] == pytest.approx(20.0, abs=0.5)


def test_formation_ids_and_member_ids_are_unique(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(RUN.format(model="kinematic") + WEST
                 + EAST_LIST.format(law="virtual_structure").replace('id = "c"', 'id = "a"'))
    with pytest.raises(ScenarioError, match="unique over all formations"):
        load_scenario(p)
    p.write_text(RUN.format(model="kinematic") + WEST
                 + EAST_LIST.format(law="virtual_structure").replace('id = "east"', 'id = "f0"'))
    with pytest.raises(ScenarioError, match="ids must be unique"):
        load_scenario(p)


def test_analysis_of_several_formations_covers_the_first_and_says_so(tmp_path):
    """Until per-formation metrics exist, a run of several formations is analysed as its first
    formation: its members only, its own virtual car, and a warning naming the others."""
    from analysis.api import analyze_run
    _run(tmp_path, "both", RUN.format(model="kinematic") + WEST
         + EAST_LIST.format(law="virtual_structure"))
    _run(tmp_path, "west", RUN.format(model="kinematic") + WEST)
    both = analyze_run(tmp_path / "both", figures=False)
    west = analyze_run(tmp_path / "west", figures=False)
    assert sorted(both.members.index) == ["a", "b"]
    pd.testing.assert_frame_equal(both.members, west.members)
    warn = both.issues[both.issues.kind == "several_formations"]
    assert len(warn) == 1 and "east" in warn.detail.iloc[0]
    assert not (west.issues.kind == "several_formations").any()
