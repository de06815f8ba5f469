"""The leader-to-member channel and the predictor (docs/communication.md): pure, no SUMO.

Statistics are checked over long runs against what was asked, within 4 standard errors of
the sample statistic (stated per test)."""
import math

import numpy as np
import pytest

from formation_traci.comm.channel import (LOST, LinkParams, build_channel, gilbert_rates,
                                          link_params)
from formation_traci.comm.predict import predicted_pose
from formation_traci.road.fast_line import frame_at
from formation_traci.road.line_pack import FastLine
from formation_traci.road.geometry import ReferenceLine
from formation_traci.scenario import ScenarioError, load_scenario
from formation_traci.control.virtual_car import along_line_advance as _advance_vc
from formation_traci.road.leader import road_leader_at
from formation_traci.comm.link import channel_instants, views
from formation_traci.comm.predict import predict_planar

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DT = 0.01  # control step [s]
pytestmark = pytest.mark.jit_off  # also run with NUMBA_DISABLE_JIT=1 (README)


def link(**kw) -> LinkParams:
    base = dict(delay_s=0.0, jitter_s=0.0, jitter="exponential", loss="none", loss_p=0.0,
                loss_burst=4.0)
    return LinkParams(**{**base, **kw})


def runs_of(lost: np.ndarray) -> np.ndarray:
    """Lengths of the runs of consecutive losses."""
    x = np.r_[False, lost, False].astype(np.int8)
    d = np.diff(x)
    return np.flatnonzero(d == -1) - np.flatnonzero(d == 1)


@pytest.mark.parametrize("dist, std_factor, kurtosis", [("exponential", 1.0, 9.0),
                                                        ("uniform", 1 / math.sqrt(3), 1.8)])
def test_delay_mean_and_jitter_match_what_was_asked(dist, std_factor, kurtosis):
    """delay = delay_s + jitter: mean delay_s + jitter_s; standard deviation jitter_s
    (exponential) or jitter_s / sqrt(3) (uniform on [0, 2 jitter_s]); the usable arrival is
    the first control instant at or after it."""
    p = link(delay_s=0.1, jitter_s=0.03, jitter=dist)
    ch = build_channel([p], seed=3, duration=20_000.0, control_step=DT, beacon_hz=10.0)
    d = ch.delay_s[0, 1:]  # beacon 0 is the one the formation starts with
    n = d.size
    sigma = 0.03 * std_factor
    assert n == 200_000
    assert abs(d.mean() - 0.13) < 4 * sigma / math.sqrt(n)
    se_std = sigma * math.sqrt((kurtosis - 1) / (4 * n))
    assert abs(d.std() - sigma) < 4 * se_std
    assert d.min() >= 0.1
    lag = (ch.arrival[0, 1:] - ch.send[1:]) * DT
    assert np.all(lag >= d - 1e-12) and np.all(lag < d + DT + 1e-12)


def test_independent_loss_rate_and_isolated_losses():
    p = link(loss="independent", loss_p=0.2)
    ch = build_channel([p], seed=5, duration=20_000.0, control_step=DT, beacon_hz=10.0)
    lost = ch.arrival[0, 1:] == LOST
    n = lost.size
    assert abs(lost.mean() - 0.2) < 4 * math.sqrt(0.2 * 0.8 / n)
    runs = runs_of(lost)
    # Bernoulli: runs are geometric with mean 1 / (1 - p) = 1.25, std sqrt(p) / (1 - p)
    assert abs(runs.mean() - 1.25) < 4 * math.sqrt(0.2) / 0.8 / math.sqrt(runs.size)


@pytest.mark.parametrize("loss_p, burst", [(0.2, 6.0), (0.05, 20.0)])
def test_bursty_loss_rate_and_mean_burst_length(loss_p, burst):
    """Gilbert-Elliott: stationary loss loss_p and bursts of mean loss_burst beacons. The
    standard error of the loss share of a two-state chain is sqrt(p (1 - p) / n) times
    sqrt((1 + lam) / (1 - lam)), lam = 1 - q - r its second eigenvalue; bursts are geometric
    with mean 1 / r and standard deviation sqrt(1 - r) / r."""
    p = link(loss="bursty", loss_p=loss_p, loss_burst=burst)
    ch = build_channel([p], seed=11, duration=100_000.0, control_step=DT, beacon_hz=10.0)
    lost = ch.arrival[0, 1:] == LOST
    n = lost.size
    q, r = gilbert_rates(loss_p, burst)
    lam = 1 - q - r
    se = math.sqrt(loss_p * (1 - loss_p) / n * (1 + lam) / (1 - lam))
    assert abs(lost.mean() - loss_p) < 4 * se
    runs = runs_of(lost)
    assert abs(runs.mean() - burst) < 4 * math.sqrt(1 - r) / r / math.sqrt(runs.size)
    # independent losses at the same rate have far shorter runs
    assert runs.mean() > 2 / (1 - loss_p)


