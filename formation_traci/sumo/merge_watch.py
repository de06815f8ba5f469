"""Ramp traffic at the joins of a formation's route, every step: the yield law's inputs read from
SUMO, the cap it puts on each formation's requested acceleration, its events, and what each
ramp vehicle did (run.json ``merges``, metrics.json per formation).

The joins come from the network (road/ramps.py); a join is watched for a formation from when its
front-most member is within ``horizon_s`` at ``V_WATCH`` of the join's start until its rear-most
member has passed the end of the acceleration lane. Its vehicles are read then only (a few lanes
a step). Modes (scenario ``[cooperation] merge``): ``open_gap`` applies the law's cap
(control/merge.py), ``none`` only observes, ``shift`` asks the formation's maneuver generator
(control/maneuvers/generator.py MergeShift) for a lane change one lane to the left when a ramp
vehicle is in conflict (the law's YIELD) and members are in the merge lane: the attempt is made
at the step's plan, after this step's cap, so on that first step of a conflict the formation
neither yields nor records a yield. While its shift is under way it does not yield (yields
under way end: "the formation shifts away"); when the attempt was refused it yields as
``open_gap`` does (the refusal's reason in merge_yield_start's detail) and asks again every step
of the conflict. At a join where the lane left of the merge lane runs into the same lane as the
merge lane (road/ramps.py ``left_merges``: LuST's on-ramps) a shift would move the formation
into a lane that merges with the merge lane: there ``shift`` yields as ``open_gap`` from the
first step (merge_yield_start's detail says why).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..control.merge import BEHIND, OUTSIDE, YIELD, MergeLane, MergeSite, RampTraffic, yield_to_ramp

V_WATCH = 40.0
"""The speed at which a formation's distance to a join is turned into time when deciding to
watch it [m/s] (above motorway speeds: a join is watched early rather than late)."""
STOOD_MPS = 1.0
"""A ramp vehicle below this speed waits [m/s]."""
NO_SHIFT_WHY = "the lane to the left merges with the merge lane at the join's end"


@dataclass(frozen=True)
class Site:
    """A join on the reference line (road/ramps.py RampJoin)."""

    merge: MergeSite  # join start and acceleration lane length [m]
    d_merge: float  # the merge lane's centre offset from the reference line [m]
    half_lane: float  # half the merge lane's width [m]
    lanes: dict  # the ramp's lanes and the acceleration lane -> distance from start to the join [m]
    added: str  # the acceleration lane ("" for a direct join)
    left_merges: bool = False  # the lane left of the merge lane merges with it at the join's end


def merge_sites(road) -> list[Site]:
    """The joins of ``road``'s route (sumo/road_setup.py Road ``joins``) on its reference line."""
    s0 = {seg.edge: seg.s0 for seg in road.segments}
    out = []
    for j in road.joins:
        edge = road.route[j.edge_index]
        lanes = dict(j.feeders)
        if j.added_lane:
            lanes[j.added_lane] = 0.0
        out.append(Site(MergeSite(s0[edge], j.length_m), float(road.lane_d[edge][j.merge_index]),
                        j.merge_width_m / 2.0, lanes, j.added_lane, j.left_merges))
    return out


@dataclass
class _Seen:
    """What one ramp vehicle did while a formation watched its join."""

    v_first: float
    v_min: float
    waited_s: float = 0.0
    at_end: bool = False  # stood at the end of the acceleration lane
    merged: bool = False


@dataclass
class _Watch:
    """One formation's state at the joins."""

    yielding: set = field(default_factory=set)
    seen: dict = field(default_factory=dict)  # ramp vehicle -> _Seen


