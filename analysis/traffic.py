"""Traffic interaction: surrogate safety measures, gaps, headways, delays.

Pure functions over arrays and DataFrames; the per-run glue (which rows, which vehicles,
issues) is :mod:`analysis.traffic_run`. Definitions, units and sources are in
``docs/metrics.md`` (section "Traffic interaction").

Geometry. Every vehicle is an oriented rectangle: centre ``(x, y)`` [m], heading ``h``
[rad, counter-clockwise from +x], length ``l`` and width ``w`` [m]. Background rows give
the body centre; members' rows give the centre of gravity, which :func:`body_centre`
moves to the body centre. Road coordinates ``s`` (along the reference line) and ``d``
(left of it) are those of ``background.parquet`` / ``trajectories.parquet``.
"""
from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

__all__ = [
    "Footprint",
    "MEMBER_FOOTPRINTS",
    "CLEARANCE_THRESHOLD_M",
    "LATERAL_GAP_THRESHOLD_M",
    "TTC2D_THRESHOLD_S",
    "TTC2D_HORIZON_S",
    "HEADWAY_THRESHOLD_S",
    "SSM_TTC_WARNING_S",
    "SSM_TTC_CRITICAL_S",
    "SSM_DRAC_HIGH_MPS2",
    "INTERACTION_RANGE_M",
    "V_STANDSTILL_MPS",
    "SSM_GROUP_COLUMNS",
    "member_footprint",
    "body_centre",
    "rectangle_corners",
    "same_time_pairs",
    "clearance",
    "ttc_2d",
    "pair_measures",
    "lateral_gap",
    "in_lateral_band",
    "gap_ahead",
    "time_headway",
    "merge_ssm_duplicates",
    "ssm_summary",
    "event_counts",
    "time_loss",
    "crossing_times",
    "section_travel_times",
    "baseline_comparison",
]


@dataclass(frozen=True, slots=True)
class Footprint:
    """Body outline of a member relative to its centre of gravity."""

    length: float  # m, bumper to bumper
    width: float  # m
    a: float  # m, centre of gravity to front axle
    front_overhang: float  # m, front axle to front bumper

    @property
    def cog_to_front(self) -> float:
        """Centre of gravity to front bumper, ``a + front_overhang`` [m]."""
        return self.a + self.front_overhang


MEMBER_FOOTPRINTS: dict[str, Footprint] = {
    "passenger_car": Footprint(length=4.6, width=1.8, a=1.421, front_overhang=0.9),
    "small_truck": Footprint(length=7.5, width=2.3, a=1.7, front_overhang=1.3),
}
"""Fallback for recordings whose run.json has no member ``body`` (written before the runner
recorded it): body sizes per ``scenario.vehicle.preset`` as the presets of
``formation_traci/models/params.py`` had them (a test checks that they still agree)."""

CLEARANCE_THRESHOLD_M = 1.0
"""Outline-to-outline clearance below which a member is "close" to another vehicle [m]
(ours: about one door opening; reported as time spent below it)."""

LATERAL_GAP_THRESHOLD_M = 0.5
"""Lateral gap to a side-by-side vehicle below which the pass is "tight" [m] (ours:
SUMO's default ``minGapLat`` is 0.6 m for cars)."""

TTC2D_THRESHOLD_S = 3.0
"""2-D time to collision below which an encounter is a conflict [s]; the TTC threshold of
SUMO's SSM device used by the runs (``--device.ssm.thresholds``)."""

TTC2D_HORIZON_S = 10.0
"""Constant-velocity extrapolation horizon of the 2-D time to collision [s]."""

HEADWAY_THRESHOLD_S = 1.0
"""Time headway below which following is "short" [s] (ours: half the common 2 s rule;
the formation's own ``leader.time_gap`` defaults to 1.5 s)."""

SSM_TTC_WARNING_S = 3.0
"""SSM conflicts with a minimum TTC below this are counted [s] (SUMO SSM threshold)."""

SSM_TTC_CRITICAL_S = 1.5
"""SSM conflicts with a minimum TTC below this are critical [s] (a common critical level
in the traffic-conflict literature, e.g. van der Horst 1990)."""

SSM_DRAC_HIGH_MPS2 = 3.0
"""SSM conflicts whose maximum DRAC exceeds this are counted [m/s^2] (SUMO SSM
threshold)."""

INTERACTION_RANGE_M = 100.0
"""Pairs of vehicles whose centres are farther apart are not evaluated [m]; also the
"near the formation" window ahead of the front member and behind the last one."""

V_STANDSTILL_MPS = 0.1
"""Below this speed a time headway is undefined (NaN) [m/s]."""

SSM_GROUP_COLUMNS: tuple[str, ...] = ("n_conflicts", "ttc_min_s", "drac_max_mps2",
                                      "pet_min_s", "n_ttc_warning", "n_ttc_critical",
                                      "n_drac_high")
