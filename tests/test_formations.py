"""Several formations in one run (sim/formation.py): each formation's rows carry its id, each
has its own virtual car, and the formations share no state: every formation's rows equal, bit
for bit, those of a run of that formation alone."""
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import toy_law
from formation_traci.control.laws import register_law
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.runner import run_scenario

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


THESIS = Path(__file__).resolve().parents[1] / "scenarios" / "thesis"


def _east(top_level: bool) -> str:
    """case 2.3.3 (speed changes, turns both ways) 400 m to the left, its members renamed
    e_v1..e_v3: as the top-level formation of a run, or as the [[formations]] entry 'east'."""
    text = (THESIS / "case_2_3_3_varying.toml").read_text()
    leader = text[text.index("[leader]\n") + 9:text.index("[[members]]")].strip()
    members = text[text.index("[[members]]"):].replace('id = "v', 'id = "e_v')
    members = re.sub(r"position = \[([-0-9.]+), ([-0-9.]+)\]",
                     lambda m: f"position = [{m[1]}, {float(m[2]) + 400.0}]", members)
    if top_level:
        return f"[leader]\ny = 400.0\n{leader}\n{members}"
    return ('[[formations]]\nid = "east"\n[formations.leader]\ny = 400.0\n' + leader + "\n"
            + members.replace("[[members]]", "[[formations.members]]"))


def test_each_formation_is_analysed_as_if_it_ran_alone(tmp_path):
    """Issue 27: a run of two formations in free space (case 2.3.1 and case 2.3.3 side by
    side, 12 s: long enough for ISO 2631). Formations share no state, so each one's members
    (comfort included) and formation-level metrics equal those of its run alone, exactly;
    metrics.json keeps the first formation's run-level metrics (those of case 2.3.1 alone),
    adds formation_metrics and fleet, whose worst is the largest over the formations and mean
    the mean; the report has one row per formation and the fleet's; a run of one formation
    writes neither."""
    import json

    from analysis.api import analyze_run
    from analysis.runs.fleet import FORMATION_METRICS
    from analysis.runs.summary import KEY_METRICS

    west = (THESIS / "case_2_3_1_straight.toml").read_text().replace("duration = 30.0",
                                                                       "duration = 12.0")
    head = west[:west.index("[leader]")]  # run, vehicle
    _run(tmp_path, "both", west + "\n" + _east(top_level=False))
    _run(tmp_path, "west", west)
    _run(tmp_path, "east", head + _east(top_level=True))
    res = {k: analyze_run(tmp_path / k, out_dir=tmp_path / f"an_{k}", figures=False)
           for k in ("both", "west", "east")}
    doc = {k: json.loads((tmp_path / f"an_{k}" / "metrics.json").read_text()) for k in res}
    both = res["both"].members
    assert list(both.index) == ["v1", "v2", "v3", "e_v1", "e_v2", "e_v3"]
    assert list(both.formation_id) == ["f0"] * 3 + ["east"] * 3
    for k in ("west", "east"):  # every member of every formation, as in its run alone
        alone = res[k].members
        pd.testing.assert_frame_equal(both.loc[alone.index].drop(columns="formation_id"), alone,
                                      check_exact=True)
        assert alone["aw_lat_mps2"].notna().all() and alone["jerk_lat_peak_mps3"].notna().all()
    assert doc["both"]["run"] == doc["west"]["run"]  # the first formation's, layout unchanged
    for fid, k in (("f0", "west"), ("east", "east")):
        rec = doc["both"]["formation_metrics"][fid]
        alone = doc[k]["run"]
        assert {m: rec[m] for m in FORMATION_METRICS if m != "string_amplification"} == \
            {m: alone[m] for m in FORMATION_METRICS if m != "string_amplification"}
        assert rec["worst"] == alone["worst"]
        assert rec["string_amplification"] == doc[k]["formations"][0]["string_amplification"]
    fleet = doc["both"]["fleet"]
    assert (fleet["n_formations"], fleet["n_members"]) == (2, 6)
    w, e = doc["west"]["run"], doc["east"]["run"]
    for m in ("shape_error_rms_m", "shape_error_max_m"):
        assert fleet["worst"][m] == max(w[m], e[m])
        assert fleet["mean"][m] == pytest.approx((w[m] + e[m]) / 2, rel=1e-15)
    winners = set()
    for m in KEY_METRICS:
        vals = [x for x in (w["worst"][m], e["worst"][m]) if x is not None]
        assert fleet["worst"]["worst"][m] == (max(vals) if vals else None), m
        if len(vals) == 2 and vals[0] != vals[1]:
            winners.add("f0" if vals[0] > vals[1] else "east")
            assert fleet["worst_formation"]["worst"][m] == ("f0" if vals[0] > vals[1] else "east")
    assert winners == {"f0", "east"}  # each formation is the worst in some metric: a real max
    assert [f["id"] for f in doc["both"]["formations"]] == ["f0", "east"]
    assert [m["id"] for m in doc["both"]["meta"]["members"]] == list(both.index)
    html = (tmp_path / "an_both" / "report.html").read_text()
    i = html.index("<h2>Formations</h2>")
    table = html[i:html.index("</table>", i)]
    assert all(f'<td class="l">{r}</td>' in table
               for r in ("f0", "east", "fleet: mean of 2", "fleet: worst"))
    for k in ("west", "east"):  # one formation: nothing of the above
        assert "formation_metrics" not in doc[k] and "fleet" not in doc[k]
        assert "formation_id" not in res[k].members.columns
        assert "<h2>Formations</h2>" not in (tmp_path / f"an_{k}" / "report.html").read_text()
    assert not (res["both"].issues.severity == "warning").any()