class MergeWatch:
    """The joins of one road run and the formations passing them (module docstring).
    ``groups``: per formation (id, its virtual car's id, its member rows); ``world``: the
    SUMO world (its adapter, recorder, members' SUMO ids and bodies)."""

    def __init__(self, sites, mode: str, params, world, groups, dt: float, shifts=None):
        self.sites, self.mode, self.p, self.groups, self.dt = sites, mode, params, groups, dt
        self.shifts = shifts if shifts is not None else [None] * len(groups)  # per formation (shift mode)
        self.adapter, self.rec, self.sumo_ids = world.adapter, world.rec, world.sumo_ids
        self._seen, self._members = None, set()  # the members' SUMO ids (a join changes one)
        self.d_front = world.d_front
        self.length = np.array([mt.length for mt in world.mtypes])
        self.watch = [_Watch() for _ in groups]
        self._decision = np.empty(0, dtype=np.int64)
        firsts = np.array([rows[0] for _, _, rows in groups], dtype=np.int64)  # contiguous rows each
        self._order = np.argsort(np.argsort(firsts))  # formation -> its rank by first row
        self._starts = np.sort(firsts)
        self.formation_at = {int(r): f for f, r in enumerate(firsts)}  # first member row -> formation
        self._from = np.array([x.merge.s_start - params.horizon_s * V_WATCH for x in sites])
        self._to = np.array([x.merge.s_start + x.merge.length for x in sites])

    def limits(self, t: float, m_s, m_d, v_m, active) -> np.ndarray:
        """Each formation's cap on its requested acceleration for the step at t [s] (inf: none),
        from its members' arc lengths, offsets [m] and speeds [m/s] (``active``: in the run)."""
        out = np.full(len(self.groups), math.inf)
        front = m_s + self.d_front
        near = self._near(front, active)
        if not near.any():
            return out
        if self.sumo_ids != self._seen:
            self._seen, self._members = list(self.sumo_ids), set(self.sumo_ids)
        ends, members = np.vstack((front, front - self.length)), self._members
        for q, site in enumerate(self.sites):
            read = None
            for f in np.flatnonzero(near[q]):
                rows = self.groups[f][2]
                rows = rows[active[rows]]
                if read is None:
                    read = self.adapter.ramp_vehicles(site.lanes, members)
                out[f] = min(out[f], self._formation(t, f, site, read, ends[:, rows], m_d[rows], v_m[rows]))
        return out

    def watching(self, front, active) -> bool:
        """Is any formation near a join, its members' front bumpers ``front`` [m] (``active``:
        in the run)? Those steps go through the loop's own path (sumo/fused_path.py)."""
        return bool(self._near(front, active).any())

    def _near(self, front, active) -> np.ndarray:
        """(joins, formations) bool: the formation's front-most member within ``horizon_s`` at
        V_WATCH of the join's start and its rear-most front bumper not past the acceleration
        lane's end (members out of the run not counted; NaN positions never near)."""
        hi = np.where(active, front, -np.inf)
        lo = np.where(active, front, np.inf)
        top = np.maximum.reduceat(hi, self._starts)[self._order]
        bottom = np.minimum.reduceat(lo, self._starts)[self._order]
        return (top >= self._from[:, None]) & (bottom <= self._to[:, None])

    def _formation(self, t, f, site, read, ends, d, v) -> float:
        """Formation f's cap at ``site`` (inf: none), its events and observations."""
        ids, lanes, rows = read
        w, (fid, vc_id, _) = self.watch[f], self.groups[f]
        in_lane = np.abs(d - site.d_merge) < site.half_lane
        if not in_lane.any() or not ids:
            self._forget(t, w, vc_id, ids)
            return math.inf
        front, rear = ends[0, in_lane], ends[1, in_lane]
        lane = MergeLane(float(front.max()), float(v[in_lane][np.argmax(front)]), float(rear.min()))
        yielding = np.array([vid in w.yielding for vid in ids])
        ramp = RampTraffic(rows[0].copy(), rows[1].copy(), rows[2].copy(), rows[3].copy(), yielding)
        if self._decision.shape[0] < len(ids):
            self._decision = np.empty(len(ids), dtype=np.int64)
        decision = self._decision[:len(ids)]
        cap = yield_to_ramp(site.merge, ramp, lane, self.p, decision)
        yields, why = self._yields(t, w, vc_id, self.shifts[f], decision, ids, site.left_merges)
        for j, vid in enumerate(ids):
            self._observe(w, vid, lanes[j], rows[:, j], decision[j], site)
            if yields:
                self._events(t, w, vc_id, vid, decision[j], cap, why)
        self._forget(t, w, vc_id, ids)
        return cap if yields else math.inf

    def _yields(self, t, w, vc_id, shift, decision, ids, left_merges=False) -> tuple[bool, str]:
        """Does the formation yield as open_gap this step (its cap and events), and the
        prefix of merge_yield_start's detail; in shift mode, asks for the shift (module docstring)."""
        if self.mode != "shift" or shift is None:  # (a formation without a generator that shifts: yields)
            return self.mode != "none", ""
        if left_merges:  # a shift would move into the lane the merge lane merges with
            return True, f"no shift ({NO_SHIFT_WHY}); "
        if shift.shifting:
            for vid in sorted(w.yielding):
                self._end(t, w, vc_id, vid, "the formation shifts away")
            return False, ""
        if not (decision == YIELD).any():
            shift.refused = None
            return True, ""
        shift.asked = ids[int(np.argmax(decision == YIELD))]  # the first in conflict, named in the event
        if shift.refused is None:  # the first step of a conflict: the attempt's answer comes at plan
            return False, ""
        return True, f"shift refused ({shift.refused}); "

    def _observe(self, w, vid, lane, row, code, site) -> None:
        if code == OUTSIDE and vid not in w.seen:
            return
        got = w.seen.get(vid)
        if got is None:
            got = w.seen[vid] = _Seen(float(row[1]), float(row[1]))
        got.v_min = min(got.v_min, float(row[1]))
        if row[1] < STOOD_MPS:
            got.waited_s += self.dt
            if lane == site.added and row[4] >= site.merge.length - 10.0:
                got.at_end = True

    def _events(self, t, w, vc_id, vid, code, cap, why: str = "") -> None:
        if code == YIELD and vid not in w.yielding:
            w.yielding.add(vid)
            self.rec.add_event(t, "merge_yield_start", vc_id, vid,
                               f"{why}open_gap: acceleration cap {cap:.2f} m/s^2")
        elif code in (OUTSIDE, BEHIND) and vid in w.yielding:
            self._end(t, w, vc_id, vid, "past the merge point" if code == OUTSIDE else "merges behind")

    def _end(self, t, w, vc_id, vid, why: str) -> None:
        w.yielding.discard(vid)
        self.rec.add_event(t, "merge_yield_end", vc_id, vid, why)

    def _forget(self, t, w, vc_id, ids) -> None:
        """Ramp vehicles no longer on the ramp's lanes have merged (or left)."""
        here = set(ids)
        for vid, got in w.seen.items():
            if vid not in here and not got.merged:
                got.merged = True
                if vid in w.yielding:
                    self._end(t, w, vc_id, vid, "merged")

    def summary(self) -> dict:
        """Per formation: ``ramp_vehicles``, ``merged_before_lane_end`` (those that did not stand
        at the end of the acceleration lane), ``ramp_speed_loss_mps``
        (mean of first speed less lowest speed over the ramp vehicles seen within the horizon),
        ``ramp_wait_s`` (their mean time below STOOD_MPS)."""
        out = {}
        for (fid, _, _), w in zip(self.groups, self.watch):
            seen = list(w.seen.values())
            n = len(seen)
            out[fid] = {"ramp_vehicles": n,
                        "merged_before_lane_end": sum(1 for x in seen if not x.at_end),
                        "ramp_speed_loss_mps": float(np.mean([x.v_first - x.v_min for x in seen])) if n else None,
                        "ramp_wait_s": float(np.mean([x.waited_s for x in seen])) if n else None}
        return out