"""Columns of :func:`ssm_summary`."""


def _num(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) and v > 0 else None


def member_footprint(scenario: Mapping[str, Any] | None,
                     members: Any = None) -> tuple[Footprint, str]:
    """Members' body outline from run.json: the ``body`` the runner recorded for the members
    (``members[i].body``: length, width, a, front_overhang [m]); for older recordings from
    the recorded scenario.

    Parameters
    ----------
    scenario : mapping or None
        The validated scenario (``run.json`` ``scenario``), used when no member carries a
        body: ``vehicle.preset`` picks :data:`MEMBER_FOOTPRINTS`, ``vehicle.params``
        (``length``, ``width``, ``a``, ``front_overhang`` [m]) overrides single values.
    members : list of mappings or None
        ``run.json`` ``members``.

    Returns
    -------
    (Footprint, str)
        The outline and where it comes from (preset name, overrides, or the
        passenger-car default when the scenario does not say).

    Examples
    --------
    >>> member_footprint({"vehicle": {"preset": "small_truck"}})[0].cog_to_front
    3.0
    """
    bodies = [m.get("body") for m in members or [] if isinstance(m, Mapping)]
    body = bodies[0] if bodies and isinstance(bodies[0], Mapping) else None
    if body is not None:
        values = {k: _num(body.get(k)) for k in ("length", "width", "a")}
        overhang = body.get("front_overhang")
        if None not in values.values() and isinstance(overhang, (int, float)) and overhang >= 0:
            return Footprint(front_overhang=float(overhang), **values), "run.json members body"
    veh = scenario.get("vehicle") if isinstance(scenario, Mapping) else None
    veh = veh if isinstance(veh, Mapping) else {}
    preset = veh.get("preset")
    if preset in MEMBER_FOOTPRINTS:
        base, source = MEMBER_FOOTPRINTS[str(preset)], f"preset {preset}"
    else:
        base = MEMBER_FOOTPRINTS["passenger_car"]
        source = ("scenario.vehicle.preset unknown, passenger_car assumed" if preset is None
                  else f"unknown preset {preset!r}, passenger_car assumed")
    params = veh.get("params") if isinstance(veh.get("params"), Mapping) else {}
    values = {}
    for name in ("length", "width", "a", "front_overhang"):
        v = _num(params.get(name))
        if v is not None or (name == "front_overhang" and params.get(name) in (0, 0.0)):
            values[name] = float(params[name])
    if values:
        source += " with overrides " + ", ".join(sorted(values))
    return replace(base, **values), source


def body_centre(x, y, heading, cog_to_front, length) -> tuple[np.ndarray, np.ndarray]:
    """Centre of the body outline from the centre of gravity.

    Parameters
    ----------
    x : array_like
        Centre of gravity x [m].
    y : array_like
        Centre of gravity y [m].
    heading : array_like
        Heading [rad], counter-clockwise from +x.
    cog_to_front : array_like
        Centre of gravity to front bumper [m].
    length : array_like
        Body length [m].

    Returns
    -------
    (ndarray, ndarray)
        ``centre = CoG + (cog_to_front - length/2) * (cos h, sin h)`` [m].

    Examples
    --------
    >>> [round(float(v), 3) for v in body_centre(0.0, 0.0, 0.0, 2.321, 4.6)]
    [0.021, 0.0]
    """
    off = np.asarray(cog_to_front, float) - 0.5 * np.asarray(length, float)
    h = np.asarray(heading, float)
    return np.asarray(x, float) + off * np.cos(h), np.asarray(y, float) + off * np.sin(h)


def rectangle_corners(x, y, heading, length, width) -> np.ndarray:
    """Corners of oriented rectangles.

    Parameters
    ----------
    x : array_like
        Centre x, shape ``(n,)`` or scalar [m].
    y : array_like
        Centre y [m].
    heading : array_like
        Heading of the long axis [rad].
    length : array_like
        Extent along the heading [m].
    width : array_like
        Extent across the heading [m].

    Returns
    -------
    ndarray
        Shape ``(n, 4, 2)``: front-left, rear-left, rear-right, front-right (counter-
        clockwise) ``(x, y)`` [m].
    """
    x, y, h, hl, hw = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, float)) for v in
                                            (x, y, heading, 0.5 * np.asarray(length, float),
                                             0.5 * np.asarray(width, float))))
    u = np.array([1.0, -1.0, -1.0, 1.0])
    v = np.array([1.0, 1.0, -1.0, -1.0])
    c, s = np.cos(h)[:, None], np.sin(h)[:, None]
    lu, lv = hl[:, None] * u, hw[:, None] * v
    return np.stack([x[:, None] + c * lu - s * lv, y[:, None] + s * lu + c * lv], axis=-1)


