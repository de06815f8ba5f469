"""Communication between the virtual leader and the members (docs/communication.md).

``channel``: which beacon reaches which member when (delay, jitter, loss, beacon rate), drawn
from the run's seed in its own random stream. ``predict``: how a member turns the newest
virtual-car state it holds into the present one. Pure, no SUMO.
"""
