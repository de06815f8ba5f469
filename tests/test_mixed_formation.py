"""Mixed formations that hold together (issue 32, item 2): the virtual car accelerates and
brakes (outside emergencies) at most 90 % of what the weakest member's speed law can give,
the scenario is warned about when its speed profile asks more, and the reported LuST case (a
small truck with Table 3.6 gains behind cars, the leader slowing 28 -> 22 m/s) and the bundled
``mixed_truck`` run with no collision."""
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.control.governor import leader_accel
from formation_traci.control.schedule import FOLLOW_SHARE, GAIN_PRESETS, law_peak, scheduled_gain
from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario
from test_incidents import LUST, TRUCK

ROOT = Path(__file__).resolve().parents[1]
MIXED = ROOT / "scenarios" / "maneuvers" / "mixed_truck.toml"


def test_law_peak_is_the_maximum_of_the_scheduled_law():
    """Table 3.6 (G_min 0.05, G_max 1.3, K_min 1): d/de [((G_max - G_min) e^-e + G_min) e] = 0
    at (1 - e) e^-e = -G_min / (G_max - G_min), e = 1.12 m/s, K e = 0.513 m/s^2 (docs/model.md)."""
    g_min, g_max, k = 0.05, 1.3, 1.0
    e = 1.0
    for _ in range(50):  # Newton on f(e) = (G_max - G_min)(1 - e) e^-e + G_min
        f = (g_max - g_min) * (1 - e) * math.exp(-e) + g_min
        df = (g_max - g_min) * (e - 2) * math.exp(-e)
        e -= f / df
    peak = float(scheduled_gain(e, g_min, g_max, k) * e)
    assert e == pytest.approx(1.12, abs=0.01) and peak == pytest.approx(0.513, abs=1e-3)
    assert law_peak(g_min, g_max, k) == pytest.approx(peak, abs=1e-6)


def test_leader_braking_outside_emergencies_is_bounded_by_the_members():
    """A slot's gap law asking -1.3 m/s^2 (comfortable): the virtual car brakes at
    decel_follow; one asking -4 m/s^2 (below -decel_comfort: an emergency) is not bounded."""
    assert leader_accel(25.0, 25.0, 0.0, [-1.3], 1.5, 7.0, 0.46, 3.0) == pytest.approx(-0.46)
    assert leader_accel(25.0, 25.0, 0.0, [-4.0], 1.5, 7.0, 0.46, 3.0) == pytest.approx(-4.0)
    assert leader_accel(25.0, 25.0, 0.0, [-1.3], 1.5, 7.0) == pytest.approx(-1.3)  # not bounded


def _run(tmp_path, path, name, **over):
    sc = load_scenario(path, **over)
    res = run_scenario(sc, tmp_path / name, scenario_path=path, progress=False)
    out = tmp_path / name
    return res, json.loads((out / "run.json").read_text()), pd.read_parquet(out / "trajectories.parquet")


def test_bundled_mixed_truck_holds_with_the_virtual_car_bounded_by_the_truck(tmp_path):
    """mixed_truck: the profile's 0.75 m/s^2 slow-down is more than the truck's law gives: the
    run says so (run.json warnings), the virtual car brakes at most 0.9 x 0.513 m/s^2, and the
    truck stays within 2 m of its slot, no incident."""
    res, meta, traj = _run(tmp_path, MIXED, "mixed", **{"traffic.warmup": 20.0})
    assert res.status == "completed", meta["incidents"]
    assert not any(meta["incidents"][k] for k in ("member_collisions", "member_removed", "stranded"))
    assert any("truck" in w and "0.513" in w for w in meta["warnings"])
    # the truck's slot, 25 m behind car_centre's (bumper gap 25 - 3.0 - 2.279 = 19.72 m), is
    # too close to stop behind it by its law from 22 m/s (sim/column_gaps.py): warned, numbers
    b_t, b_c = law_peak(0.05, 1.3, 1.0), law_peak(*(lambda g: (g.g_min, g.g_max, g.k_min))(
        GAIN_PRESETS["table_3_4"]))
    need = 242.0 * (1 / b_t - 1 / b_c) + 22.0 * 0.05 + 2.0
    assert [w[:w.index(" (")] for w in meta["warnings"] if "in their column" in w] == [
        f"member 'truck' is 19.72 m behind 'car_centre' in their column; to stop behind it from "
        f"the leader's top speed 22.00 m/s it needs {need:.2f} m"]
    vc = traj[traj.vehicle_id == "vc"]
    limit = FOLLOW_SHARE * law_peak(0.05, 1.3, 1.0)
    assert vc.a_lon.min() >= -limit - 1e-9 and vc.a_lon.min() < -0.9 * limit
    assert traj[traj.vehicle_id == "truck"].e_lon.abs().max() < 2.0


@pytest.mark.skipif(not LUST.is_file(), reason="needs ../shared/realnet beside the checkout")
def test_lust_truck_slow_down_completes_without_collision(tmp_path):
    """Issue 32's LuST report with the defaults: status completed, no member collision, the
    truck within 2 m of its slot along the road and in its lane (|e_lat| < 0.5 m). The same
    scenario with bound_by_members = false collides (tests/test_incidents.py)."""
    p = tmp_path / "truck.toml"
    p.write_text(TRUCK.replace("bound_by_members = false\n", ""))
    res, meta, traj = _run(tmp_path, p, "truck")
    assert res.status == "completed", meta["incidents"]
    assert meta["incidents"]["member_collisions"] == 0
    truck = traj[traj.vehicle_id == "truck"]
    assert truck.e_lon.abs().max() < 2.0 and truck.e_lat.abs().max() < 0.5
    assert np.all(np.isfinite(truck.v))
