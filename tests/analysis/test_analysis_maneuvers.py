"""analysis/metrics/maneuvers.py: maneuver intervals from events and the steady / maneuver split."""
import numpy as np
import pandas as pd
import pytest

from analysis.metrics.maneuvers import in_intervals, maneuver_intervals, phase_metrics


def _events(rows):
    return pd.DataFrame(rows, columns=["t", "kind", "vehicle_id", "other_id", "detail"])


def test_intervals_pair_start_and_end_and_close_an_open_one_at_the_end():
    ev = _events([(1.0, "maneuver_postponed", "vc", "", "lane_change: no room: x"),
                  (2.0, "maneuver_start", "vc", "", "lane_change: T = 4.38 s"),
                  (6.38, "maneuver_end", "vc", "", "lane_change"),
                  (7.0, "collision", "a", "b", "lane x"),
                  (8.0, "maneuver_start", "vc", "", "reshape: T = 13.0 s")])
    iv = maneuver_intervals(ev, t_end=10.0)
    assert iv.to_dict("list") == {"name": ["lane_change", "reshape"], "start_s": [2.0, 8.0],
                                  "end_s": [6.38, 10.0], "completed": [True, False]}
    assert maneuver_intervals(None, 5.0).empty
    assert in_intervals([1.9, 2.0, 4.0, 6.38, 7.0, 9.0], iv).tolist() == [False, True, True, True, False, True]


def test_phase_split_of_error_and_comfort():
    """A member with 1 m/s^2 lateral acceleration and 0.3 m lateral error only during the
    maneuver: the steady phase has neither, the maneuver phase both."""
    dt = 0.05
    t = np.round(np.arange(0.0, 10.0 + dt / 2, dt), 10)
    during = (t >= 4.0) & (t <= 6.0)
    traj = pd.DataFrame({"t": t, "vehicle_id": "m", "e_lon": 0.0, "e_lat": np.where(during, 0.3, 0.0),
                         "a_lat": np.where(during, -1.0, 0.0), "a_lon": 0.2})
    iv = pd.DataFrame({"name": ["reshape"], "start_s": [4.0], "end_s": [6.0], "completed": [True]})
    ph = phase_metrics(traj, ["m"], iv, dt)
    man, steady = ph.loc[("m", "maneuver")], ph.loc[("m", "steady")]
    assert man.duration_s == pytest.approx(41 * dt) and steady.duration_s == pytest.approx((len(t) - 41) * dt)
    assert man.a_lat_peak_mps2 == 1.0 and man.e_rms_m == pytest.approx(0.3) and man.e_lat_rms_m == pytest.approx(0.3)
    assert steady.a_lat_peak_mps2 == 0.0 and steady.e_max_m == 0.0
    assert man.a_lon_peak_mps2 == steady.a_lon_peak_mps2 == pytest.approx(0.2)
