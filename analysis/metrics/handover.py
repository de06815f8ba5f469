"""Hand-overs between the formation and SUMO in a recorded run (docs/maneuvers.md): a member
leaving (``handover`` event: our controller -> SUMO's driver) or a vehicle joining (``join``
event: SUMO's driver -> our controller), and the figure that shows one across the switch.

The vehicle is a member (trajectories.parquet, recorded under the member's id) on one side
of the switch and an ordinary SUMO vehicle (background.parquet, under SUMO's id) on the
other. :func:`handover_track` joins the two into one time series
(analysis/figures/handover_figures.py draws it).
"""
from __future__ import annotations

import numpy as np
import pandas as pd
__all__ = ["HANDOVER_KINDS", "handover_track"]

HANDOVER_KINDS = ("handover", "join")
"""Event kinds of a switch between our controller and SUMO's driver."""
def handover_track(events: pd.DataFrame, traj: pd.DataFrame, background: pd.DataFrame,
                   member: str) -> tuple[pd.DataFrame, float, str]:
    """The vehicle of ``member``'s hand-over as one series.

    Parameters
    ----------
    events : DataFrame
        events.parquet of the run (t, kind, vehicle_id, other_id).
    traj : DataFrame
        trajectories.parquet (the member's rows: t, v, d, s, ex, ey).
    background : DataFrame
        background.parquet (the SUMO vehicle's rows: t, v, d, s, lane).
    member : str
        The member that left (``handover``) or joined (``join``).

    Returns
    -------
    (DataFrame, float, str)
        Rows t [s], v [m/s], d [m], s [m], lane (SUMO's lane id, "" while a member),
        e [m] (formation error, NaN while SUMO drives), driver ("formation" or "sumo");
        the time of the switch [s]; the event kind (``handover`` or ``join``).
    """
    ev = events[events["kind"].isin(HANDOVER_KINDS) & (events["vehicle_id"] == member)]
    if ev.empty:
        raise ValueError(f"no handover or join event of {member!r}")
    t_switch, kind = float(ev["t"].iloc[0]), str(ev["kind"].iloc[0])
    sumo_id = str(ev["other_id"].iloc[0]) or member
    ours = traj[traj["vehicle_id"] == member]
    theirs = background[background["vehicle_id"] == sumo_id]
    a = pd.DataFrame({"t": ours["t"], "v": ours["v"], "d": ours["d"], "s": ours["s"], "lane": "",
                      "e": np.hypot(ours["ex"], ours["ey"]), "driver": "formation"})
    b = pd.DataFrame({"t": theirs["t"], "v": theirs["v"], "d": theirs["d"], "s": theirs["s"],
                      "lane": theirs["lane"].astype(str), "e": np.nan, "driver": "sumo"})
    track = pd.concat([a, b], ignore_index=True).sort_values("t", kind="stable")
    return track.reset_index(drop=True), t_switch, kind
