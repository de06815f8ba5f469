"""Generic statistics: closed-form values."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.metrics.signals import (contiguous_segments, count_episodes, peak_abs, percentile_abs,
                                      rms, time_where, trapezoid_integral)


def test_rms_of_sinusoid_over_whole_periods():
    t = np.arange(0.0, 10.0, 0.001)  # 10 periods of 1 Hz
    assert rms(3.0 * np.sin(2 * np.pi * t)) == pytest.approx(3.0 / np.sqrt(2), rel=1e-9)


def test_statistics_ignore_non_finite_samples():
    x = np.array([3.0, np.nan, -4.0, np.inf])
    assert rms(x) == pytest.approx(np.sqrt(12.5))
    assert peak_abs(x) == 4.0
    assert np.isnan(rms([np.nan, np.nan]))
    assert np.isnan(peak_abs(np.array([])))


def test_percentile_of_uniform_magnitudes():
    x = -np.linspace(0.0, 1.0, 10001)  # |x| uniform on [0, 1]
    assert percentile_abs(x, 95.0) == pytest.approx(0.95, abs=1e-9)
    with pytest.raises(ValueError, match="q must be"):
        percentile_abs(x, 120.0)


def test_axis_argument_reduces_the_time_axis():
    x = np.stack([np.ones(5), 2 * np.ones(5)], axis=1)  # time on axis 0
    np.testing.assert_allclose(rms(x, axis=0), [1.0, 2.0])
    np.testing.assert_allclose(trapezoid_integral(x, 0.5, axis=0), [2.0, 4.0])


def test_trapezoid_is_exact_for_a_line():
    t = np.arange(0.0, 2.0 + 1e-12, 0.1)
    assert trapezoid_integral(3.0 * t, 0.1) == pytest.approx(6.0, rel=1e-12)


@pytest.mark.parametrize("mask, n", [
    ([False, False], 0),
    ([True, True, True], 1),
    ([True, False, True], 2),
    ([False, True, True, False, True, False, False, True], 3),
])
def test_count_episodes(mask, n):
    assert count_episodes(mask) == n


def test_count_episodes_and_time_where_along_rows():
    m = np.array([[1, 0, 1, 1], [0, 0, 0, 1]], dtype=bool)
    np.testing.assert_array_equal(count_episodes(m), [2, 1])
    np.testing.assert_allclose(time_where(m, 0.1), [0.3, 0.1])


def test_contiguous_segments_split_at_gaps():
    t = np.array([0.0, 0.1, 0.2, 0.5, 0.6, 1.0])
    segs = contiguous_segments(t, 0.1)
    assert [(s.start, s.stop) for s in segs] == [(0, 3), (3, 5), (5, 6)]
    with pytest.raises(ValueError, match="dt"):
        contiguous_segments(t, 0.0)
