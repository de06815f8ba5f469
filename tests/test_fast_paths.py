"""The set-up and per-step fast paths of issue 18 give, bit for bit, what the straightforward
code they replace gives (the straightforward code is written out here as the reference):
compiled frame conversions, the Bernstein map u(s), the ball tree and clearance of a line's
samples, Parquet columns built from buffers. And a run no longer imports pandas (its import
was ~1 s of every run's start). No timing here: benchmarks/ measures the speed."""
from __future__ import annotations

import math
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
from formation_traci.road.lanes import LaneShapes
from formation_traci.sumo.events import PLACEMENT_TOLERANCE
from formation_traci.sumo.types import cog_to_sumo, cog_to_sumo_rows, sumo_to_cog, sumo_to_cog_rows

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


def reference_lane_xy(lane, pos, lat):
    """SUMO's (lane, position, lateral offset) -> x, y on numpy arrays, as LaneShapes.xy was."""
    pts = np.asarray([p[:2] for p in lane.getShape()], dtype=float)
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    scale = cum[-1] / lane.getLength() if lane.getLength() > 0 else 1.0
    g = min(max(pos * scale, 0.0), cum[-1])
    k = int(min(max(np.searchsorted(cum, g, side="right") - 1, 0), len(pts) - 2))
    seg = pts[k + 1] - pts[k]
    length = math.hypot(*seg) or 1.0
    t = seg / length
    p = pts[k] + t * (g - cum[k])
    return float(p[0] - lat * t[1]), float(p[1] + lat * t[0])


def test_lane_shape_points_equal_the_numpy_ones_bit_for_bit():
    """The per-member lane point of sumo_gap (sumo/sense.py lane_point has its arithmetic),
    on curved and real lanes (positions before, on, between and past the shape points; lateral offsets both ways)."""
    import sumolib
    rng = np.random.default_rng(3)
    nets = [ROOT / "sumo_nets" / "curved3.net.xml", ROOT / "sumo_nets" / "lanedrop.net.xml"]
    for net_file in nets:
        net = sumolib.net.readNet(str(net_file), withInternal=True)
        shapes = LaneShapes(net)
        for edge in net.getEdges(withInternal=True):
            for lane in edge.getLanes():
                length = lane.getLength()
                pos = np.concatenate([[-1.0, 0.0, length, length + 3.0],
                                      rng.uniform(0.0, length, 12)])
                for p, lat in zip(pos, rng.uniform(-2.5, 2.5, len(pos))):
                    assert shapes.xy(lane.getID(), p, lat) == reference_lane_xy(lane, p, lat)


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
            "from formation_traci.runner import run_scenario\n"
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


@pytest.mark.jit_off  # also as plain Python (NUMBA_DISABLE_JIT=1)
def test_py_hypot_is_pythons_math_hypot_bit_for_bit():
    """The compiled lane-point distance uses CPython's hypot, not the C library's (they
    differ in the last bit for about 1 input in 1000)."""
    from formation_traci.core.kernels import py_hypot
    rng = np.random.default_rng(11)
    n = 200_000
    a = rng.uniform(-5, 5, n) * 10.0 ** rng.integers(-12, 6, n)
    b = rng.uniform(-5, 5, n) * 10.0 ** rng.integers(-12, 6, n)
    special = [(0.0, 0.0), (-0.0, 0.0), (np.inf, np.nan), (-np.inf, 1.0), (np.nan, np.inf),
               (np.nan, 1.0), (1e-310, 1e-311), (5e-324, 0.0), (1e308, 1e308), (3.0, 4.0)]
    pairs = special + list(zip(a.tolist(), b.tolist()))
    got = np.array([py_hypot(x, y) for x, y in pairs])
    ref = np.array([math.hypot(x, y) for x, y in pairs])
    assert np.array_equal(got, ref, equal_nan=True)
    assert np.count_nonzero(np.hypot(a, b) != ref[len(special):]) > 0  # the C library's differs


