"""analysis/metrics/handover.py: one series across a switch between the formation and SUMO."""
import numpy as np
import pandas as pd
import pytest

from analysis.metrics.handover import handover_track


def _tables(kind, member_first):
    t = np.round(np.arange(0.0, 2.01, 0.5), 10)
    ev = pd.DataFrame([(1.0, kind, "m", "sumo.7" if kind == "join" else "", "x")],
                      columns=["t", "kind", "vehicle_id", "other_id", "detail"])
    mine, theirs = (t >= 1.0, t < 1.0) if not member_first else (t < 1.0, t >= 1.0)
    traj = pd.DataFrame({"t": t[mine], "vehicle_id": "m", "v": 25.0, "d": -3.5, "s": 100 + 25 * t[mine],
                         "ex": 0.3, "ey": 0.4})
    sid = "sumo.7" if kind == "join" else "m"
    bg = pd.DataFrame({"t": t[theirs], "vehicle_id": sid, "v": 24.0, "d": -3.5,
                       "s": 100 + 25 * t[theirs], "lane": "main_0"})
    bg = pd.concat([bg, bg.assign(vehicle_id="other", v=30.0)])
    return ev, traj, bg


@pytest.mark.parametrize("kind,member_first", [("join", False), ("handover", True)])
def test_track_joins_the_member_and_the_sumo_vehicle_in_time_order(kind, member_first):
    ev, traj, bg = _tables(kind, member_first)
    track, t_sw, k = handover_track(ev, traj, bg, "m")
    assert (t_sw, k) == (1.0, kind) and track.t.tolist() == [0.0, 0.5, 1.0, 1.5, 2.0]
    ours = track.driver == "formation"
    assert (track.t[ours] >= 1.0).all() != member_first  # who drives before the switch
    np.testing.assert_allclose(track.e[ours], 0.5)  # |(ex, ey)| while a member
    assert track.e[~ours].isna().all() and (track.v[~ours] == 24.0).all()  # not 'other'
    assert (track.lane[~ours] == "main_0").all() and (track.lane[ours] == "").all()
    with pytest.raises(ValueError, match="no handover or join"):
        handover_track(ev, traj, bg, "nobody")
