"""When a scheduled maneuver becomes due: by time, by the virtual car's position along the
route, or by the queue of vehicles behind the formation."""
from __future__ import annotations

import numpy as np

from ...road.lanes import LaneCentres
from .gap import Others


def queue_behind(m_s, m_d, m_length, lanes: LaneCentres, others: Others, reach: float) -> int:
    """Vehicles queued behind the formation [-].

    A vehicle counts when its front bumper is behind the rearmost member's rear bumper by at
    most ``reach`` [m] and it drives in a lane the formation occupies: its centre is nearest to
    the centre of some member's lane (SUMO's lane centres ``lanes`` at the formation's rear).

    Parameters
    ----------
    m_s, m_d, m_length : ndarray, shape (n,)
        Active members' centre arc length [m], lateral offset [m], body length [m].
    """
    if len(others.ids) == 0 or len(m_s) == 0:
        return 0
    rear = float(np.min(np.asarray(m_s) - np.asarray(m_length) / 2))
    front = others.s + others.length / 2
    behind = (front <= rear) & (front >= rear - reach)
    in_lane = np.any(lanes.same_lane(rear, others.d[:, None], np.asarray(m_d)[None, :]), axis=1)
    return int(np.count_nonzero(behind & in_lane))


def is_due(trigger, t: float, s_route: float, queue: int) -> bool:
    """Has ``trigger`` (scenario.maneuvers.TriggerSpec) fired at formation time t [s], with
    the virtual car at route arc length s_route [m] and ``queue`` vehicles queued behind?"""
    if trigger.time is not None:
        return t >= trigger.time - 1e-9
    if trigger.s is not None:
        return s_route >= trigger.s
    return queue > trigger.queue_behind