def reference_sumo_gap(shapes, pos, heading, d_front, front, angle, lanes, lane_pos, lat):
    """sumo/world.py sumo_gap as it was (Python loop over LaneShapes.xy), with SUMO's
    front bumper converted to the CoG as sumo_adapter.read_members did."""
    px, py = np.ascontiguousarray(pos[:, 0]), np.ascontiguousarray(pos[:, 1])
    xs, ys, _ = sumo_to_cog_rows(front, angle, d_front)
    gap = np.hypot(xs - px, ys - py)
    fx, fy, _ = (a.tolist() for a in cog_to_sumo_rows(px, py, heading, d_front))
    for j, (lane, lt, lp) in enumerate(zip(lanes, lat.tolist(), lane_pos.tolist())):
        if lane and math.isfinite(lt) and math.isfinite(lp):
            sx, sy = shapes.xy(lane, lp, lt)
            gap[j] = max(gap[j], math.hypot(sx - fx[j], sy - fy[j]))
    return gap


NO_NEIGHBOUR = (np.empty((0, 2)), np.empty(0), np.empty(0), np.empty(0), np.empty(0))


@pytest.mark.jit_off  # also as plain Python (NUMBA_DISABLE_JIT=1)
def test_compiled_member_sense_equals_the_python_sumo_gap_and_projection():
    """sumo/sense.py sense_step: the members' s, d, speed and sumo_gap in one compiled
    call, bit for bit the Python loop over LaneShapes.xy, FastLine.to_frenet and np.hypot it
    replaces (curved and real lanes, members off their lane, out of SUMO, no lane)."""
    import sumolib
    from formation_traci.road.line_pack import FastLine, packed
    from formation_traci.sumo.sense import NeighbourReads, PackedLanes, SumoRows, sense_step
    rng = np.random.default_rng(5)
    line = lines()[2]
    fast = FastLine(float(line.length), packed(line))
    for net_file in (ROOT / "sumo_nets" / "curved3.net.xml", ROOT / "sumo_nets" / "lanedrop.net.xml"):
        net = sumolib.net.readNet(str(net_file), withInternal=True)
        shapes = LaneShapes(net)
        packed_lanes = PackedLanes(shapes)
        all_lanes = [lane for edge in net.getEdges(withInternal=True) for lane in edge.getLanes()]
        for _ in range(300):
            n = int(rng.integers(1, 8))
            pick = [all_lanes[i] for i in rng.integers(0, len(all_lanes), n)]
            lanes = [lane.getID() for lane in pick]
            lane_pos = np.array([rng.uniform(-2.0, lane.getLength() + 2.0) for lane in pick])
            lat = rng.uniform(-2.5, 2.5, n)
            front = np.array([shapes.xy(lid, p, q) for lid, p, q in zip(lanes, lane_pos, lat)])
            front += rng.normal(0.0, rng.choice([1e-9, 0.05, 3.0]), (n, 2))
            angle, heading = rng.uniform(0.0, 360.0, n), rng.uniform(-4.0, 4.0, n)
            d_front = rng.uniform(1.0, 4.0, n)
            pos = front + rng.normal(0.0, 2.0, (n, 2))
            vel = rng.normal(0.0, 20.0, (n, 2))
            if n > 2:  # out of SUMO, no lane, a non-finite lane position
                front[0], angle[0], lanes[0] = np.nan, np.nan, ""
                lanes[1] = ""
                lane_pos[2] = np.nan
            li = packed_lanes.indices(lanes).copy()
            guess = np.where(rng.random(n) < 0.5, np.nan, rng.uniform(0.0, line.length, n))
            s, d, v, gap, n_off, *nb = sense_step(
                fast.G, pos, vel, guess, heading, d_front, SumoRows(front, angle, lane_pos, lat, li),
                packed_lanes.table, packed_lanes.points, 0.1, NeighbourReads(*NO_NEIGHBOUR))
            ref = reference_sumo_gap(shapes, pos, heading, d_front, front, angle, lanes, lane_pos, lat)
            assert np.array_equal(gap, ref, equal_nan=True)
            assert n_off == np.count_nonzero(ref > 0.1) and all(len(a) == 0 for a in nb)
            s_ref, d_ref = fast.to_frenet(pos)
            assert np.array_equal(s, s_ref) and np.array_equal(d, d_ref)
            assert np.array_equal(v, np.hypot(vel[:, 0], vel[:, 1]))
            empty = (np.empty((0, 2)), np.empty(0), np.empty(0), np.empty(0), np.empty(0, dtype=np.int64))
            out = sense_step(fast.G, pos, vel, guess, heading, d_front, SumoRows(*empty),
                             packed_lanes.table, packed_lanes.points, 0.1,
                             NeighbourReads(*NO_NEIGHBOUR))
            assert np.array_equal(out[0], s) and np.isnan(out[3]).all()


