"""ISO 2631-1 Wd weighting against the standard's Table 3 and Annex A."""
from __future__ import annotations

import math

import numpy as np
import pytest

from analysis.metrics import iso2631 as iso

# Table 3 of ISO 2631-1:1997, Wk (x 1000), 0.5 ... 80 Hz
WK_TABLE_HZ = np.array([0.5, 0.63, 0.8, 1, 1.25, 1.6, 2, 2.5, 3.15, 4, 5, 6.3, 8, 10, 12.5, 16,
                        20, 25, 31.5, 40, 50, 63, 80])
WK_TABLE = np.array([418, 459, 477, 482, 484, 494, 531, 631, 804, 967, 1039, 1054, 1036, 988,
                     902, 768, 636, 513, 405, 314, 246, 186, 132]) / 1000


def annex_a_wd(f):
    """Wd of Annex A written out independently: |Hh Hl Ht| at s = j 2 pi f."""
    s = 2j * np.pi * np.asarray(f, float)
    w1, w2, w3, w4, q4 = 2 * np.pi * 0.4, 2 * np.pi * 100, 2 * np.pi * 2, 2 * np.pi * 2, 0.63
    hh = 1 / (1 + math.sqrt(2) * w1 / s + (w1 / s) ** 2)
    hl = 1 / (1 + math.sqrt(2) * s / w2 + (s / w2) ** 2)
    ht = (1 + s / w3) / (1 + s / (q4 * w4) + (s / w4) ** 2)
    return np.abs(hh * hl * ht)


def test_analog_wd_matches_table_3_within_1_percent():
    ok = iso.WD_TABLE_HZ != 10.0
    ratio = np.abs(iso.analog_response(iso.WD_TABLE_HZ)) / iso.WD_TABLE
    np.testing.assert_allclose(ratio[ok], 1.0, atol=0.01)
    # the key points named in the brief
    for f, w in ((1, 1.011), (2, 0.890), (4, 0.512), (8, 0.253)):
        assert abs(iso.analog_response(f)[0]) == pytest.approx(w, rel=0.005)


def test_printed_10hz_value_is_the_known_outlier():
    # Table 3 prints 0.212; Annex A's own formula gives 0.2017 (5 % lower)
    assert annex_a_wd(10.0) == pytest.approx(0.2017, abs=5e-4)
    assert abs(iso.analog_response(10.0)[0]) == pytest.approx(annex_a_wd(10.0), rel=1e-9)


def test_analog_wd_equals_independent_annex_a_transcription():
    f = np.geomspace(0.05, 500, 200)
    np.testing.assert_allclose(np.abs(iso.analog_response(f)), annex_a_wd(f), rtol=1e-9)


def test_upward_step_section_reproduces_wk_table():
    ratio = np.abs(iso.analog_response(WK_TABLE_HZ, iso.WK)) / WK_TABLE
    np.testing.assert_allclose(ratio, 1.0, atol=0.01)


def test_digital_wd_at_1khz_matches_table_up_to_80hz():
    m = (iso.WD_TABLE_HZ <= 80) & (iso.WD_TABLE_HZ != 10.0)
    ratio = np.abs(iso.digital_response(iso.WD_TABLE_HZ[m], 1000.0)) / iso.WD_TABLE[m]
    np.testing.assert_allclose(ratio, 1.0, atol=iso.WD_TOLERANCE)


def test_digital_wd_within_tolerance_inside_the_valid_band_only():
    fs = 100.0
    fv = iso.valid_upper_frequency(fs)
    assert 11.0 < fv < 13.0  # about fs / 8.2
    f = np.geomspace(0.5, fv, 300)
    ratio = np.abs(iso.digital_response(f, fs)) / np.abs(iso.analog_response(f))
    assert np.all(np.abs(ratio - 1) <= iso.WD_TOLERANCE)
    beyond = np.abs(iso.digital_response([1.5 * fv], fs)) / np.abs(iso.analog_response(1.5 * fv))
    assert abs(beyond[0] - 1) > iso.WD_TOLERANCE


@pytest.mark.parametrize("f", [1.0, 2.0, 4.0])
def test_weighted_rms_of_sinusoid_at_100hz(f):
    t = np.arange(0.0, 60.0, 0.01)
    r = iso.weighted_rms(2.0 * np.sin(2 * np.pi * f * t), 0.01)
    expected = 2.0 / np.sqrt(2) * iso.WD_TABLE[list(iso.WD_TABLE_HZ).index(f)]
    assert r.value == pytest.approx(expected, rel=0.02)
    assert not r.full_band and "partial band" in r.reason
    assert r.band_hz[1] == pytest.approx(iso.valid_upper_frequency(100.0))


def test_full_band_at_high_sample_rate():
    dt = 1 / 1000
    t = np.arange(0.0, 12.0, dt)
    r = iso.weighted_rms(np.sin(2 * np.pi * 1.0 * t), dt)
    assert r.full_band and r.reason is None and r.band_hz == (0.5, 80.0)
    assert r.value == pytest.approx(1.011 / np.sqrt(2), rel=0.02)
    assert iso.min_sample_rate(80.0) == pytest.approx(823, rel=0.01)


def test_low_sample_rate_reports_nan_with_reason():
    t = np.arange(0.0, 60.0, 0.05)  # 20 Hz
    r = iso.weighted_rms(np.sin(t), 0.05)
    assert np.isnan(r.value) and "sample rate 20 Hz" in r.reason and "66 Hz" in r.reason


def test_short_or_non_finite_records_report_nan_with_reason():
    assert "shorter than" in iso.weighted_rms(np.ones(500), 0.01).reason
    x = np.sin(np.arange(0.0, 20.0, 0.01))
    x[100] = np.nan
    r = iso.weighted_rms(x, 0.01)
    assert np.isnan(r.value) and "non-finite" in r.reason


def test_constant_acceleration_has_no_weighted_content():
    r = iso.weighted_rms(np.full(3000, 2.5), 0.01)  # steady cornering: DC is not vibration
    assert r.value < 1e-9


def test_rows_are_weighted_independently_and_total_value():
    t = np.arange(0.0, 30.0, 0.01)
    x = np.sin(2 * np.pi * t)
    r = iso.weighted_rms(np.vstack([x, 3 * x]), 0.01)
    assert r.value[1] == pytest.approx(3 * r.value[0], rel=1e-9)
    assert iso.weighted_rms(x, 0.01).value == pytest.approx(r.value[0], rel=1e-12)
    assert iso.vibration_total_value(3.0, 4.0) == pytest.approx(5.0)