def same_time_pairs(key_a, key_b) -> tuple[np.ndarray, np.ndarray]:
    """All index pairs ``(i, j)`` with ``key_a[i] == key_b[j]`` (e.g. the same time step).

    Parameters
    ----------
    key_a : array_like of int
        Key of each row of table A, shape ``(n_a,)``.
    key_b : array_like of int
        Key of each row of table B, shape ``(n_b,)``.

    Returns
    -------
    (ndarray, ndarray)
        Row indices into A and into B, one entry per matching pair, grouped by A's row
        in ascending order.

    Examples
    --------
    >>> [a.tolist() for a in same_time_pairs([0, 1], [1, 0, 1])]
    [[0, 1, 1], [1, 0, 2]]
    """
    ka = np.asarray(key_a)
    kb = np.asarray(key_b)
    order = np.argsort(kb, kind="stable")
    kb_sorted = kb[order]
    lo = np.searchsorted(kb_sorted, ka, side="left")
    hi = np.searchsorted(kb_sorted, ka, side="right")
    counts = hi - lo
    ia = np.repeat(np.arange(ka.size), counts)
    starts = np.repeat(lo - np.concatenate(([0], np.cumsum(counts)[:-1])), counts)
    ib = order[np.arange(ia.size) + starts]
    return ia, ib


_SU = np.array([1.0, -1.0, -1.0, 1.0])
_SV = np.array([1.0, 1.0, -1.0, -1.0])


def _min4(a: np.ndarray) -> np.ndarray:
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), np.minimum(a[:, 2], a[:, 3]))


class _Frames:
    """Each rectangle seen from the other's frame (shared by clearance and TTC)."""

    def __init__(self, xa, ya, ha, la, wa, xb, yb, hb, lb, wb):
        xa, ya, ha, la, wa, xb, yb, hb, lb, wb = np.broadcast_arrays(
            *(np.atleast_1d(np.asarray(v, float)) for v in (xa, ya, ha, la, wa, xb, yb, hb,
                                                            lb, wb)))
        self.hla, self.hwa, self.hlb, self.hwb = 0.5 * la, 0.5 * wa, 0.5 * lb, 0.5 * wb
        self.ca, self.sa, self.cb, self.sb = np.cos(ha), np.sin(ha), np.cos(hb), np.sin(hb)
        dx, dy = xb - xa, yb - ya
        # centre of B in A's frame, and of A in B's frame
        self.ub, self.vb = self.ca * dx + self.sa * dy, -self.sa * dx + self.ca * dy
        self.ua, self.va = -(self.cb * dx + self.sb * dy), -(-self.sb * dx + self.cb * dy)
        phi = hb - ha  # B's heading in A's frame (A's is -phi in B's frame)
        self.cp, self.sp = np.cos(phi), np.sin(phi)
        acp, asp = np.abs(self.cp), np.abs(self.sp)
        # half-extents of each rectangle projected on the other's axes
        self.rb_u = self.hlb * acp + self.hwb * asp
        self.rb_v = self.hlb * asp + self.hwb * acp
        self.ra_u = self.hla * acp + self.hwa * asp
        self.ra_v = self.hla * asp + self.hwa * acp

    def separated(self) -> np.ndarray:
        return ((np.abs(self.ub) > self.hla + self.rb_u)
                | (np.abs(self.vb) > self.hwa + self.rb_v)
                | (np.abs(self.ua) > self.hlb + self.ra_u)
                | (np.abs(self.va) > self.hwb + self.ra_v))

    def clearance(self) -> np.ndarray:
        c, s = self.cp[:, None], self.sp[:, None]
        lu, lv = self.hlb[:, None] * _SU, self.hwb[:, None] * _SV
        u, v = self.ub[:, None] + c * lu - s * lv, self.vb[:, None] + s * lu + c * lv
        d_b = np.hypot(np.maximum(np.abs(u) - self.hla[:, None], 0.0),
                       np.maximum(np.abs(v) - self.hwa[:, None], 0.0))
        lu, lv = self.hla[:, None] * _SU, self.hwa[:, None] * _SV  # A in B's frame: -phi
        u, v = self.ua[:, None] + c * lu + s * lv, self.va[:, None] - s * lu + c * lv
        d_a = np.hypot(np.maximum(np.abs(u) - self.hlb[:, None], 0.0),
                       np.maximum(np.abs(v) - self.hwb[:, None], 0.0))
        return np.where(self.separated(), np.minimum(_min4(d_b), _min4(d_a)), 0.0)

    def ttc(self, vxa, vya, vxb, vyb, horizon: float) -> np.ndarray:
        vxa, vya, vxb, vyb = (np.broadcast_to(np.asarray(v, float), self.ub.shape)
                              for v in (vxa, vya, vxb, vyb))
        rx, ry = vxb - vxa, vyb - vya  # B relative to A
        ru_a, rv_a = self.ca * rx + self.sa * ry, -self.sa * rx + self.ca * ry
        ru_b, rv_b = -(self.cb * rx + self.sb * ry), -(-self.sb * rx + self.cb * ry)
        enter = np.full(self.ub.shape, -np.inf)
        leave = np.full(self.ub.shape, np.inf)
        for half, centre, radius, u in ((self.hla, self.ub, self.rb_u, ru_a),
                                        (self.hwa, self.vb, self.rb_v, rv_a),
                                        (self.hlb, self.ua, self.ra_u, ru_b),
                                        (self.hwb, self.va, self.ra_v, rv_b)):
            lo, hi = _axis_interval(-half, half, centre - radius, centre + radius, u)
            enter, leave = np.maximum(enter, lo), np.minimum(leave, hi)
        hit = (enter <= leave) & (leave >= 0) & (enter <= horizon)
        return np.where(hit, np.maximum(enter, 0.0), np.inf)