def test_infeasible_burst_is_refused():
    with pytest.raises(ValueError, match="needs loss_burst >= "):
        gilbert_rates(0.8, 2.0)  # needs at least 0.8 / 0.2 = 4 beacons


def test_each_link_has_its_own_seeded_stream():
    """Same seed: the same draws; another link's parameters never change a link's draws; the
    global numpy generator is not touched; another seed: other draws."""
    a = link(delay_s=0.05, jitter_s=0.02, loss="bursty", loss_p=0.2, loss_burst=5.0)
    b = link(loss="independent", loss_p=0.5)
    state = np.random.get_state()[1].copy()
    c1 = build_channel([a, b], seed=1, duration=100.0, control_step=DT, beacon_hz=20.0)
    c2 = build_channel([a, link()], seed=1, duration=100.0, control_step=DT, beacon_hz=20.0)
    c3 = build_channel([a, b], seed=2, duration=100.0, control_step=DT, beacon_hz=20.0)
    assert np.array_equal(np.random.get_state()[1], state)
    assert np.array_equal(c1.arrival[0], c2.arrival[0])
    assert not np.array_equal(c1.arrival[1], c2.arrival[1])
    assert not np.array_equal(c1.arrival[0], c3.arrival[0])


def test_beacon_instants_follow_the_rate():
    ch = build_channel([link()], seed=0, duration=10.0, control_step=DT, beacon_hz=30.0)
    assert len(ch.send) == 301
    t = ch.send * DT
    assert np.all(t >= np.arange(301) / 30.0 - 1e-9) and np.all(t < np.arange(301) / 30.0 + DT)
    perfect = build_channel([link()], seed=0, duration=10.0, control_step=DT, beacon_hz=None)
    assert np.array_equal(perfect.send, np.arange(1001))
    assert np.array_equal(perfect.arrival[0], perfect.send)  # perfect: every instant, at once


def test_newest_beacon_held_and_compiled_lookup_agree_with_the_definition():
    """With jitter, beacons overtake each other: a member holds the largest beacon index among
    those that have arrived (a late older one never replaces it). The compiled per-step lookup
    (comm/link.py) gives the same beacon and its age as the definition."""
    p = link(delay_s=0.02, jitter_s=0.08, loss="independent", loss_p=0.3)
    ch = build_channel([p, link(delay_s=0.3)], seed=4, duration=6.0, control_step=DT, beacon_hz=50.0)
    assert np.any(np.diff(ch.arrival[0][ch.arrival[0] != LOST]) < 0)  # reordering happens
    n_ctrl, n = 5, 2
    B = len(ch.send)
    beacons, truth = np.zeros((B, 8)), np.zeros((n_ctrl, 8))
    nxt, ptr = np.zeros(1, np.int64), np.zeros(n, np.int64)
    NB, AGE = np.zeros((n_ctrl, n), np.int64), np.zeros((n_ctrl, n))
    for k in range(60):
        channel_instants(truth, DT, k * n_ctrl, ch.send, beacons, nxt, ch.arrival_sorted,
                         ch.newest_sorted, ptr, NB, AGE)
        for j in range(n_ctrl):
            c = k * n_ctrl + j
            want = [max(b for b in range(B) if ch.arrival[i, b] <= c) for i in range(n)]
            assert list(NB[j]) == want == list(ch.newest(c))
            assert np.allclose(AGE[j], (c - ch.send[want]) * DT, atol=1e-12)
            assert np.allclose(ch.age(c), AGE[j], atol=1e-12)


def _circle_line(radius=400.0):
    phi = np.linspace(0.0, 1.5 * np.pi, 600)
    pts = np.c_[radius * np.sin(phi), radius * (1 - np.cos(phi))]
    return FastLine.from_reference_line(ReferenceLine.from_points(pts))


