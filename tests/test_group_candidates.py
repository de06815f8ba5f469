"""Each formation of a group reads only the rows of the joined neighbour table that can lead
its members or slots (control/reference_group.py _candidates): for random tables with ties,
NaN rows, rows far ahead, released members inside the formation and the formation's own
members among the rows, the leaders, gaps and leader indices are those of control/governor.py
_vehicles_ahead over every row the formation sees (_seen_by), exactly."""
import numpy as np
import pytest

from formation_traci.control.governor import _vehicles_ahead
from formation_traci.control.reference_group import _candidates, _row_of, _seen_by, _seen_index
from formation_traci.control.reference_records import NeighbourRows


def _table(rng, m_sumo, n, a, b):
    """SUMO's rows then every member's (owner), as sumo/peers.py peer_table joins them."""
    lanes = np.array([-5.25, -1.75, 1.75, 5.25])
    m = m_sumo + n
    rear = np.round(rng.uniform(0.0, 3000.0, m), 1)  # rounded: ties in rear
    rear[rng.random(m) < 0.03] = np.nan
    d = lanes[rng.integers(0, 4, m)] + rng.normal(0.0, 0.3, m)
    half = rng.uniform(0.8, 1.3, m)
    v = rng.uniform(20.0, 35.0, m)
    flags = np.zeros(m, dtype=bool)
    flags[rng.random(m) < 0.05] = True  # released members inside a formation
    owner = np.full(m, -1, dtype=np.int64)
    owner[m_sumo:] = np.arange(n)
    rear[m_sumo + a:m_sumo + b] = 1500.0 + 12.0 * np.arange(b - a)  # the formation's own members
    return NeighbourRows(rear, d, half, v, flags, np.empty(0)), owner


def _probes(rng, k):
    """k members then their k slots: front bumper [m], offset [m], half width [m], slot flag."""
    p = np.empty((2 * k, 4))
    p[:, 0] = 1500.0 + 12.0 * (np.arange(2 * k) % k) + rng.normal(0.0, 2.0, 2 * k)
    p[:, 1] = np.array([-5.25, -1.75, 1.75, 5.25])[rng.integers(0, 4, 2 * k)]
    p[:, 2] = 0.9
    p[:k, 3], p[k:, 3] = 0.0, 1.0
    p[rng.random(2 * k) < 0.1, 0] = np.nan  # a member not sensed
    return p


@pytest.mark.parametrize("seed", range(40))
def test_candidates_give_the_leaders_of_every_row_seen(seed):
    rng = np.random.default_rng(seed)
    m_sumo, n, a, b = int(rng.integers(0, 600)), 12, 4, 8
    nbs, owner = _table(rng, m_sumo, n, a, b)
    if seed % 4 == 0:
        nbs.rear[:m_sumo] = 1520.0  # every SUMO row at one rear: all tie
    if seed % 4 == 1:
        nbs.in_formation[:m_sumo] = rng.random(m_sumo) < 0.6  # many rows that lead no slot
    probes = _probes(rng, b - a)
    k = b - a
    order = np.argsort(nbs.rear, kind="mergesort")
    row_of = _row_of(owner, n)
    seen = _seen_by(nbs, owner, a, b, nbs.rear.shape[0])
    cand, keep = _candidates(nbs, order, nbs.rear[order], row_of[a:b], probes)
    assert len(keep) <= len(seen.rear)
    for part, probe in (("members", probes[:k]), ("slots", probes[k:])):
        rear_all = seen.rear.copy()
        rear_c = cand.rear.copy()
        if part == "slots":  # governor_step: a released member does not lead a slot
            rear_all[seen.in_formation] = np.inf
            rear_c[cand.in_formation] = np.inf
        gap, v_lead, idx = _vehicles_ahead(probe[:, 0], probe[:, 1], probe[:, 2], rear_all, seen.d,
                                           seen.half_w, seen.v)
        gap_c, v_c, idx_c = _vehicles_ahead(probe[:, 0], probe[:, 1], probe[:, 2], rear_c, cand.d,
                                            cand.half_w, cand.v)
        _seen_index(idx_c, keep, row_of[a:b])
        assert np.array_equal(gap, gap_c) and np.array_equal(v_lead, v_c, equal_nan=True), part
        assert np.array_equal(idx, idx_c), part
        assert (idx >= 0).any() or seed % 4 == 0 or m_sumo < 50  # the cases have leaders
