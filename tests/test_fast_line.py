"""The reference line's compiled evaluation (road/fast_line.py: ReferenceLine.frame and
to_frenet call it) against the fitted line it packs, evaluated independently here with
scipy's B-spline and BPoly (``scipy_frame``, ``scipy_to_frenet``: the formulas
road/geometry.py used before it called the kernels).

The fit is scipy's; the kernels evaluate the same piecewise polynomials in power/Bernstein
form, so the two agree to rounding (positions 1e-9 m, angles 1e-12 rad).
"""
from __future__ import annotations

import numpy as np
import pytest

from run_contract.columns import TRAJECTORY_COLUMNS
from formation_traci.record.columns import FILLED_BY_CALLER, SIGNAL_COLUMNS
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


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def scipy_frame(line, s):
    """Position, tangent, normal, heading, curvature, curvature rate at s from scipy's
    spline c(u) and u(s) directly (straight past the ends)."""
    s = np.asarray(s, dtype=float)
    sc = np.clip(s, 0.0, line.length)
    u = np.asarray(line.u_of_s(sc.reshape(-1))).reshape(s.shape)
    c1, c2, c3 = line.curve_d1(u), line.curve_d2(u), line.curve_d3(u)
    g = np.hypot(c1[..., 0], c1[..., 1])
    t = c1 / g[..., None]
    cr12 = c1[..., 0] * c2[..., 1] - c1[..., 1] * c2[..., 0]
    cr13 = c1[..., 0] * c3[..., 1] - c1[..., 1] * c3[..., 0]
    kappa = cr12 / g ** 3
    kappa_rate = (cr13 / g ** 3 - 3.0 * cr12 * _dot(c1, c2) / g ** 5) / g
    idx = np.clip(np.searchsorted(line.s_nodes, sc), 0, len(line.s_nodes) - 1)
    ref = line.heading_nodes[idx]
    dh = np.arctan2(t[..., 1], t[..., 0]) - ref
    heading = ref + (np.pi - np.mod(np.pi - dh, 2.0 * np.pi))
    pos = line.curve(u) + (s - sc)[..., None] * t
    outside = s != sc
    normal = np.stack([-t[..., 1], t[..., 0]], axis=-1)
    return (pos, t, normal, heading, np.where(outside, 0.0, kappa),
            np.where(outside, 0.0, kappa_rate))


def scipy_to_frenet(line, xy):
    """(s, d) by the vectorised Newton iteration from the nearest 1 m sample (cKDTree)."""
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    _, i = line.tree.query(p)
    s = line.tree_s[i].astype(float)
    max_step = 2.0 * (line.tree_s[1] - line.tree_s[0])
    for _ in range(50):
        pos, t, n, _, kappa, _ = scipy_frame(line, s)
        r = p - pos
        along, d = _dot(r, t), _dot(r, n)
        denom = 1.0 - kappa * d
        step = np.clip(along / np.where(denom > 0.1, denom, 1.0), -max_step, max_step)
        s = s + step
        if np.max(np.abs(step), initial=0.0) < 1e-10:
            break
    pos, _, n, _, _, _ = scipy_frame(line, s)
    return s, _dot(p - pos, n)


def assert_close(a, b, what, rtol=1e-10, atol=1e-9):
    np.testing.assert_allclose(a, b, rtol=rtol, atol=atol, equal_nan=True, err_msg=what)


def test_frame_equals_reference(line):
    rng = np.random.default_rng(4)
    s = np.concatenate([rng.uniform(-60.0, line.length + 60.0, 4000), line.s_nodes,
                        [0.0, line.length, -1e-9, line.length + 1e-9, -500.0, line.length + 500.0]])
    F = frame_many(FastLine.from_reference_line(line).G, s)
    pos, tan, _, heading, kappa, kappa_rate = scipy_frame(line, s)
    assert_close(F[:, 0:2], pos, "position", rtol=0.0, atol=1e-9)
    assert_close(F[:, 2:4], tan, "tangent", rtol=0.0, atol=1e-12)
    assert_close(F[:, 4], heading, "heading", rtol=0.0, atol=1e-12)
    assert_close(F[:, 5], kappa, "curvature", rtol=0.0, atol=1e-14)
    assert_close(F[:, 6], kappa_rate, "curvature rate", rtol=0.0, atol=1e-16)
    f = line.frame(s)  # the ReferenceLine's methods are the kernel
    assert np.array_equal(f.position, F[:, 0:2]) and np.array_equal(f.curvature, F[:, 5])
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
    s_ref, d_ref = scipy_to_frenet(line, xy)
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
    s_ref, d_ref = scipy_to_frenet(curved, xy)
    assert np.array_equal(curved.to_frenet(xy)[0], fline.to_frenet(xy)[0])
    for g in (None, 1000.0, [5.0, 1234.0, 3001.0]):
        s, d = fline.to_frenet(xy[::-1][::-1], g)  # a non-contiguous view
        assert_close(s, s_ref, f"guess {g}")
        assert_close(d, d_ref, f"guess {g}")
    for i in range(3):
        assert_close(to_frenet_one(fline.G, xy[i, 0], xy[i, 1], np.nan), (s_ref[i], d_ref[i]),
                     "to_frenet_one")
    assert_close(fline.frame(1234.5), frame_many(fline.G, np.array([1234.5]))[0], "frame")


def test_signal_columns_follow_the_contract():
    names = [c.name for c in TRAJECTORY_COLUMNS if not c.derived_from]  # formation_id: the writer's
    assert list(SIGNAL_COLUMNS) == [c for c in names if c not in FILLED_BY_CALLER]
    assert len(SIGNAL_COLUMNS) == 26  # 23 of the seed's model + power, drag_force, drag_ratio
