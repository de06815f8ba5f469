"""The leader-to-member channel: beacon instants, per-link delay, jitter and loss.

The virtual leader broadcasts its state at ``beacon_hz``; beacon b leaves at control instant
``send[b]`` (the first control instant at or after b / beacon_hz: the leader's state exists
only at control instants). On each link (one per member) it is lost or arrives after

    delay = delay_s + jitter,   jitter >= 0 drawn from ``jitter`` with mean ``jitter_s``:
        'exponential'  mean jitter_s, standard deviation jitter_s,
        'uniform'      on [0, 2 jitter_s]: mean jitter_s, standard deviation jitter_s / sqrt(3).

A member samples its radio at its own control instants, so a beacon is usable from the first
control instant at or after its arrival. Loss models (per beacon, per link):

* ``none``;
* ``independent``: each beacon lost with probability ``loss_p`` (Bernoulli);
* ``bursty``: the two-state Gilbert-Elliott chain, every beacon lost in the bad state and none
  in the good one, with P(good -> bad) = q and P(bad -> good) = r per beacon chosen so that the
  stationary loss is ``loss_p`` = q / (q + r) and the mean burst (run of losses) is
  ``loss_burst`` = 1 / r beacons: r = 1 / loss_burst, q = loss_p r / (1 - loss_p).

Every link draws from ``numpy.random.default_rng(SeedSequence([seed, COMM_STREAM, i]))``
(member index i): its own stream, so switching the channel on changes no other random draw.
Beacon 0 (the state at t = 0) is delivered to every member at once: the formation starts with it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

COMM_STREAM = 0x636F6D6D
"""Second entropy word of every link's SeedSequence ("comm"): the channel's own stream."""
LOST = np.iinfo(np.int64).max
"""Arrival instant of a lost beacon."""
_EPS = 1e-9


@dataclass(frozen=True)
class LinkParams:
    """One link's channel, resolved from [comm] and its per-member override."""

    delay_s: float  # constant part of the delay [s]
    jitter_s: float  # mean of the extra delay [s]
    jitter: str  # "exponential" | "uniform"
    loss: str  # "none" | "independent" | "bursty"
    loss_p: float  # mean loss probability [-]
    loss_burst: float  # mean burst length, bursty model [beacons]

    @property
    def perfect(self) -> bool:
        return self.delay_s == 0.0 and self.jitter_s == 0.0 and (self.loss == "none" or self.loss_p == 0.0)


def link_params(comm, member_id: str) -> LinkParams:
    """[comm] with ``comm.links[member_id]``'s fields where given."""
    o = comm.links.get(member_id)
    pick = lambda name: getattr(o, name) if o is not None and getattr(o, name) is not None \
        else getattr(comm, name)
    return LinkParams(*(float(pick(n)) if n not in ("jitter", "loss") else pick(n)
                        for n in ("delay_s", "jitter_s", "jitter", "loss", "loss_p", "loss_burst")))


def gilbert_rates(loss_p: float, loss_burst: float) -> tuple[float, float]:
    """(q, r): per-beacon P(good -> bad) and P(bad -> good) of the Gilbert-Elliott chain with
    stationary loss ``loss_p`` and mean burst ``loss_burst`` [beacons]; ValueError when no
    chain has them (q > 1: loss_burst < loss_p / (1 - loss_p))."""
    r = 1.0 / loss_burst
    q = loss_p * r / (1.0 - loss_p)
    if q > 1.0 + _EPS:
        raise ValueError(f"no Gilbert-Elliott chain has mean loss {loss_p} with mean bursts of "
                         f"{loss_burst} beacons (needs loss_burst >= loss_p / (1 - loss_p) = "
                         f"{loss_p / (1.0 - loss_p):.3g})")
    return min(q, 1.0), r


def beacon_instants(duration: float, control_step: float, beacon_hz: float | None) -> np.ndarray:
    """Control instant (index, time / control_step) at which each beacon leaves; int64.

    ``beacon_hz`` None: one beacon per control instant."""
    n_instants = int(round(duration / control_step))
    if beacon_hz is None:
        return np.arange(n_instants + 1, dtype=np.int64)
    k = np.arange(int(math.floor(duration * beacon_hz + _EPS)) + 1)
    c = np.ceil(k / beacon_hz / control_step - _EPS).astype(np.int64)
    return c[c <= n_instants]


def draw_delays(rng: np.random.Generator, n: int, p: LinkParams) -> np.ndarray:
    """Delays of n beacons [s]: delay_s plus the jitter (see the module docstring)."""
    if p.jitter_s == 0.0:
        return np.full(n, p.delay_s)
    if p.jitter == "exponential":
        return p.delay_s + rng.exponential(p.jitter_s, n)
    if p.jitter == "uniform":
        return p.delay_s + rng.uniform(0.0, 2.0 * p.jitter_s, n)
    raise ValueError(f"unknown jitter distribution {p.jitter!r}")


