"""The members' rows of the trajectory and comfort tables written by the compiled step
(sim/fleet.py member_signals, step_members; sumo/fused_step.py): the rows sim/recorder.py's
add_signal_rows, add_comfort_rows and add_comfort_periods write, in their layout (one buffer row
per column, a table row per member in the run), from inside the compiled call."""
from __future__ import annotations

from ..core.kernels import kernel


@kernel
def signal_table_rows(out, t, traj, traj_ids, at, comfort, comfort_ids, c_at, comfort_cols,
                      active):
    """The members' rows of a recorded step at t [s] (sim/fleet.py member_signals' table rows):
    member i's signals ``out[i]`` into a column of ``traj`` (t, then out's columns) and of
    ``traj_ids`` (its code, i) from column ``at``, and into ``comfort`` (t, then out's columns
    ``comfort_cols``) and ``comfort_ids`` from ``c_at``; the members with ``active`` only, in
    order (sim/recorder.py add_signal_rows' and add_comfort_rows' rows); returns how many."""
    r = 0
    for i in range(out.shape[0]):
        if not active[i]:
            continue
        traj[0, at + r] = t
        for q in range(out.shape[1]):
            traj[1 + q, at + r] = out[i, q]
        traj_ids[at + r] = i
        comfort[0, c_at + r] = t
        for q in range(comfort_cols.shape[0]):
            comfort[1 + q, c_at + r] = out[i, comfort_cols[q]]
        comfort_ids[c_at + r] = i
        r += 1
    return r


@kernel
def period_table_rows(comfort, t0, dt_c, table, table_ids, at, active):
    """Control periods 1 .. n_ctrl - 1 of ``comfort`` (n_ctrl, n, 3) as comfort table rows from
    row ``at`` of ``table`` (t = t0 + j dt_c [s], speed, a_lon, a_lat) and ``table_ids`` (code
    i), period by period, the members with ``active`` only (sim/recorder.py
    add_comfort_periods' rows)."""
    n = comfort.shape[1]
    n_act = 0
    for i in range(n):
        if active[i]:
            n_act += 1
    for j in range(1, comfort.shape[0]):
        tj = t0 + j * dt_c
        r = at + (j - 1) * n_act
        for i in range(n):
            if not active[i]:
                continue
            table[0, r] = tj
            table[1, r] = comfort[j, i, 0]
            table[2, r] = comfort[j, i, 1]
            table[3, r] = comfort[j, i, 2]
            table_ids[r] = i
            r += 1
