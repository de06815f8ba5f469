"""Members' accelerations at the control rate (``comfort.parquet``, 100 Hz by default).

The trajectory table has one row per SUMO step (20 Hz); ISO 2631's weighting needs the
signal at the controller's rate. These wrappers run one outer step as ``n_ctrl`` calls of
the compiled one-period step (the same arithmetic as one ``n_ctrl``-period call, so the
trajectories are bit-identical) and record speed, a_lon and a_lat at the start of periods
1 .. n_ctrl - 1; period 0 is recorded with the step's trajectory row
(:meth:`Recorder.add_comfort_rows` called by the loop).
"""
from __future__ import annotations

import numpy as np


def road_step(ff, rec, state, s_vc: float, v_vc: float,
              a_vc: float, v_cap, a_cap, dt_c: float, n_ctrl: int, t: float, buf: np.ndarray,
              mask=None):
    """``ff.step`` (a fast.FastFleet) over one SUMO step from time ``t`` [s], recording into
    ``rec`` (a recorder.Recorder); returns (FleetState, s_vc, v_vc)."""
    for j in range(n_ctrl):
        if j:
            rec.add_comfort_rows(t + j * dt_c, ff.signals(state, s_vc, v_vc, a_vc, v_cap, a_cap,
                                                          out=buf), mask)
        state, s_vc, v_vc = ff.step(state, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c, 1)
    return state, s_vc, v_vc


def free_step(ff, rec, state, t: float, pose, dt_c: float,
              n_ctrl: int, buf: np.ndarray):
    """``ff.step_free`` over one outer step from time ``t`` [s]; returns (state, pose)."""
    for j in range(n_ctrl):
        tj = t + j * dt_c
        if j:
            rec.add_comfort_rows(tj, ff.signals_free(state, tj, pose, out=buf))
        state, pose = ff.step_free(state, tj, pose, dt_c, 1)
    return state, pose
