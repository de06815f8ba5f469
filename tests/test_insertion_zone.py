"""The insertion zone's room check (sumo/zone.py insertion_zones and blocker, also behind the clearing at
insertion): the circle pre-test skips only pairs the exact separating-axis test finds apart,
so the answer is the exact test's for every pair, touching bodies included."""
import math

import numpy as np

from formation_traci.sumo.road_setup import rectangles_overlap
from formation_traci.sumo.zone import blocker, insertion_zone, insertion_zones


def has_room(pos, heading, v, vehicles, front, bodies) -> bool:
    """Is every member's insertion zone free of ``bodies``? (sumo/flow_inserts.py RoomCheck's test)"""
    return blocker(insertion_zones(pos, heading, v, vehicles, front), bodies) < 0


class Car:
    length, width = 4.5, 1.8


def _exact(pos, heading, v, front, bodies) -> bool:
    x, y, psi, length, width = bodies
    for i in range(len(pos)):
        zc, zl, zw = insertion_zone(pos[i], heading[i], v[i], Car, front[i])
        for j in range(len(x)):
            if rectangles_overlap(zc, heading[i], np.array([x[j], y[j]]), psi[j], zl, zw, length[j], width[j]):
                return False
    return True


def test_room_is_the_exact_tests_answer_for_random_traffic():
    rng = np.random.default_rng(7)
    agree = {True: 0, False: 0}
    for _ in range(400):
        pos = rng.uniform([-5, -4], [5, 4], size=(3, 2))
        heading = rng.uniform(-0.2, 0.2, 3)
        v, front = rng.uniform(0, 35, 3), rng.uniform(0, 40, 3)
        n = int(rng.integers(0, 12))
        bodies = (rng.uniform(-80, 80, n), rng.uniform(-8, 8, n), rng.uniform(-math.pi, math.pi, n),
                  rng.uniform(3.5, 16.0, n), rng.uniform(1.6, 2.6, n))
        want = _exact(pos, heading, v, front, bodies)
        assert has_room(pos, heading, v, [Car] * 3, front, bodies) == want
        agree[want] += 1
    assert min(agree.values()) > 40  # both answers were exercised


def test_a_body_touching_the_zone_leaves_room_and_one_a_centimetre_in_does_not():
    """Zone of a car at the origin, heading +x, at 0 m/s: its rear end 2 m behind the body,
    0.3 m beside it. A car of the same width right behind, bumper on the zone's end: room (the
    exact test calls touching apart); 1 cm closer: none. Both are within the pre-test's reach."""
    zc, zl, zw = insertion_zone(np.zeros(2), 0.0, 0.0, Car, 10.0)
    rear = zc[0] - zl / 2
    for overlap, room in ((0.0, True), (0.01, False)):
        x = rear - Car.length / 2 + overlap  # its front bumper ``overlap`` [m] inside the zone
        bodies = (np.array([x]), np.array([0.0]), np.array([0.0]), np.array([Car.length]), np.array([Car.width]))
        assert has_room(np.zeros((1, 2)), np.zeros(1), np.zeros(1), [Car], np.array([10.0]), bodies) is room