def draw_losses(rng: np.random.Generator, n: int, p: LinkParams) -> np.ndarray:
    """Which of n beacons are lost (bool)."""
    if p.loss == "none" or p.loss_p == 0.0:
        return np.zeros(n, dtype=bool)
    if p.loss == "independent":
        return rng.random(n) < p.loss_p
    if p.loss == "bursty":
        return gilbert_losses(rng, n, p.loss_p, p.loss_burst)
    raise ValueError(f"unknown loss model {p.loss!r}")


def gilbert_losses(rng: np.random.Generator, n: int, loss_p: float, loss_burst: float) -> np.ndarray:
    """n steps of the Gilbert-Elliott chain (lost in the bad state), started in its stationary
    distribution. Drawn as alternating sojourns: good ~ Geometric(q), bad ~ Geometric(r)."""
    q, r = gilbert_rates(loss_p, loss_burst)
    lost = np.zeros(n, dtype=bool)
    bad = rng.random() < loss_p
    i = 0
    while i < n:
        m = max(1, int(2 * n * min(q, r) + 16))  # sojourn pairs drawn per batch
        good_len = rng.geometric(q, m) if q > 0 else np.full(m, n + 1)
        bad_len = rng.geometric(r, m)
        lens = np.empty(2 * m, dtype=np.int64)
        first, second = (bad_len, good_len) if bad else (good_len, bad_len)
        lens[0::2], lens[1::2] = first, second
        for j, length in enumerate(lens):
            if (j % 2 == 0) == bad:
                lost[i:i + length] = True
            i += int(length)
            if i >= n:
                break
        bad = bad if len(lens) % 2 == 0 else not bad
    return lost


@dataclass(frozen=True)
class Channel:
    """Which beacon each member holds at each control instant.

    ``send`` (B,) control instant of each beacon; ``arrival`` (n, B) control instant from which
    member i can use beacon b (LOST if lost); ``delay_s`` (n, B) drawn delays [s];
    ``arrival_sorted`` / ``newest_sorted`` (n, B): arrivals in increasing order and the newest
    beacon (largest index) among those that have arrived by then (a late beacon never replaces
    a newer one)."""

    send: np.ndarray
    arrival: np.ndarray
    delay_s: np.ndarray
    arrival_sorted: np.ndarray
    newest_sorted: np.ndarray
    control_step: float

    def newest(self, c: int) -> np.ndarray:
        """Newest beacon index each member holds at control instant c, shape (n,)."""
        out = np.empty(self.arrival.shape[0], dtype=np.int64)
        for i in range(len(out)):
            p = int(np.searchsorted(self.arrival_sorted[i], c, side="right"))
            out[i] = self.newest_sorted[i, p - 1]
        return out

    def age(self, c: int) -> np.ndarray:
        """Age of the newest state each member holds at control instant c [s], shape (n,)."""
        return (c - self.send[self.newest(c)]) * self.control_step


def build_channel(links: list[LinkParams], seed: int, duration: float, control_step: float,
                  beacon_hz: float | None, outages=()) -> Channel:
    """Draw every link's delays and losses for a run of ``duration`` [s]; every beacon sent
    inside an ``outages`` window [t0, t1) [s] is lost on every link (the draws unchanged)."""
    send = beacon_instants(duration, control_step, beacon_hz)
    t_send = send * control_step
    dark = np.zeros(len(send), dtype=bool)
    for t0, t1 in outages:
        dark |= (t_send >= t0 - _EPS * control_step) & (t_send < t1 - _EPS * control_step)
    B, n = len(send), len(links)
    arrival = np.empty((n, B), dtype=np.int64)
    delays = np.empty((n, B))
    for i, p in enumerate(links):
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), COMM_STREAM, i]))
        delays[i] = draw_delays(rng, B, p)
        lost = draw_losses(rng, B, p) | dark
        lag = np.ceil(delays[i] / control_step - _EPS).astype(np.int64)
        arrival[i] = np.where(lost, LOST, send + lag)
    arrival[:, 0] = send[0]  # the formation starts with the state at t = 0
    order = np.argsort(arrival, axis=1, kind="stable")
    arrival_sorted = np.take_along_axis(arrival, order, axis=1)
    newest_sorted = np.maximum.accumulate(order, axis=1)
    return Channel(send, arrival, delays, arrival_sorted, newest_sorted, float(control_step))
