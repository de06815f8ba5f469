"""The reference seam (control/reference.py): transforms change what the kernels track
without touching them. Slot rates enter the desired point exactly (eq 2.4 / road targets
differentiated by hand), and a delay channel (control/channel.py) makes a member lag its
slot by v d on a straight road at constant speed v."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from formation_traci.control.channel import Delay
from formation_traci.control.formation import rigid_target_at
from formation_traci.road.line_pack import packed
from formation_traci.road.geometry import reference_line_from_net
from formation_traci.road.targets import road_target_at
from formation_traci.scenario import parse_scenario
from formation_traci.runner import run_scenario
from sumo_nets import net_path

SCENARIO = """
name = "delay"
[run]
duration = 30.0
step = 0.05
[vehicle]
model = "kinematic"
[leader]
speed = 20.0
[[members]]
id = "a"
offset = [-10.0, 3.5]
position = [-10.0, 3.5]
[[members]]
id = "b"
offset = [-10.0, -3.5]
position = [-10.0, -3.5]
"""


def _slot(t):
    """A slot moving on both axes: dx = 2 sin(0.7 t) - 5, dy = 3.5 cos(0.4 t) [m]."""
    return (2 * np.sin(0.7 * t) - 5, 3.5 * np.cos(0.4 * t), 1.4 * np.cos(0.7 * t),
            -1.4 * np.sin(0.4 * t), -0.98 * np.sin(0.7 * t), -0.56 * np.cos(0.4 * t))


@pytest.mark.jit_off
def test_moving_rigid_slot_derivatives_are_exact():
    """p(t) of a moving slot about a turning, accelerating virtual car: the kernel's p' and
    p'' equal central differences of p and p' (h = 1e-4 s) to 1e-6."""
    def vc(t):  # x, y, theta, v, omega, v_dot, omega_dot along an exact circle-ish path
        th = 0.1 * t + 0.02 * t * t
        v = 20.0 + 0.5 * t
        return (100 + 30 * t, 5 * t * t, th, v, 0.1 + 0.04 * t, 0.5, 0.04)

    def p(t):
        X, Y, th, v, om, vd, omd = vc(t)
        return np.array(rigid_target_at(np.array([X, Y, th, v, om, vd, omd]),
                                        np.array(_slot(t), dtype=float)))

    h, t = 1e-4, 3.0
    base = p(t)
    # position part of p(t) comes from X, Y given; only the rotating offset is differentiated
    # by the kernel, so compare p' against d/dt of (p - p_vc) plus the vc's own velocity
    def rel(tt):
        X, Y = vc(tt)[:2]
        return p(tt)[:2] - (X, Y)
    d_rel = (rel(t + h) - rel(t - h)) / (2 * h)
    X, Y, th, v = vc(t)[:4]
    np.testing.assert_allclose(base[2:4], d_rel + v * np.array([np.cos(th), np.sin(th)]), atol=1e-6)
    dd = (p(t + h)[2:4] - p(t - h)[2:4]) / (2 * h)
    # the virtual car's velocity is v t(theta): its derivative enters through v_dot and omega
    np.testing.assert_allclose(base[4:6], dd, atol=2e-5)


@pytest.mark.jit_off
def test_moving_road_slot_derivatives_are_exact():
    """Road-frame slot moving across lanes on the curved motorway: p' and p'' equal central
    differences (virtual car s(t) = 900 + 25 t + 0.15 t^2)."""
    line = reference_line_from_net(net_path("curved3"), ["entry", "main"], 1)
    G = packed(line)

    def p(t):
        return np.array(road_target_at(G, 900 + 25 * t + 0.15 * t * t, 25 + 0.3 * t, 0.3, *_slot(t)))

    h, t = 1e-4, 2.0
    base = p(t)
    np.testing.assert_allclose(base[2:4], (p(t + h)[0:2] - p(t - h)[0:2]) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(base[4:6], (p(t + h)[2:4] - p(t - h)[2:4]) / (2 * h), atol=1e-5)


def _run(tmp_path, name, transforms):
    import tomllib
    sc = parse_scenario(tomllib.loads(SCENARIO))
    res = run_scenario(sc, tmp_path / name, force=True, progress=False, transforms=transforms)
    assert res.status == "completed", res.reason
    return pd.read_parquet(tmp_path / name / "trajectories.parquet")


def test_delay_channel_makes_a_member_lag_by_v_times_delay(tmp_path):
    """Member a receives the virtual car 0.5 s late, member b without delay. At 20 m/s on a
    straight line a settles 20 x 0.5 = 10 m behind its true slot (the recorded 'vc' rows are
    the true virtual car) while tracking the slot it believes in (recorded e ~ 0); b sits on
    its slot. A zero-delay channel gives bit-identical trajectories."""
    plain = _run(tmp_path, "plain", [])
    zero = _run(tmp_path, "zero", [Delay([0.0, 0.0], 0.01)])
    pd.testing.assert_frame_equal(plain, zero)
    late = _run(tmp_path, "late", [Delay([0.5, 0.0], 0.01)])
    end = late[late.t >= 25.0]
    vc = end[end.vehicle_id == "vc"].set_index("t")
    a, b = (end[end.vehicle_id == m].set_index("t") for m in ("a", "b"))
    lag_a = (vc.x - 10.0) - a.x  # true slot x minus member x [m] (road along +x)
    assert lag_a.mean() == pytest.approx(10.0, abs=0.05)
    assert (a.y - 3.5).abs().max() < 0.01 and a.e_lon.abs().max() < 0.01
    assert ((vc.x - 10.0) - b.x).abs().max() < 0.01 and (b.y + 3.5).abs().max() < 0.01
    vc_plain, vc_late = (df[df.vehicle_id == "vc"][["x", "y"]].to_numpy() for df in (plain, late))
    np.testing.assert_array_equal(vc_plain, vc_late)  # the recorded virtual car is the true one


def test_lane_shift_maneuver_moves_a_slot_smoothly(tmp_path):
    """Member a (kinematic) shifts from dy = 3.5 m to 0 m between t = 5 and 10 s: its desired
    point follows the smoothstep with exact rates, so it stays on it within 1 cm throughout
    and ends on the new slot; member b is untouched."""
    from formation_traci.control.maneuvers import LaneShift
    shift = LaneShift(0, 3.5, 0.0, 5.0, 5.0)
    df = _run(tmp_path, "shift", [shift])
    vc = df[df.vehicle_id == "vc"].set_index("t")
    a = df[df.vehicle_id == "a"].set_index("t")
    want = np.array([shift.offset(t)[0] for t in a.index])
    settled = a.index >= 3.0
    np.testing.assert_allclose((a.y - vc.y)[settled], want[settled], atol=0.01)
    assert a.y[a.index >= 12.0].abs().max() < 0.01
    plain = _run(tmp_path, "plain", [])
    b, b0 = (d[d.vehicle_id == "b"].reset_index(drop=True) for d in (df, plain))
    pd.testing.assert_frame_equal(b, b0)
