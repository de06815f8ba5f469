"""The World verbs (sim/world.py): a member leaves the run and the world at any step
(``retire``) and enters it again at a later step where its state puts it (``spawn``), in free
space and in SUMO (real libsumo)."""
import numpy as np
import pandas as pd

import formation_traci.sim.loop as loop
import formation_traci.run.road_parts as road_parts
from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario
from run_helpers import free_toml

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]
OUT_AT, BACK_AT = 1.0, 2.0  # [s]


class OutAndBack:
    """A transform that retires member ``i`` at OUT_AT and spawns it again at BACK_AT."""

    def __init__(self, i: int):
        self.i, self.world = i, None

    def sense(self, k, t, sensed, kin, rec):
        if abs(t - OUT_AT) < 1e-9:
            self.world.retire(t, np.array([self.i]), "test: out")
        elif abs(t - BACK_AT) < 1e-9:
            self.world.spawn(t, np.array([self.i]))

    def __call__(self, ref):
        return ref


def _capture(monkeypatch, module, name, tr):
    build = getattr(module, name)

    def wrapped(*a, **kw):
        parts = build(*a, **kw)
        tr.world = parts.world
        return parts
    monkeypatch.setattr(module, name, wrapped)


def _check(out, member, dt):
    traj = pd.read_parquet(out / "trajectories.parquet")
    ev = pd.read_parquet(out / "events.parquet")
    t = np.sort(traj[traj.vehicle_id == member].t.to_numpy())
    gone = (t > OUT_AT - 1e-9) & (t < BACK_AT - 1e-9)
    assert not gone.any()  # no rows while out of the run
    assert np.isclose(t, BACK_AT).any()  # in the run again from the step it was spawned
    assert t.max() > BACK_AT + 5 * dt  # rows again after it came back
    retired = ev[ev.kind == "member_retired"]
    assert retired.vehicle_id.tolist() == [member] and retired.t.tolist() == [OUT_AT]
    assert retired.detail.tolist() == ["test: out"]
    return traj, ev


def test_free_space_member_retires_and_spawns_again(tmp_path, monkeypatch):
    tr = OutAndBack(0)
    _capture(monkeypatch, loop, "free_space_run", tr)
    monkeypatch.setattr("formation_traci.run.scenario_run.free_space_run", loop.free_space_run)
    p = tmp_path / "s.toml"
    p.write_text(free_toml(3.0))
    res = run_scenario(load_scenario(p), tmp_path / "run", force=True, progress=False,
                       transforms=[tr])
    assert res.status == "completed"
    _check(tmp_path / "run", "a", 0.05)


def test_sumo_member_leaves_the_road_and_is_inserted_again_later(tmp_path, monkeypatch):
    tr = OutAndBack(1)
    _capture(monkeypatch, road_parts, "road_run", tr)
    path = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"
    sc = load_scenario(path, **{"run.duration": 4.0, "traffic.warmup": 10.0})
    res = run_scenario(sc, tmp_path / "run", scenario_path=path, force=True, progress=False,
                       transforms=[tr])
    assert res.status == "completed"
    traj, ev = _check(tmp_path / "run", "centre", sc.run.step)
    c = traj[(traj.vehicle_id == "centre") & (traj.t > BACK_AT + 0.2)]
    # back in SUMO where our model has it: SUMO's CoG within a few cm of ours
    assert (c.sumo_gap < 0.1).all() and c.sumo_gap.notna().all()
    assert not (ev.kind == "member_removed").any()  # the world took it out, not SUMO
    # a road run's formation: its members' and its virtual car's rows and events carry its id
    assert set(traj.formation_id) == {"f0"}
    mine = ev.vehicle_id.isin(["right", "centre", "left", "vc"])
    assert (ev.formation_id[mine] == "f0").all() and (ev.formation_id[~mine] == "").all()
    cf = pd.read_parquet(tmp_path / "run" / "comfort.parquet")
    assert set(cf.formation_id) == {"f0"}
