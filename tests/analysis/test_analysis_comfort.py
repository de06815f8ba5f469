"""Comfort metrics on signals with closed-form answers."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.metrics import comfort
from analysis.metrics.signals import peak_abs, percentile_abs, rms

DT = 0.01


def sinusoid(A=0.5, f=0.5, t_end=20.0):
    """Lateral position y = -A sin(w t): a = A w^2 sin(w t), jerk = A w^3 cos(w t)."""
    w = 2 * np.pi * f
    t = np.arange(0.0, t_end, DT)
    return t, w, A * w**2 * np.sin(w * t)


def test_acceleration_peak_rms_p95_of_sinusoid():
    _, w, a = sinusoid()
    amp = 0.5 * w**2
    assert peak_abs(a) == pytest.approx(amp, rel=1e-3)
    assert rms(a) == pytest.approx(amp / np.sqrt(2), rel=1e-3)
    # |sin| of a uniform phase: P(|sin| <= x) = (2/pi) asin(x)
    assert percentile_abs(a, 95.0) == pytest.approx(amp * np.sin(0.95 * np.pi / 2), rel=2e-3)


def test_jerk_of_sinusoid_matches_A_w3():
    _, w, a = sinusoid()
    j = comfort.jerk(a, DT)
    amp = 0.5 * w**3
    half = comfort.savgol_window_samples(comfort.JERK_WINDOW_S, DT, comfort.JERK_POLYORDER) // 2
    # interior: within 0.5 %; the whole record (edge windows use a polynomial fit): 3 %
    assert peak_abs(j[half:-half]) == pytest.approx(amp, rel=5e-3)
    assert peak_abs(j) == pytest.approx(amp, rel=3e-2)
    assert rms(j) == pytest.approx(amp / np.sqrt(2), rel=1e-2)
    # and in phase: jerk = A w^3 cos(w t)
    t = np.arange(a.size) * DT
    np.testing.assert_allclose(j[half:-half], (amp * np.cos(w * t))[half:-half], atol=5e-3 * amp)


def test_polyorder_3_keeps_1hz_jerk_where_polyorder_2_loses_it():
    _, w, a = sinusoid(f=1.0)
    amp = 0.5 * w**3
    sl = slice(50, -50)
    assert rms(comfort.jerk(a, DT, polyorder=3)[sl]) / (amp / np.sqrt(2)) > 0.98
    assert rms(comfort.jerk(a, DT, polyorder=2)[sl]) / (amp / np.sqrt(2)) < 0.80


def test_jerk_rejects_a_signal_shorter_than_the_window():
    with pytest.raises(ValueError, match="shorter than"):
        comfort.jerk(np.zeros(20), DT)


@pytest.mark.parametrize("window_s, dt, order, n", [
    (0.5, 0.01, 3, 51), (0.5, 0.1, 3, 7), (0.5, 0.25, 3, 5), (0.5, 0.25, 2, 5), (0.2, 0.01, 2, 21),
])
def test_window_samples_span_the_window(window_s, dt, order, n):
    assert comfort.savgol_window_samples(window_s, dt, order) == n


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_band_times_of_a_ramp(sign):
    k = 0.5  # m/s^3: |a| goes 0 -> 7 m/s^2 in 14 s
    t = np.arange(0.0, 14.0, DT)
    times = comfort.band_times(sign * k * t, DT)
    expected = [1.8 / k, (3.6 - 1.8) / k, (5.0 - 3.6) / k, (7.0 - 5.0) / k]
    np.testing.assert_allclose(times, expected, atol=1.01 * DT)
    assert times.sum() == pytest.approx(t.size * DT)


def test_band_times_along_rows_and_constants_cite_the_seed():
    a = np.array([[0.0, 2.0, 4.0, 6.0], [1.0, 1.0, 1.0, 1.0]])
    np.testing.assert_allclose(comfort.band_times(a, 0.5), [[0.5, 0.5, 0.5, 0.5], [2, 0, 0, 0]])
    assert comfort.LAT_BAND_EDGES[1:4] == (1.8, 3.6, 5.0)
    assert comfort.LON_ACC_COMFORT == 2.0


def test_jerk_1s_peak_metric_is_the_ramp_rate_and_leaves_out_emergencies(tmp_path):
    """``jerk_lon_1s_peak_mps3`` (issue 19): member a ramps its acceleration at 1.5 m/s^3 for
    2 s, so every 1-s window inside the ramp averages exactly 1.5; member b steps by 6 m/s^2 in
    0.5 s (12 m/s^3, a 1-s mean of 6) inside a recorded emergency brake, which is left out (and
    counts again when the events are not recorded)."""
    import analysis_synth as S
    from analysis.load.run_data import load_run
    from analysis.runs.summary import DEFAULT_SETTINGS, compute_run

    def a_lon(mid, t):
        if mid == "a":
            return 1.5 * np.clip(t - 2.0, 0.0, 2.0)
        return -12.0 * np.clip(t - 10.0, 0.0, 0.5)

    offsets = {"a": (0.0, 0.0), "b": (-10.0, 0.0)}
    peaks = {}
    for events in (True, False):
        run = S.make_run(tmp_path / f"run{events}", dt=0.05, t_end=20.0, offsets=offsets,
                         columns={"a_lon": a_lon}, n_parts=1)
        if events:
            S.write_traffic(run, events_df=S.events([(9.8, "emergency_brake", "b", "", ""),
                                                     (11.0, "emergency_end", "b", "", "")]))
        m = compute_run(load_run(run), DEFAULT_SETTINGS).members
        peaks[events] = m["jerk_lon_1s_peak_mps3"]
    assert peaks[True]["a"] == pytest.approx(1.5, abs=1e-9)
    assert peaks[True]["b"] < 1e-9  # only the step, inside the emergency (+3 s to settle)
    assert peaks[False]["b"] == pytest.approx(6.0, abs=1e-9)