@pytest.mark.jit_off  # also as plain Python (NUMBA_DISABLE_JIT=1)
def test_compiled_neighbour_sense_equals_the_numpy_one_whatever_the_guess():
    """sumo/sense.py sense_step's neighbours (SUMO's front bumper converted, projected
    with last step's s as the guess, in the same call as the members) give what
    sumo_to_cog_rows, FastLine.to_frenet without a guess and the numpy arithmetic gave."""
    from formation_traci.road.line_pack import FastLine, packed
    from formation_traci.sumo.sense import NeighbourGuess, NeighbourReads, SumoRows, sense_step
    rng = np.random.default_rng(9)
    no_lane = (np.empty(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    used = 0
    for line in lines():
        fast = FastLine(float(line.length), packed(line))
        guess = NeighbourGuess()
        s_true = rng.uniform(-20.0, line.length + 20.0, 12)
        for step in range(6):
            n = int(rng.integers(1, 12))
            ids = sorted(f"v{i}" for i in rng.choice(12, n, replace=False))
            k = [int(v[1:]) for v in ids]
            s_true[k] += rng.uniform(0.0, 2.0, n)
            fr = np.array([fast.frame(s) for s in s_true[k]])
            off = rng.uniform(-6.0, 6.0, n)
            front = np.column_stack([fr[:, 0] - off * fr[:, 3], fr[:, 1] + off * fr[:, 2]])
            angle = rng.uniform(0.0, 360.0, n)
            length, width = rng.uniform(3.0, 18.0, n), rng.uniform(1.6, 2.6, n)
            members = int(rng.integers(0, 4))
            pos = rng.uniform(0.0, 50.0, (members, 2))
            g = guess(ids)
            s, d, v, gap, n_off, x, y, psi, rear, half_w = sense_step(
                fast.G, pos, np.ones((members, 2)), np.full(members, np.nan), np.zeros(members),
                np.ones(members),
                SumoRows(np.empty((0, 2)), np.empty(0), np.empty(0), np.empty(0), no_lane[0]),
                no_lane[1], no_lane[2], 0.1, NeighbourReads(front, angle, length, width, g))
            guess.keep(ids, s[members:])
            x_ref, y_ref, psi_ref = sumo_to_cog_rows(front, angle, length * 0.5)
            assert np.array_equal(x, x_ref) and np.array_equal(y, y_ref) and np.array_equal(psi, psi_ref)
            s_ref, d_ref = fast.to_frenet(np.column_stack([x_ref, y_ref]))
            assert np.array_equal(s[members:], s_ref) and np.array_equal(d[members:], d_ref)
            assert np.array_equal(rear, s_ref - length / 2) and np.array_equal(half_w, width / 2)
            m_ref = fast.to_frenet(pos)  # the members' projection is not changed by the neighbours'
            assert np.array_equal(s[:members], m_ref[0]) and np.array_equal(d[:members], m_ref[1])
            used += int(np.isfinite(g).sum())
    assert used > 20  # last step's s was the guess of many of them


def _without_shortcut(method):
    """``method`` with the state its shortcut keys on forgotten first: its full loop every step."""
    def full(self, *args):
        self._settled = None
        return method(self, *args)
    return full


def _placement_counting_itself(method):
    """MemberWatch.placement without the count of gaps over the tolerance the compiled sense
    gives: its own comparison every step."""
    def full(self, t, gap_sumo, n_off):
        self._off = True  # the state its shortcut keys on forgotten: the full comparison
        return method(self, t, gap_sumo, int(np.count_nonzero(gap_sumo > PLACEMENT_TOLERANCE)))
    return full


NO_DRAIN = {"traffic.sections.drain_max": 0.0}
"""No drain of the measurement stretch after the formation's last step (sumo/sections.py:
members out, SUMO alone runs on): it records into none of the tables read here."""


def test_member_read_shortcuts_record_what_the_full_loops_record(tmp_path, monkeypatch):
    """Real SUMO: a reshape at a lane drop (members change lanes and reach into the
    neighbour lane) recorded once with the per-step shortcuts of the member read (lane
    tracking, placement and lane-change checks skip a step where nothing changed) and once
    with the full loops they replace: every table is the same, bit for bit, and both the
    shortcut and the full loop were taken."""
    import pyarrow.parquet as pq
    from formation_traci.scenario import load_scenario
    from formation_traci.sumo import adapter as sumo_adapter, events
    from formation_traci.runner import run_scenario
    path = ROOT / "scenarios" / "maneuvers" / "lanedrop_reshape.toml"
    calls = {"full": 0, "reads": 0}
    fast_track = sumo_adapter.SumoAdapter._track_lanes
    overlapped = sumo_adapter.SumoAdapter._overlapped_lane

    def counted_track(self, *a):
        calls["reads"] += 1
        return fast_track(self, *a)

    def counted_overlap(self, lane_id, *a):
        calls["full"] += 1
        return overlapped(self, lane_id, *a)

    def run(name):
        sc = load_scenario(path, **{"run.duration": 60.0}, **NO_DRAIN)
        res = run_scenario(sc, tmp_path / name, scenario_path=path, progress=False, force=True)
        # traffic cuts in at t = 55 s: members' emergency brakes, the run's incidents (issue 32)
        assert res.status == "completed_with_incidents" and not res.incidents["member_collisions"]
        return {p.relative_to(tmp_path / name): pq.read_table(p) for p in (tmp_path / name).rglob("*.parquet")
                if p.is_file()}

    with monkeypatch.context() as m:
        m.setattr(sumo_adapter.SumoAdapter, "_track_lanes", counted_track)
        m.setattr(sumo_adapter.SumoAdapter, "_overlapped_lane", counted_overlap)
        fast = run("fast")
    assert 0 < calls["full"] < calls["reads"] * 3  # 3 members: most reads took the shortcut
    with monkeypatch.context() as m:
        m.setattr(sumo_adapter.SumoAdapter, "_track_lanes", _without_shortcut(fast_track))
        m.setattr(events.MemberWatch, "placement", _placement_counting_itself(events.MemberWatch.placement))
        m.setattr(events.MemberWatch, "lane_changes", _without_shortcut(events.MemberWatch.lane_changes))
        full = run("full")
    assert fast.keys() == full.keys() and len(fast) >= 4
    for name, table in fast.items():  # NaN included, bit for bit
        other = full[name]
        assert table.column_names == other.column_names and table.num_rows == other.num_rows, name
        for a, b in zip(table.columns, other.columns):
            a, b = a.to_numpy(zero_copy_only=False), b.to_numpy(zero_copy_only=False)
            assert (a.tobytes() == b.tobytes()) if a.dtype.kind == "f" else list(a) == list(b), name
    ev = full[Path("events.parquet") if Path("events.parquet") in full else next(
        k for k in full if k.parts[0] == "events.parquet")].to_pandas()
    assert (ev.kind == "lane_change").sum() >= 2  # the full loops had lane changes to report
