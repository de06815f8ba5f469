"""Incidents of a run: what makes its status ``completed_with_incidents`` (docs/reliability.md).

* ``member_collisions``: a member's body overlaps another member's by our own geometry (the
  signed body clearance of :func:`signed_clearance` < 0 at a recorded step; one per pair and
  contact, counted when it starts), or a collision SUMO reports between a member and a SUMO
  vehicle that our clearance confirms;
* ``member_removed``: a member SUMO no longer has or that was taken out after refused moves;
* ``emergency_brakes``: the virtual car or a member starts braking harder than comfortable
  (``emergency_brake`` events, sumo/events.py EmergencyWatch);
* ``stranded``: a member in the run below :data:`STRANDED_SPEED` for more than
  :data:`STRANDED_TIME` while its speed reference (eq 2.6) is above :data:`STRANDED_V_REF`:
  it stands while the formation wants it to drive (:func:`slow_members`, which the compiled
  step of a road run calls too);
* ``sumo_emergency_brakes``: SUMO's "emergency braking" warning about a member, whoever drives
  it (sumo/messages.py): a member SUMO's own car-following model drives (``controller.law =
  "sumo_cacc"``) braked harder than its vType's ``decel``; a member we place is told its
  commanded speed with every move (docs/sumo.md, "SUMO's speed of a member"), so SUMO warns only
  when that speed drops faster than the member type's emergency deceleration;
* ``lane_departures``: a member of a column under a platoon law (ours or SUMO's CACC; its
  head, which runs the virtual structure, included) with its centre of gravity more than half a lane width
  (:meth:`Incidents.watch_lanes`) across from its slot's lateral offset: it left its lane
  (counted when it leaves; a ``lane_departure`` event). Only in runs without maneuvers (a
  maneuver moves the slot);
* ``sumo_collision_artefacts``: collisions SUMO reports for a member where our clearance is
  >= 0 (SUMO checks collisions per lane: a body that reaches into the next lane "collides"
  with a vehicle there it does not touch). Counted, recorded as ``collision_artefact``
  events, not in the verdict.

Contacts and SUMO's reports are counted once per pair and contact: a pair reported at
consecutive recorded steps is one incident.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from run_contract.columns import INCIDENT_VERDICT as VERDICT

from ..core.kernels import kernel
from ..record.columns import SIGNAL_COLUMNS


STRANDED_SPEED = 0.5
"""A member below this speed [m/s] ... """
STRANDED_TIME = 5.0
"""... for longer than this [s] ..."""
STRANDED_V_REF = 2.0
"""... while its speed reference v_ref (eq 2.6) is above this [m/s] is stranded."""

_X, _Y, _H = (SIGNAL_COLUMNS.index(c) for c in ("x", "y", "heading"))
_V, _VREF = SIGNAL_COLUMNS.index("v"), SIGNAL_COLUMNS.index("v_ref")


@kernel
def _point_to_box(cx, cy, c, s, hl, hw, px, py):
    """Distance [m] from point (px, py) to the rectangle of centre (cx, cy), heading (c, s) =
    (cos, sin), half length hl and half width hw (0 inside)."""
    dx, dy = px - cx, py - cy
    u, v = abs(c * dx + s * dy) - hl, abs(-s * dx + c * dy) - hw
    return math.hypot(max(u, 0.0), max(v, 0.0))


@kernel
def signed_clearance(xa, ya, ha, la, wa, xb, yb, hb, lb, wb):
    """Signed clearance [m] between two rectangles (centre x, y [m], heading [rad CCW from
    +x], length, width [m]): the distance between the outlines when apart (a corner of one to
    the other: the closest pair of disjoint convex polygons always has a corner), minus the
    smallest overlap over the four edge normals when they overlap (separating-axis test)."""
    ca, sa, cb, sb = math.cos(ha), math.sin(ha), math.cos(hb), math.sin(hb)
    hla, hwa, hlb, hwb = 0.5 * la, 0.5 * wa, 0.5 * lb, 0.5 * wb
    dx, dy = xb - xa, yb - ya
    depth = math.inf
    for k in range(4):
        nx, ny = (ca, sa) if k == 0 else (-sa, ca) if k == 1 else (cb, sb) if k == 2 else (-sb, cb)
        ra = hla * abs(ca * nx + sa * ny) + hwa * abs(-sa * nx + ca * ny)
        rb = hlb * abs(cb * nx + sb * ny) + hwb * abs(-sb * nx + cb * ny)
        depth = min(depth, ra + rb - abs(dx * nx + dy * ny))
    if depth >= 0.0:
        return -depth
    best = math.inf
    for k in range(4):
        su = 1.0 if k == 0 or k == 3 else -1.0
        sv = 1.0 if k < 2 else -1.0
        best = min(best, _point_to_box(xa, ya, ca, sa, hla, hwa,
                                       xb + cb * su * hlb - sb * sv * hwb,
                                       yb + sb * su * hlb + cb * sv * hwb))
        best = min(best, _point_to_box(xb, yb, cb, sb, hlb, hwb,
                                       xa + ca * su * hla - sa * sv * hwa,
                                       ya + sa * su * hla + ca * sv * hwa))
    return best


REACH_MARGIN = 1e-3
"""Pairs whose body centres are farther apart than the sum of their half diagonals plus this
[m] cannot touch: :func:`member_clearances` leaves their clearance at +inf."""


@kernel
def member_clearances(sig, x_col, y_col, h_col, shift, length, width, active, out):
    """Signed clearance [m] of every pair of active members that can touch into ``out`` (n, n),
    upper triangle (i < j); +inf for a pair with a member out of the run and for a pair whose
    body centres are farther apart than their half diagonals and :data:`REACH_MARGIN` (its
    clearance is above that margin: no contact). ``sig``: the members' signal rows (CoG x, y,
    heading in columns x_col, y_col, h_col); ``shift``: CoG to body centre along the heading
    [m]. Returns the smallest clearance of the pairs that can touch (+inf: none). The test of
    reach costs ~4 ns a pair, the clearance itself ~100 ns (500 members in formations of three:
    0.44 ms per step against 16 ms for every pair's clearance; benchmarks/member_pairs.py)."""
    n = sig.shape[0]
    cx, cy, reach = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        hi = sig[i, h_col]
        cx[i] = sig[i, x_col] + shift[i] * math.cos(hi)
        cy[i] = sig[i, y_col] + shift[i] * math.sin(hi)
        reach[i] = 0.5 * math.hypot(length[i], width[i])
    worst = math.inf
    for i in range(n):
        for j in range(i + 1, n):
            out[i, j] = math.inf
            if not (active[i] and active[j]):
                continue
            dx, dy, r = cx[j] - cx[i], cy[j] - cy[i], reach[i] + reach[j] + REACH_MARGIN
            if dx * dx + dy * dy > r * r:
                continue  # apart by more than the margin
            c = signed_clearance(cx[i], cy[i], sig[i, h_col], length[i], width[i],
                                 cx[j], cy[j], sig[j, h_col], length[j], width[j])
            out[i, j] = c
            worst = min(worst, c)
    return worst


@kernel
def slow_members(sig, v_col, v_ref_col, thresholds, active, out):
    """Which members with ``active`` stand while their speed reference does not: speed (signal
    column ``v_col`` of ``sig``) below ``thresholds[0]`` [m/s] while v_ref (``v_ref_col``) is
    above ``thresholds[1]`` [m/s] (:data:`STRANDED_SPEED`, :data:`STRANDED_V_REF`), into ``out``
    (n,); returns whether any does."""
    anyone = False
    for i in range(sig.shape[0]):
        out[i] = active[i] and sig[i, v_col] < thresholds[0] and sig[i, v_ref_col] > thresholds[1]
        anyone |= out[i]
    return anyone


class IncidentArrays(NamedTuple):
    """What the compiled step reads of the incidents' watch (sumo/fused_step.py)."""

    cols: np.ndarray  # the signal columns x, y, heading, v, v_ref
    shift: np.ndarray  # (n,) CoG to the body's centre [m]
    length: np.ndarray  # (n,) [m]
    width: np.ndarray  # (n,) [m]
    clear: np.ndarray  # (n, n) clearance between members [m] (written)
    stranded: np.ndarray  # STRANDED_SPEED [m/s], STRANDED_V_REF [m/s]
    slow: np.ndarray  # (n,) the members slow_members finds (written)


class Incidents:
    """Counts the incidents of a run (module docstring) and records their events.

    :meth:`step` at every recorded step (the members' signal rows); :meth:`sumo_collisions`
    with the collisions SUMO reported for the step (sumo/world.py); :meth:`counts` for
    run.json."""

    def __init__(self, rec, ids, vehicles, pairs: bool = True):
        n = len(ids)
        self.rec, self.ids = rec, list(ids)
        self.pairs = bool(pairs)  # False: independent members (run.independent_members)
        self.length = np.array([v.length for v in vehicles], dtype=float)
        self.width = np.array([v.width for v in vehicles], dtype=float)
        self.shift = np.array([v.cog_to_front_bumper - 0.5 * v.length for v in vehicles], dtype=float)
        self.clear = np.full((n, n), np.inf)
        self.contact = np.zeros((n, n), dtype=bool)
        self.slow_since = np.full(n, np.nan)  # since when each member stands while its v_ref does not [s]
        self.slow = np.zeros(n, dtype=np.bool_)  # who does at the last check (slow_members)
        self._thresholds = np.array([STRANDED_SPEED, STRANDED_V_REF])
        self.is_stranded = np.zeros(n, dtype=bool)
        self._sumo_prev: set = set()  # (collider, victim) SUMO reported at the last report
        self._standing = False  # any member in slow_since
        self.busy = False  # a contact, a stranded or standing member: after_clearances has work
        self.n = dict.fromkeys(("member_collisions", "stranded", "sumo_collision_artefacts",
                                "sumo_emergency_brakes", "lane_departures"), 0)
        self.lane_watch = None  # (mask, slot d [m], half lane width [m]): watch_lanes
        self.off_lane = np.zeros(n, dtype=bool)  # out of its lane at the last check

    @property
    def arrays(self) -> IncidentArrays:
        """The arrays the compiled step works on (the same ones over a run)."""
        return IncidentArrays(np.array([_X, _Y, _H, _V, _VREF], dtype=np.int64), self.shift,
                              self.length, self.width, self.clear, self._thresholds, self.slow)

    def step(self, t: float, sig: np.ndarray, active: np.ndarray) -> None:
        worst = math.inf
        if self.pairs:
            worst = member_clearances(sig, _X, _Y, _H, self.shift, self.length, self.width,
                                      active, self.clear)
        self.after_clearances(t, sig, active, worst)

    def after_clearances(self, t: float, sig: np.ndarray, active: np.ndarray, worst: float) -> None:
        """:meth:`step` once the clearances are in ``self.clear`` (``worst``: the smallest)
        [m]: contacts and stranded members."""
        if self.pairs and (worst < 0.0 or self.contact.any()):
            self._contacts(t)
        slow = self.slow
        if (slow_members(sig, _V, _VREF, self._thresholds, np.ascontiguousarray(active, dtype=np.bool_), slow)
                or self.is_stranded.any()):
            self._stranded(t, slow, sig[:, _V], sig[:, _VREF])
        elif self._standing:
            self.slow_since[:] = np.nan
            self._standing = False
        self.busy = bool(self._standing or self.contact.any() or self.is_stranded.any())

    def _contacts(self, t):
        n = len(self.ids)
        for i in range(n):
            for j in range(i + 1, n):
                c = self.clear[i, j]
                if c < 0.0 and not self.contact[i, j]:
                    self.n["member_collisions"] += 1
                    self.rec.add_event(t, "member_collision", self.ids[i], self.ids[j],
                                       f"the bodies overlap by {-c:.2f} m (our geometry)", value=c)
                self.contact[i, j] = c < 0.0

    def _stranded(self, t, slow, v, v_ref):
        since = np.where(slow, np.where(np.isnan(self.slow_since), t, self.slow_since), np.nan)
        self.slow_since, self._standing = since, bool(slow.any())
        now = slow & (t - np.where(slow, since, t) > STRANDED_TIME + 1e-9)
        for i in np.flatnonzero(now & ~self.is_stranded):
            self.n["stranded"] += 1
            self.rec.add_event(t, "stranded", self.ids[i], "",
                               f"v = {v[i]:.2f} m/s for {t - since[i]:.2f} s with v_ref = "
                               f"{v_ref[i]:.2f} m/s", value=v[i])
        self.is_stranded = now

    def sumo_collisions(self, t, collisions, clearance_of) -> None:
        """SUMO's collision reports of a step, ``collisions``: (collider, victim, lane) with
        member ids where a member is involved. ``clearance_of(a, b)``: our signed clearance of
        the two [m] (NaN: not known, e.g. no member or a vehicle out of sight). A report with a
        member and our clearance >= 0 is a ``collision_artefact``; the others stay
        ``collision`` events, and one with a SUMO vehicle our clearance confirms is a member
        collision (a member pair is counted by :meth:`step`)."""
        members = set(self.ids)
        now = set()
        for a, b, lane in collisions:
            c = clearance_of(a, b)
            key = (a, b)
            now.add(key)
            new = key not in self._sumo_prev
            if c == c and c >= 0.0:
                self.rec.add_event(t, "collision_artefact", a, b,
                                   f"lane {lane}; our body clearance {c:.2f} m")
                self.n["sumo_collision_artefacts"] += new
                continue
            known = "" if c != c else f"; our body clearance {c:.2f} m"
            self.rec.add_event(t, "collision", a, b, f"lane {lane}{known}")
            if new and (a in members) != (b in members):  # not refuted: counted
                self.n["member_collisions"] += 1
                m, other = (a, b) if a in members else (b, a)
                log = getattr(self.rec, "incident_log", None)
                if log is not None:
                    log.add(t, "member_collision", m, other, c)
        self._sumo_prev = now

    def watch_lanes(self, mask, slot_d, half_width: float) -> None:
        """Check the members of ``mask`` (n,) in :meth:`lanes`: each keeps its centre of
        gravity within ``half_width`` [m] of its slot's lateral offset ``slot_d`` (n,) [m]."""
        mask = np.asarray(mask, dtype=bool)
        if mask.any():
            self.lane_watch = (mask, np.asarray(slot_d, dtype=float), float(half_width))

    def lanes(self, t: float, d, active) -> None:
        """Lane departures at t [s] from the members' lateral offsets ``d`` (n,) [m] across
        the road's reference line (NaN: not known)."""
        if self.lane_watch is None:
            return
        mask, slot_d, half = self.lane_watch
        off = mask & active & (np.abs(d - slot_d) > half)  # NaN compares False
        if not (off.any() or self.off_lane.any()):
            return
        for i in np.flatnonzero(off & ~self.off_lane):
            self.n["lane_departures"] += 1
            self.rec.add_event(t, "lane_departure", self.ids[i], "",
                               f"d = {d[i]:.2f} m, its slot's {slot_d[i]:.2f} m: more than "
                               f"{half:.2f} m (half a lane) across")
        self.off_lane = off

    def sumo_message(self, kind: str, of_member: bool) -> None:
        """One of SUMO's warnings (sumo/messages.py kind), ``of_member`` when it names a
        member's SUMO vehicle: an emergency braking of a member is an incident."""
        if kind == "emergency_braking" and of_member:
            self.n["sumo_emergency_brakes"] += 1

    def counts(self) -> dict[str, int]:
        """run.json ``incidents`` (INCIDENT_KEYS)."""
        ev = self.rec.event_counts
        return {"member_collisions": int(self.n["member_collisions"]),
                "member_removed": int(ev.get("member_removed", 0)),
                "emergency_brakes": int(ev.get("emergency_brake", 0)),
                "stranded": int(self.n["stranded"]),
                "sumo_emergency_brakes": int(self.n["sumo_emergency_brakes"]),
                "lane_departures": int(self.n["lane_departures"]),
                "sumo_collision_artefacts": int(self.n["sumo_collision_artefacts"])}


def clearance_lookup(inc: Incidents | None, ids, active, pos, heading, nb):
    """``clearance_of(a, b)`` for :meth:`Incidents.sumo_collisions`: our signed body clearance
    [m] of two vehicles by id (members: our CoG ``pos`` and ``heading``; SUMO's vehicles: their
    body as sensed, ``nb``: sumo/types.py Neighbours; NaN for one out of the run or out of
    sight)."""
    index = {m: i for i, m in enumerate(ids)}
    nb_index = {} if nb is None else {vid: j for j, vid in enumerate(nb.ids)}

    def body(vid):
        i = index.get(vid)
        if i is not None:
            if inc is None or not active[i]:
                return None
            h = float(heading[i])
            return (float(pos[i, 0]) + inc.shift[i] * math.cos(h),
                    float(pos[i, 1]) + inc.shift[i] * math.sin(h), h, inc.length[i], inc.width[i])
        j = nb_index.get(vid)
        if j is None:
            return None
        return (float(nb.x[j]), float(nb.y[j]), float(nb.heading[j]), float(nb.length[j]),
                float(nb.width[j]))

    def clearance_of(a, b):
        ba, bb = body(a), body(b)
        return np.nan if ba is None or bb is None else float(signed_clearance(*ba, *bb))
    return clearance_of


def verdict(status: str, incidents: dict) -> tuple[str, str | None]:
    """``completed`` becomes ``completed_with_incidents`` when any verdict incident is > 0;
    returns the status and a one-line summary of the incidents (None: none)."""
    named = [f"{incidents[k]} {k.replace('_', ' ')}" for k in VERDICT if incidents.get(k, 0) > 0]
    if not named:
        return status, None
    return ("completed_with_incidents" if status == "completed" else status), ", ".join(named)