@pytest.mark.parametrize("a", [0.0, -1.2])
def test_prediction_of_a_constant_turn_leader_on_a_road_is_exact(a):
    """The virtual car on an arc of constant curvature at constant speed (a = 0: constant
    turn rate) or constant acceleration: every member's view, 0.37 s old and predicted to the
    present, equals the true state (arc length, pose, speed, yaw rate) to rounding."""
    line = _circle_line()
    ch = build_channel([link(delay_s=0.37), link(delay_s=0.05, jitter_s=0.1)], seed=2,
                       duration=4.0, control_step=DT, beacon_hz=10.0)
    n_ctrl, n = 5, 2
    B = len(ch.send)
    beacons, truth = np.zeros((B, 8)), np.zeros((n_ctrl, 8))
    nxt, ptr = np.zeros(1, np.int64), np.zeros(n, np.int64)
    NB, AGE = np.zeros((n_ctrl, n), np.int64), np.zeros((n_ctrl, n))
    vc = np.zeros((n_ctrl, n, 8))
    fb = np.zeros(n, np.bool_)
    s, v = 50.0, 25.0
    worst, oldest = 0.0, 0.0
    for k in range(40):
        s0, v0 = s, v
        for j in range(n_ctrl):  # the generator's rows (control/reference_road.py road_vc_rows)
            truth[j] = [*road_leader_at(line.G, s, v, a), s]
            s, v = _advance_vc(s, v, a, DT)
        channel_instants(truth, DT, k * n_ctrl, ch.send, beacons, nxt, ch.arrival_sorted,
                         ch.newest_sorted, ptr, NB, AGE)
        views(line.G, True, NB, AGE, beacons, fb, np.zeros((n, 8)), DT, vc)
        for j in range(n_ctrl):
            for i in range(n):
                assert vc[j, i, 7] == pytest.approx(truth[j, 7], abs=1e-9)
                assert vc[j, i, 3] == pytest.approx(truth[j, 3], abs=1e-10)
                worst = max(worst, math.hypot(vc[j, i, 0] - truth[j, 0], vc[j, i, 1] - truth[j, 1]))
                assert vc[j, i, 2] == pytest.approx(truth[j, 2], abs=1e-12)
                assert vc[j, i, 4] == pytest.approx(truth[j, 4], abs=1e-12)
                bs, bv, ba = beacons[NB[j, i]][[7, 3, 5]]
                x, y, hd, vp, r = predicted_pose(line.G, bs, bv, ba, AGE[j, i])
                assert math.hypot(x - vc[j, i, 0], y - vc[j, i, 1]) < 1e-12
                oldest = max(oldest, AGE[j, i])
    assert worst < 1e-9
    assert oldest >= 0.37  # the prediction did span the delay


def test_prediction_is_not_exact_when_the_acceleration_changes():
    """The predictor holds the acceleration of the beacon: a change of acceleration after it
    shows as an error of a tau^2 / 2."""
    s_b, v_b, a_b, tau = 0.0, 20.0, 0.0, 0.4
    s_true, v_true = _advance_vc(s_b, v_b, -2.0, tau)
    s_pred, _ = _advance_vc(s_b, v_b, a_b, tau)
    assert s_pred - s_true == pytest.approx(0.5 * 2.0 * tau ** 2, rel=1e-12)


def _write(tmp_path, text):
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


ROAD = (ROOT / "scenarios" / "highway" / "straight_3lane_light.toml").read_text()


@pytest.mark.parametrize("extra, field, expect", [
    ("[comm]\nbeacon_hz = 150.0\n", "(document)", "must not exceed the control rate"),
    ("[comm]\nloss = \"bursty\"\nloss_p = 0.8\nloss_burst = 2.0\n", "comm", "needs loss_burst >="),
    ("[comm.links.nobody]\ndelay_s = 0.1\n", "(document)", "do not exist: ['nobody']"),
    ("[comm]\nloss_p = 1.0\n", "comm.loss_p", "less than 1"),
    ("[comm]\njitter = \"pareto\"\n", "comm.jitter", "'exponential' or 'uniform'"),
    ("[comm]\ndelay = 0.1\n", "comm.delay", "unknown field"),
])
def test_bad_comm_tables_are_refused_with_the_field(tmp_path, extra, field, expect):
    p = _write(tmp_path, ROAD + "\n" + extra)
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    assert any(f == field and expect in m for f, m in ei.value.problems), ei.value.problems