def _axis_interval(a0, a1, b0, b1, u):
    """Times at which [b0, b1] + u t overlaps [a0, a1] (closed), as (t_lo, t_hi)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / u
        lo = np.where(u > 0, (a0 - b1) * inv, (a1 - b0) * inv)
        hi = np.where(u > 0, (a1 - b0) * inv, (a0 - b1) * inv)
    still = u == 0
    if still.any():
        overlap = (b0 <= a1) & (b1 >= a0)
        lo = np.where(still, np.where(overlap, -np.inf, np.inf), lo)
        hi = np.where(still, np.where(overlap, np.inf, -np.inf), hi)
    return lo, hi


def clearance(xa, ya, ha, la, wa, xb, yb, hb, lb, wb) -> np.ndarray:
    """Minimum distance between the outlines of two oriented rectangles.

    Parameters
    ----------
    xa : array_like
        Centre x of rectangle A [m].
    ya : array_like
        Centre y of A [m].
    ha : array_like
        Heading of A [rad].
    la : array_like
        Length of A [m].
    wa : array_like
        Width of A [m].
    xb : array_like
        Centre x of rectangle B [m].
    yb : array_like
        Centre y of B [m].
    hb : array_like
        Heading of B [rad].
    lb : array_like
        Length of B [m].
    wb : array_like
        Width of B [m].

    Returns
    -------
    ndarray
        Polygon distance [m], shape of the broadcast inputs (at least 1-D): 0 when the
        rectangles touch or overlap (separating-axis test on the four edge normals),
        else the smallest distance from a corner of one to the other rectangle (for
        disjoint convex polygons the closest pair always includes a corner).

    Examples
    --------
    >>> float(clearance(0, 0, 0, 4, 2, 10, 0, 0, 4, 2)[0])
    6.0
    """
    return _Frames(xa, ya, ha, la, wa, xb, yb, hb, lb, wb).clearance()


def ttc_2d(xa, ya, ha, la, wa, vxa, vya, xb, yb, hb, lb, wb, vxb, vyb,
           horizon: float = TTC2D_HORIZON_S) -> np.ndarray:
    """2-D time to collision of two rectangles moving at constant velocity.

    Both outlines keep their heading and translate with their current velocity; the
    result is the first time their outlines touch (exact for rectangles: the separating-
    axis test on the four edge normals, solved per axis for the interval of overlap and
    intersected over the axes).

    Parameters
    ----------
    xa : array_like
        Centre x of rectangle A [m].
    ya : array_like
        Centre y of A [m].
    ha : array_like
        Heading of A [rad].
    la : array_like
        Length of A [m].
    wa : array_like
        Width of A [m].
    vxa : array_like
        Velocity x of A [m/s].
    vya : array_like
        Velocity y of A [m/s].
    xb : array_like
        Centre x of rectangle B [m].
    yb : array_like
        Centre y of B [m].
    hb : array_like
        Heading of B [rad].
    lb : array_like
        Length of B [m].
    wb : array_like
        Width of B [m].
    vxb : array_like
        Velocity x of B [m/s].
    vyb : array_like
        Velocity y of B [m/s].
    horizon : float
        Longest time looked ahead [s].

    Returns
    -------
    ndarray
        Time to first contact [s]: 0 when the outlines already overlap, ``inf`` when
        they do not touch within ``horizon`` (or move apart).

    Examples
    --------
    >>> float(ttc_2d(0, 0, 0, 4, 2, 30, 0, 24, 0, 0, 4, 2, 25, 0)[0])  # 20 m at 5 m/s
    4.0
    """
    return _Frames(xa, ya, ha, la, wa, xb, yb, hb, lb, wb).ttc(vxa, vya, vxb, vyb, horizon)


def pair_measures(xa, ya, ha, la, wa, vxa, vya, xb, yb, hb, lb, wb, vxb, vyb,
                  horizon: float = TTC2D_HORIZON_S) -> tuple[np.ndarray, np.ndarray]:
    """:func:`clearance` and :func:`ttc_2d` of the same pairs, sharing the geometry.

    Parameters
    ----------
    xa : array_like
        Centre x of rectangle A [m].
    ya : array_like
        Centre y of A [m].
    ha : array_like
        Heading of A [rad].
    la : array_like
        Length of A [m].
    wa : array_like
        Width of A [m].
    vxa : array_like
        Velocity x of A [m/s].
    vya : array_like
        Velocity y of A [m/s].
    xb : array_like
        Centre x of rectangle B [m].
    yb : array_like
        Centre y of B [m].
    hb : array_like
        Heading of B [rad].
    lb : array_like
        Length of B [m].
    wb : array_like
        Width of B [m].
    vxb : array_like
        Velocity x of B [m/s].
    vyb : array_like
        Velocity y of B [m/s].
    horizon : float
        Longest time looked ahead [s].

    Returns
    -------
    (ndarray, ndarray)
        Clearance [m] and 2-D time to collision [s] (``inf``: no contact within
        ``horizon``), shape of the broadcast inputs (at least 1-D).
    """
    f = _Frames(xa, ya, ha, la, wa, xb, yb, hb, lb, wb)
    return f.clearance(), f.ttc(vxa, vya, vxb, vyb, horizon)


def lateral_gap(s_a, d_a, l_a, w_a, s_b, d_b, l_b, w_b) -> np.ndarray:
    """Lateral gap between side-by-side vehicles in road coordinates.

    Parameters
    ----------
    s_a : array_like
        Body centre of A along the road [m].
    d_a : array_like
        Body centre of A across the road, left positive [m].
    l_a : array_like
        Length of A [m].
    w_a : array_like
        Width of A [m].
    s_b : array_like
        Body centre of B along the road [m].
    d_b : array_like
        Body centre of B across the road [m].
    l_b : array_like
        Length of B [m].
    w_b : array_like
        Width of B [m].

    Returns
    -------
    ndarray
        ``|d_a - d_b| - (w_a + w_b)/2`` [m] where the two overlap longitudinally
        (``|s_a - s_b| < (l_a + l_b)/2``), NaN elsewhere. Both bodies are taken as aligned
        with the road; negative means the outlines overlap.

    Examples
    --------
    >>> round(float(lateral_gap(0, 0, 4.6, 1.8, 1, 3.5, 4.5, 1.8)), 6)
    1.7
    """
    s_a, d_a, l_a, w_a, s_b, d_b, l_b, w_b = (np.asarray(v, float) for v in
                                              (s_a, d_a, l_a, w_a, s_b, d_b, l_b, w_b))
    side = np.abs(s_a - s_b) < 0.5 * (l_a + l_b)
    return np.where(side, np.abs(d_a - d_b) - 0.5 * (w_a + w_b), np.nan)


def in_lateral_band(d_a, w_a, d_b, w_b) -> np.ndarray:
    """Whether B is in A's lateral band (their extents across the road overlap).

    Parameters
    ----------
    d_a : array_like
        Body centre of A across the road [m].
    w_a : array_like
        Width of A [m].
    d_b : array_like
        Body centre of B across the road [m].
    w_b : array_like
        Width of B [m].

    Returns
    -------
    ndarray of bool
        ``|d_a - d_b| < (w_a + w_b)/2``.
    """
    return np.abs(np.asarray(d_a, float) - np.asarray(d_b, float)) < 0.5 * (
        np.asarray(w_a, float) + np.asarray(w_b, float))


def gap_ahead(s_a, l_a, s_b, l_b) -> np.ndarray:
    """Bumper-to-bumper gap from A's front to B's rear along the road.

    Parameters
    ----------
    s_a : array_like
        Body centre of A (the follower) along the road [m].
    l_a : array_like
        Length of A [m].
    s_b : array_like
        Body centre of B (the leader) along the road [m].
    l_b : array_like
        Length of B [m].

    Returns
    -------
    ndarray
        ``(s_b - l_b/2) - (s_a + l_a/2)`` [m]; negative when they overlap.

    Examples
    --------
    >>> float(gap_ahead(0.0, 4.0, 24.0, 4.0))
    20.0
    """
    return (np.asarray(s_b, float) - 0.5 * np.asarray(l_b, float)) - (
        np.asarray(s_a, float) + 0.5 * np.asarray(l_a, float))


def time_headway(gap, v, v_min: float = V_STANDSTILL_MPS) -> np.ndarray:
    """Time headway: the gap divided by the follower's speed.

    Parameters
    ----------
    gap : array_like
        Bumper-to-bumper gap to the vehicle ahead [m].
    v : array_like
        Speed of the follower [m/s].
    v_min : float
        Below this speed the headway is NaN [m/s].

    Returns
    -------
    ndarray
        ``gap / v`` [s] (the time the follower needs to reach the leader's current rear
        position); NaN where ``v < v_min`` or the gap is not finite.

    Examples
    --------
    >>> float(time_headway(30.0, 20.0))
    1.5
    """
    gap, v = np.asarray(gap, float), np.asarray(v, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(v >= v_min, gap / v, np.nan)


def merge_ssm_duplicates(ssm: pd.DataFrame) -> pd.DataFrame:
    """One row per conflict: merge the copies SUMO writes for ego and foe.

    Every vehicle carries an SSM device in our runs, so an encounter appears once per
    device, with ego and foe swapped. Rows with the same unordered pair and the same
    ``begin``/``end`` are merged (smallest TTC and PET, largest DRAC).

    Parameters
    ----------
    ssm : DataFrame
        Table with the ``ssm.parquet`` columns (``begin``, ``end``, ``ego``, ``foe``,
        ``min_ttc``, ``max_drac``, ``pet``, ...).

    Returns
    -------
    DataFrame
        Same columns, one row per conflict, ``ego``/``foe`` of the first copy.
    """
    if ssm.empty:
        return ssm.copy()
    df = ssm.copy()
    a, b = df["ego"].astype(str), df["foe"].astype(str)
    df["_p1"], df["_p2"] = np.where(a <= b, a, b), np.where(a <= b, b, a)
    df["_b"], df["_e"] = df["begin"].round(6), df["end"].round(6)
    keys = ["_p1", "_p2", "_b", "_e"]
    agg = {c: "first" for c in df.columns if c not in keys}
    for c, f in (("min_ttc", "min"), ("pet", "min"), ("max_drac", "max")):
        if c in df.columns:
            agg[c] = f
    out = df.groupby(keys, sort=False, dropna=False).agg(agg).reset_index(drop=True)
    return out[[c for c in ssm.columns]]


def ssm_summary(ssm: pd.DataFrame, groups: pd.Series | np.ndarray | None = None, *,
                ttc_warning: float = SSM_TTC_WARNING_S,
                ttc_critical: float = SSM_TTC_CRITICAL_S,
                drac_high: float = SSM_DRAC_HIGH_MPS2) -> pd.DataFrame:
    """Counts and extremes of SSM conflicts per group.

    Parameters
    ----------
    ssm : DataFrame
        Conflicts (one row each, see :func:`merge_ssm_duplicates`) with ``min_ttc`` [s],
        ``max_drac`` [m/s^2], ``pet`` [s].
    groups : array_like of str, optional
        Group label of each row (e.g. ``"member"``/``"other"``); default one group
        ``"all"``.
    ttc_warning : float
        Conflicts with ``min_ttc < ttc_warning`` are counted in ``n_ttc_warning`` [s].
    ttc_critical : float
        Conflicts with ``min_ttc < ttc_critical`` are counted in ``n_ttc_critical`` [s].
    drac_high : float
        Conflicts with ``max_drac > drac_high`` are counted in ``n_drac_high`` [m/s^2].

    Returns
    -------
    DataFrame
        Index: the group labels (sorted); columns :data:`SSM_GROUP_COLUMNS`:
        ``n_conflicts``, ``ttc_min_s``, ``drac_max_mps2``, ``pet_min_s`` (NaN when the
        group has no finite value) and the three counts.

    Examples
    --------
    >>> t = pd.DataFrame({"min_ttc": [2.0, 1.0, np.nan], "max_drac": [1.0, 4.0, 0.5],
    ...                   "pet": [np.nan] * 3})
    >>> ssm_summary(t, ["a", "a", "b"]).loc["a", ["n_conflicts", "n_ttc_critical"]].tolist()
    [2, 1]
    """
    n = len(ssm)
    g = np.asarray(groups, dtype=object) if groups is not None else np.full(n, "all",
                                                                            dtype=object)
    if g.shape != (n,):
        raise ValueError(f"groups must have one label per row ({n}), got shape {g.shape}")
    ttc = pd.to_numeric(ssm.get("min_ttc", pd.Series(np.nan, index=ssm.index)),
                        errors="coerce").to_numpy(float)
    drac = pd.to_numeric(ssm.get("max_drac", pd.Series(np.nan, index=ssm.index)),
                         errors="coerce").to_numpy(float)
    pet = pd.to_numeric(ssm.get("pet", pd.Series(np.nan, index=ssm.index)),
                        errors="coerce").to_numpy(float)
    rows = {}
    for label in sorted(set(g.tolist())):
        m = g == label
        rows[label] = {
            "n_conflicts": int(m.sum()),
            "ttc_min_s": float(np.nanmin(ttc[m])) if np.isfinite(ttc[m]).any() else np.nan,
            "drac_max_mps2": float(np.nanmax(drac[m])) if np.isfinite(drac[m]).any() else np.nan,
            "pet_min_s": float(np.nanmin(pet[m])) if np.isfinite(pet[m]).any() else np.nan,
            "n_ttc_warning": int(np.sum(ttc[m] < ttc_warning)),
            "n_ttc_critical": int(np.sum(ttc[m] < ttc_critical)),
            "n_drac_high": int(np.sum(drac[m] > drac_high)),
        }
    return pd.DataFrame.from_dict(rows, orient="index", columns=list(SSM_GROUP_COLUMNS))


def event_counts(events: pd.DataFrame, ids: Collection[str], kinds: Collection[str],
                 roles: tuple[str, ...] = ("vehicle_id", "other_id")) -> pd.DataFrame:
    """Number of events of each kind that involve each of some vehicles.

    Parameters
    ----------
    events : DataFrame
        Table with the ``events.parquet`` columns (``kind``, ``vehicle_id``,
        ``other_id``).
    ids : collection of str
        Vehicles to count for (e.g. the members).
    kinds : collection of str
        Event kinds to count (e.g. ``"collision"``, ``"cut_in"``).
    roles : tuple of str
        Columns in which a vehicle counts as involved.

    Returns
    -------
    DataFrame
        Index ``ids``, one integer column per kind; an event naming the vehicle in
        several roles counts once.
    """
    ids = [str(i) for i in ids]
    out = pd.DataFrame(0, index=pd.Index(ids, name="id"), columns=list(kinds), dtype=int)
    if events is None or events.empty or "kind" not in events.columns:
        return out
    ev = events.loc[events["kind"].astype(str).isin(list(kinds))]
    for k in kinds:
        e = ev.loc[ev["kind"].astype(str) == k]
        for i in ids:
            hit = np.zeros(len(e), dtype=bool)
            for r in roles:
                if r in e.columns:
                    hit |= (e[r].astype(str) == i).to_numpy()
            out.loc[i, k] = int(hit.sum())
    return out


def time_loss(v, dt: float, v_ref=None, axis: int = -1):
    """Time lost against a reference speed: ``sum (1 - v/v_ref) dt``.

    Parameters
    ----------
    v : array_like
        Speed samples [m/s], uniformly spaced (each sample stands for ``dt``).
    dt : float
        Sample spacing [s].
    v_ref : array_like, optional
        Reference speed [m/s] (broadcast against ``v`` without the time axis); default
        the largest speed along ``axis`` (the vehicle's own maximum recorded speed).
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        Time lost [s]: the extra time the distance actually covered took compared with
        driving it at ``v_ref`` (SUMO's ``timeLoss`` uses the allowed speed instead of the
        maximum recorded one). Non-finite samples count as no loss.

    Examples
    --------
    >>> float(time_loss([20.0, 10.0, 20.0, 20.0], 1.0))  # one second at half speed
    0.5
    """
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive finite sample spacing [s], got {dt!r}")
    v = np.moveaxis(np.asarray(v, float), axis, -1)
    if v_ref is None:
        with np.errstate(invalid="ignore"):
            v_ref = np.nanmax(np.where(np.isfinite(v), v, np.nan), axis=-1) if v.shape[-1] \
                else np.nan
    v_ref = np.asarray(v_ref, float)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        loss = np.where(np.isfinite(v) & (v_ref > 0), 1.0 - v / v_ref, 0.0)
    return np.sum(loss, axis=-1) * dt


def crossing_times(t, s, s_cross) -> np.ndarray:
    """When a vehicle first reaches positions along the road.

    Parameters
    ----------
    t : array_like
        Sample times of one vehicle, ascending [s].
    s : array_like
        Its position along the road [m] (small backward steps are ignored: the running
        maximum is used).
    s_cross : array_like
        Positions to reach [m].

    Returns
    -------
    ndarray
        Time [s] at which ``s`` first reaches each ``s_cross``, linearly interpolated
        between the samples around it; NaN when ``s_cross`` lies outside the recorded
        range ``[s[0], max s]``.

    Examples
    --------
    >>> crossing_times([0.0, 1.0, 2.0], [0.0, 10.0, 20.0], [5.0, 20.0, 30.0]).tolist()
    [0.5, 2.0, nan]
    """
    t, s = np.asarray(t, float), np.asarray(s, float)
    q = np.atleast_1d(np.asarray(s_cross, float))
    ok = np.isfinite(t) & np.isfinite(s)
    t, s = t[ok], s[ok]
    out = np.full(q.shape, np.nan)
    if t.size == 0:
        return out
    sm = np.maximum.accumulate(s)
    k = np.searchsorted(sm, q, side="left")
    inside = (q >= s[0]) & (q <= sm[-1])
    k = np.clip(k, 1, max(sm.size - 1, 1))
    if sm.size == 1:
        return np.where(inside, t[0], np.nan)
    s0, s1, t0, t1 = sm[k - 1], sm[k], t[k - 1], t[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(s1 > s0, (q - s0) / (s1 - s0), 1.0)
    tt = t0 + np.clip(frac, 0.0, 1.0) * (t1 - t0)
    tt = np.where(q == s[0], t[0], tt)
    return np.where(inside, tt, np.nan)


def section_travel_times(bg: pd.DataFrame, s_a: float, s_b: float) -> pd.DataFrame:
    """Travel time of each vehicle over the road section ``[s_a, s_b]``.

    Parameters
    ----------
    bg : DataFrame
        Rows ``t`` [s], ``vehicle_id``, ``s`` [m] (``background.parquet``).
    s_a : float
        Section start along the road [m].
    s_b : float
        Section end [m], ``> s_a``.

    Returns
    -------
    DataFrame
        Index ``vehicle_id``; columns ``t_in``, ``t_out`` [s] (:func:`crossing_times` of
        ``s_a`` and ``s_b``, NaN when not recorded), ``travel_time_s``, ``s_first``,
        ``s_last`` [m] (the recorded range).
    """
    if not s_b > s_a:
        raise ValueError(f"s_b ({s_b!r}) must be greater than s_a ({s_a!r}) [m]")
    rows = {}
    df = bg[["t", "vehicle_id", "s"]].dropna().sort_values(["vehicle_id", "t"], kind="stable")
    for vid, g in df.groupby("vehicle_id", sort=True):
        t, s = g["t"].to_numpy(float), g["s"].to_numpy(float)
        t_in, t_out = crossing_times(t, s, [s_a, s_b])
        rows[str(vid)] = (t_in, t_out, t_out - t_in, s[0], float(np.max(s)))
    out = pd.DataFrame.from_dict(rows, orient="index",
                                 columns=["t_in", "t_out", "travel_time_s", "s_first",
                                          "s_last"])
    out.index.name = "vehicle_id"
    return out


def baseline_comparison(bg_run: pd.DataFrame, bg_base: pd.DataFrame, s_a: float, s_b: float,
                        min_length: float = 50.0) -> pd.DataFrame:
    """Per-vehicle travel times over a common section, formation run vs baseline twin.

    For each vehicle id present in both tables the section ``[s_a, s_b]`` is clipped to
    the part recorded in both runs, ``[max(s_a, s_first), min(s_b, s_last)]`` (the
    formation run records only vehicles near the formation); a vehicle recorded over
    the whole section in both is timed over the whole of it.

    Parameters
    ----------
    bg_run : DataFrame
        Background rows of the formation run (``t``, ``vehicle_id``, ``s``).
    bg_base : DataFrame
        Background rows of the baseline twin (same traffic and seed, no formation).
    s_a : float
        Section start [m].
    s_b : float
        Section end [m].
    min_length : float
        Vehicles whose common part is shorter are left out [m].

    Returns
    -------
    DataFrame
        Index ``vehicle_id``; columns ``s_from``, ``s_to``, ``length_m`` [m],
        ``full_section`` (bool), ``tt_run_s``, ``tt_base_s``, ``delta_s`` (run minus
        baseline) [s], ``v_run_mps``, ``v_base_mps`` (``length_m`` over the travel time)
        [m/s]. Sorted by ``delta_s``, largest first.
    """
    if not s_b > s_a:
        raise ValueError(f"s_b ({s_b!r}) must be greater than s_a ({s_a!r}) [m]")
    cols = ["s_from", "s_to", "length_m", "full_section", "tt_run_s", "tt_base_s", "delta_s",
            "v_run_mps", "v_base_mps"]
    runs = {}
    for name, bg in (("run", bg_run), ("base", bg_base)):
        df = bg[["t", "vehicle_id", "s"]].dropna()
        df = df.assign(vehicle_id=df["vehicle_id"].astype(str)).sort_values(
            ["vehicle_id", "t"], kind="stable")
        runs[name] = {k: (g["t"].to_numpy(float), g["s"].to_numpy(float))
                      for k, g in df.groupby("vehicle_id", sort=False)}
    rows = {}
    for vid in sorted(set(runs["run"]) & set(runs["base"])):
        (tr, sr), (tb, sb_) = runs["run"][vid], runs["base"][vid]
        lo = max(s_a, sr[0], sb_[0])
        hi = min(s_b, float(np.max(sr)), float(np.max(sb_)))
        if not hi - lo >= min_length:
            continue
        a_r, b_r = crossing_times(tr, sr, [lo, hi])
        a_b, b_b = crossing_times(tb, sb_, [lo, hi])
        tt_r, tt_b = b_r - a_r, b_b - a_b
        length = hi - lo
        with np.errstate(divide="ignore", invalid="ignore"):
            rows[vid] = (lo, hi, length, bool(lo == s_a and hi == s_b), tt_r, tt_b,
                         tt_r - tt_b, length / tt_r if tt_r > 0 else np.nan,
                         length / tt_b if tt_b > 0 else np.nan)
    out = pd.DataFrame.from_dict(rows, orient="index", columns=cols)
    out.index.name = "vehicle_id"
    out["full_section"] = out["full_section"].astype(bool)
    return out.sort_values("delta_s", ascending=False, kind="stable")
