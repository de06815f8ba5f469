"""The set-up and per-step fast paths of issue 18 give, bit for bit, what the straightforward
code they replace gives (the straightforward code is written out here as the reference):
compiled frame conversions, the Bernstein map u(s), the ball tree and clearance of a line's
samples, Parquet columns built from buffers. And a run no longer imports pandas (its import
was ~1 s of every run's start). No timing here: benchmarks/ measures the speed."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from scipy.interpolate import BPoly
from scipy.spatial import cKDTree

from formation_traci.record.writer import _arrow, _arrow_strings
from formation_traci.road.bernstein import ball_tree, clearance, hermite_bpoly
from formation_traci.road.fast_line import LEAF_SIZE, WINDOW
from formation_traci.road.geometry import ReferenceLine
from formation_traci.sim.sumo_types import cog_to_sumo, cog_to_sumo_rows, sumo_to_cog, sumo_to_cog_rows

ROOT = Path(__file__).resolve().parents[1]


def reference_tree(xy, leaf):
    """The recursive ball tree the compiled one replaces (rows lo, hi, left, right, cx, cy, r)."""
    nodes = []

    def build(lo, hi):
        idx = len(nodes)
        pts = xy[lo:hi]
        c = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        r = float(np.max(np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1])))
        nodes.append([lo, hi, -1, -1, float(c[0]), float(c[1]), r * (1.0 + 1e-12) + 1e-9])
        if hi - lo > leaf:
            mid = (lo + hi) // 2
            nodes[idx][2], nodes[idx][3] = build(lo, mid), build(mid, hi)
        return idx

    build(0, len(xy))
    return np.array(nodes, dtype=float)


def reference_clearance(xy, window):
    """The k-nearest query the compiled clearance replaces."""
    n = len(xy)
    k = min(2 * window + 2, n)
    ds = float(np.hypot(*(xy[1] - xy[0])))
    dist, idx = cKDTree(xy).query(xy, k=k, distance_upper_bound=4.0 * window * max(ds, 1e-9))
    dist, idx = np.asarray(dist).reshape(n, -1), np.asarray(idx).reshape(n, -1)
    outside = (np.abs(idx - np.arange(n)[:, None]) > window) & np.isfinite(dist)
    out = np.where(outside, dist, np.inf).min(axis=1)
    if k < 2 * window + 2:
        out[:] = 0.0
    return out


def lines():
    t = np.linspace(0.0, 6.0 * np.pi, 300)
    spiral = np.column_stack([300 * np.cos(t) + 5 * t, 300 * np.sin(t) + 40 * t])  # passes near itself
    s = np.linspace(0.0, 2.0 * np.pi, 60)
    eight = np.column_stack([60 * np.cos(s), 30 * np.sin(2 * s) + s])  # crosses itself
    straight = np.column_stack([np.linspace(0.0, 3000.0, 40), np.zeros(40)])
    short = np.column_stack([np.linspace(0.0, 30.0, 10), np.zeros(10)])  # fewer samples than a window
    return [ReferenceLine.from_points(p) for p in (spiral, eight, straight, short)]


def test_compiled_frame_conversions_equal_the_numpy_ones_bit_for_bit():
    rng = np.random.default_rng(7)
    n = 20000
    x, y = rng.uniform(-1e4, 1e5, n), rng.uniform(-1e4, 1e4, n)
    psi = np.concatenate([rng.uniform(-7.0, 7.0, n // 2), rng.normal(0.0, 1e-3, n // 2)])
    psi[:8] = [0.0, np.pi / 2, -np.pi / 2, np.pi, -np.pi, 2 * np.pi, -0.0, 1.5 * np.pi]
    d = rng.uniform(0.0, 5.0, n)
    for a, b in zip(cog_to_sumo(x, y, psi, d), cog_to_sumo_rows(x, y, psi, d)):
        np.testing.assert_array_equal(a, b)
    ang = np.concatenate([rng.uniform(0.0, 360.0, n // 2), rng.normal(90.0, 1e-3, n // 2)])
    for a, b in zip(sumo_to_cog(x, y, ang, d), sumo_to_cog_rows(np.column_stack([x, y]), ang, d)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("m", [1, 7, 500])
def test_hermite_bpoly_equals_scipys_from_derivatives(m):
    rng = np.random.default_rng(m)
    xi = np.cumsum(rng.uniform(0.5, 30.0, m + 1))
    yi = rng.normal(size=(m + 1, 3)) * [100.0, 1.0, 0.01]
    a = BPoly.from_derivatives(xi, yi, extrapolate=True)
    b = hermite_bpoly(xi, yi, extrapolate=True)
    np.testing.assert_array_equal(a.c, b.c)
    np.testing.assert_array_equal(a.x, b.x)
    assert b.extrapolate


def test_compiled_ball_tree_and_clearance_equal_the_python_ones():
    for line in lines():
        xy = np.asarray(line.tree.data, dtype=float)
        np.testing.assert_array_equal(ball_tree(xy, LEAF_SIZE), reference_tree(xy, LEAF_SIZE))
        ds = float(np.hypot(*(xy[1] - xy[0])))
        got = clearance(xy, WINDOW, 4.0 * WINDOW * max(ds, 1e-9))
        np.testing.assert_array_equal(got, reference_clearance(xy, WINDOW))
    # the self-approaching spiral has finite clearances below the window's length
    xy = np.asarray(lines()[0].tree.data, dtype=float)
    assert np.isfinite(clearance(xy, WINDOW, 4.0 * WINDOW)).all()


def test_parquet_columns_from_buffers_equal_pa_array():
    for data in (np.array([1.5, np.nan, -3.0]), np.arange(5, dtype=np.int32),
                 np.array([True, False, True] * 7), np.zeros(0), np.zeros(0, dtype=bool)):
        got, ref = _arrow(data), pa.array(data)
        got.validate(full=True)
        assert got.type == ref.type and got.null_count == ref.null_count == 0
        np.testing.assert_array_equal(got.to_numpy(zero_copy_only=False),
                                      ref.to_numpy(zero_copy_only=False))  # NaN where NaN
    labels = ["a", "éx", "", "member 1"]
    assert _arrow_strings(labels).equals(pa.array(labels, type=pa.string()))
    assert _arrow_strings([]).equals(pa.array([], type=pa.string()))


def test_a_run_does_not_import_pandas(tmp_path):
    """pyarrow's pa.array imported pandas on its first call; the recorder no longer calls it."""
    code = ("import sys\n"
            "from formation_traci.scenario import load_scenario\n"
            "from formation_traci.sim.runner import run_scenario\n"
            f"sc = load_scenario({str(ROOT / 'scenarios/thesis/dynamic_case4_straight.toml')!r}, "
            "**{'run.duration': 0.5})\n"
            f"r = run_scenario(sc, {str(tmp_path / 'run')!r}, progress=False)\n"
            "assert r.status == 'completed', r.reason\n"
            "print('pandas' in sys.modules)\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         cwd=tmp_path, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "False"