def test_link_overrides_take_the_comm_values_for_what_they_leave_out(tmp_path):
    p = _write(tmp_path, ROAD + '\n[comm]\ndelay_s = 0.2\nloss = "independent"\nloss_p = 0.1\n'
               '[comm.links.left]\ndelay_s = 0.5\n')
    sc = load_scenario(p)
    assert link_params(sc.comm, "left") == LinkParams(0.5, 0.0, "exponential", "independent", 0.1, 4.0)
    assert link_params(sc.comm, "right").delay_s == 0.2


@pytest.mark.parametrize("w", [0.25, -0.05, 1e-9, 0.0])
def test_planar_prediction_of_a_constant_turn_leader_is_exact(w):
    """Free space: a leader at constant speed 20 m/s and turn rate w [rad/s] is on a circle of
    radius 20 / w: the prediction over 0.8 s lands on it (and on the straight line for w = 0)."""
    x0, y0, th0, v, tau = 3.0, -2.0, 0.4, 20.0, 0.8
    x, y, th, v1 = predict_planar(x0, y0, th0, v, w, 0.0, tau)
    if w == 0.0:
        ex, ey = x0 + v * tau * math.cos(th0), y0 + v * tau * math.sin(th0)
    else:
        # on the circle of radius v / w: ahead r sin(w tau), to the left r (1 - cos(w tau)),
        # written without cancellation for small w
        ahead = v * math.sin(w * tau) / w
        left = v * 2 * math.sin(w * tau / 2) ** 2 / w
        ex = x0 + ahead * math.cos(th0) - left * math.sin(th0)
        ey = y0 + ahead * math.sin(th0) + left * math.cos(th0)
    assert math.hypot(x - ex, y - ey) < 1e-9
    assert th == pytest.approx(th0 + w * tau, abs=1e-15) and v1 == v


def test_planar_prediction_with_acceleration_matches_the_integrated_spiral():
    """Constant turn rate and acceleration: the closed form against a fine RK4 of eq 2.3; the
    speed stops at 0 and the position with it."""
    x0, y0, th0, v, w, a, tau = 0.0, 0.0, 0.0, 15.0, 0.3, -2.0, 1.5

    def f(t, q):
        vt = v + a * t
        return np.array([vt * math.cos(q[2]), vt * math.sin(q[2]), w])

    q, h = np.array([x0, y0, th0]), tau / 3000
    for k in range(3000):
        t = k * h
        k1 = f(t, q)
        k2 = f(t + h / 2, q + h / 2 * k1)
        k3 = f(t + h / 2, q + h / 2 * k2)
        k4 = f(t + h, q + h * k3)
        q = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    x, y, th, v1 = predict_planar(x0, y0, th0, v, w, a, tau)
    assert math.hypot(x - q[0], y - q[1]) < 1e-9 and v1 == pytest.approx(12.0)
    xs, ys, _, vs = predict_planar(x0, y0, th0, 3.0, w, a, 4.0)  # stops after 1.5 s
    xm, ym, _, _ = predict_planar(x0, y0, th0, 3.0, w, a, 1.5)
    assert vs == 0.0 and math.hypot(xs - xm, ys - ym) < 1e-12


@pytest.mark.jit_off
def test_planar_prediction_of_a_car_that_stops_stops_turning_too():
    """A braking, turning leader that comes to rest within the prediction horizon stands still
    from then on: its heading stops at theta + w v/|a| (the heading kept turning over the whole
    horizon while the position had stopped)."""
    v, w, a, tau = 10.0, 0.1, -5.0, 5.0  # stops after 2 s
    x, y, th, v1 = predict_planar(0.0, 0.0, 0.3, v, w, a, tau)
    xs, ys, ths, _ = predict_planar(0.0, 0.0, 0.3, v, w, a, 2.0)
    assert v1 == 0.0
    assert (x, y) == pytest.approx((xs, ys), abs=1e-12)
    assert th == pytest.approx(0.3 + w * 2.0, abs=1e-12) and th == pytest.approx(ths, abs=1e-12)
