"""The reference line's compiled evaluation (road/fast_line.py, used by every step) against
the fitted line it packs (road/geometry.py ReferenceLine: scipy's B-spline and BPoly).

The fit is scipy's; the kernels evaluate the same piecewise polynomials in power/Bernstein
form, so the two agree to rounding (positions 1e-9 m, angles 1e-12 rad).
"""
from __future__ import annotations

import numpy as np
import pytest

from formation_traci.record.columns import FILLED_BY_CALLER, SIGNAL_COLUMNS, TRAJECTORY_COLUMNS
from formation_traci.road.fast_line import frame_many, to_frenet_many, to_frenet_one
from formation_traci.road.line_pack import FastLine
from formation_traci.road.geometry import reference_line_from_net
from sumo_nets import net_path


@pytest.fixture(scope="module", params=["straight3", "curved3"])
def line(request):
    return reference_line_from_net(net_path(request.param), ["entry", "main"], 1)


@pytest.fixture(scope="module")
def curved():
    return reference_line_from_net(net_path("curved3"), ["entry", "main"], 1)


def assert_close(a, b, what, rtol=1e-10, atol=1e-9):
    np.testing.assert_allclose(a, b, rtol=rtol, atol=atol, equal_nan=True, err_msg=what)


def test_frame_equals_reference(line):
    rng = np.random.default_rng(4)
    s = np.concatenate([rng.uniform(-60.0, line.length + 60.0, 4000), line.s_nodes,
                        [0.0, line.length, -1e-9, line.length + 1e-9, -500.0, line.length + 500.0]])
    F = frame_many(FastLine.from_reference_line(line).G, s)
    f = line.frame(s)
    assert_close(F[:, 0:2], f.position, "position", rtol=0.0, atol=1e-9)
    assert_close(F[:, 2:4], f.tangent, "tangent", rtol=0.0, atol=1e-12)
    assert_close(F[:, 4], f.heading, "heading", rtol=0.0, atol=1e-12)
    assert_close(F[:, 5], f.curvature, "curvature", rtol=0.0, atol=1e-14)
    assert_close(F[:, 6], f.curvature_rate, "curvature rate", rtol=0.0, atol=1e-16)
    outside = (s < 0.0) | (s > line.length)
    assert np.all(F[outside, 5] == 0.0) and np.all(F[outside, 6] == 0.0)


def test_to_frenet_equals_reference(line):
    fline = FastLine.from_reference_line(line)
    rng = np.random.default_rng(5)
    n = 3000
    s_true = rng.uniform(-120.0, line.length + 120.0, n)  # beyond both ends too
    d_true = rng.uniform(-30.0, 30.0, n)
    xy = np.vstack([line.from_frenet(s_true, d_true),
                    rng.uniform(-500.0, 6500.0, (50, 2))])  # far off the line
    s_ref, d_ref = line.to_frenet(xy)
    m = len(xy)
    guesses = {
        "none": np.full(m, np.nan),
        "good": s_ref + rng.normal(0.0, 2.0, m),
        "far": s_ref + rng.choice([-1.0, 1.0], m) * rng.uniform(200.0, 3000.0, m),
        "zero": np.zeros(m),
        "wild": rng.choice([-1e7, 1e7, np.inf, -np.inf], m),
    }
    for name, g in guesses.items():
        s_f, d_f = to_frenet_many(fline.G, xy, g)
        # the reference's vectorised Newton keeps iterating converged points while others
        # have not (steps < 1e-10 m), so allow its tolerance on top of rounding
        assert_close(s_f, s_ref, f"s, guess {name}", rtol=0.0, atol=1e-9)
        assert_close(d_f, d_ref, f"d, guess {name}", rtol=0.0, atol=1e-9)
    # the round trip itself (sanity of the data, not of the kernel); the reference's Newton
    # moves at most 50 x 2 m from its seed, so points > 100 m past an end do not converge
    # (the kernel reproduces that too)
    near = (s_true > -90.0) & (s_true < line.length + 90.0)
    assert np.max(np.abs(s_ref[:n][near] - s_true[near])) < 1e-7
    assert np.max(np.abs(s_ref[:n][~near] - s_true[~near])) > 1.0
    s1, d1 = fline.to_frenet(xy[:5])
    assert_close(s1, s_ref[:5], "wrapper")


def test_to_frenet_edge_inputs(curved):
    fline = FastLine.from_reference_line(curved)
    s, d = fline.to_frenet(np.array([[np.nan, 0.0], [100.0, -5.0]]))
    assert np.isnan(s[0]) and np.isnan(d[0]) and np.isfinite(s[1])
    s, d = fline.to_frenet(np.empty((0, 2)))
    assert s.shape == (0,) and d.shape == (0,)
    xy = curved.from_frenet(np.array([5.0, 1234.5, 3000.0]), np.array([-3.5, 0.0, 7.0]))
    s_ref, d_ref = curved.to_frenet(xy)
    for g in (None, 1000.0, [5.0, 1234.0, 3001.0]):
        s, d = fline.to_frenet(xy[::-1][::-1], g)  # a non-contiguous view
        assert_close(s, s_ref, f"guess {g}")
        assert_close(d, d_ref, f"guess {g}")
    for i in range(3):
        assert_close(to_frenet_one(fline.G, xy[i, 0], xy[i, 1], np.nan), (s_ref[i], d_ref[i]),
                     "to_frenet_one")
    assert_close(fline.frame(1234.5), frame_many(fline.G, np.array([1234.5]))[0], "frame")


def test_signal_columns_follow_the_contract():
    names = [c.name for c in TRAJECTORY_COLUMNS]
    assert list(SIGNAL_COLUMNS) == [c for c in names if c not in FILLED_BY_CALLER]
    assert len(SIGNAL_COLUMNS) == 26  # 23 of the seed's model + power, drag_force, drag_ratio
