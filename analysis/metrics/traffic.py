"""Traffic interaction: surrogate safety measures, gaps, headways, delays.

Pure functions over arrays and DataFrames; the per-run glue (which rows, which vehicles,
issues) is :mod:`analysis.runs.traffic_run`. Definitions, units and sources are in
``docs/metrics.md`` (section "Traffic interaction").

Geometry. Every vehicle is an oriented rectangle: centre ``(x, y)`` [m], heading ``h``
[rad, counter-clockwise from +x], length ``l`` and width ``w`` [m]. Background rows give
the body centre; members' rows give the centre of gravity, which :func:`body_centre`
moves to the body centre. Road coordinates ``s`` (along the reference line) and ``d``
(left of it) are those of ``background.parquet`` / ``trajectories.parquet``.

This module holds the road-frame gaps and headways and the thresholds shared by the
per-run glue; it re-exports the rest of the traffic measures, which live by topic in
:mod:`analysis.metrics.footprint` (outlines), :mod:`analysis.metrics.pair_geometry`
(clearance, 2-D TTC), :mod:`analysis.metrics.ssm` (SUMO SSM output, events) and
:mod:`analysis.metrics.travel_time` (delays).
"""
from __future__ import annotations

import numpy as np

from analysis.metrics.footprint import (MEMBER_FOOTPRINTS, Footprint, body_centre, member_footprint,
                                        member_footprints, rectangle_corners)
from analysis.metrics.pair_geometry import (TTC2D_HORIZON_S, TTC2D_THRESHOLD_S, clearance,
                                            Moving, pair_measures, same_time_pairs, ttc_2d)
from analysis.metrics.ssm import (SSM_DRAC_HIGH_MPS2, SSM_GROUP_COLUMNS, SSM_TTC_CRITICAL_S,
                                  SSM_TTC_WARNING_S, event_counts, merge_ssm_duplicates,
                                  ssm_summary)
from analysis.metrics.travel_time import (baseline_comparison, crossing_times, section_travel_times,
                                          time_loss)

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
    "member_footprints",
    "body_centre",
    "rectangle_corners",
    "same_time_pairs",
    "clearance",
    "Moving",
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


CLEARANCE_THRESHOLD_M = 1.0
"""Outline-to-outline clearance below which a member is "close" to another vehicle [m]
(ours: about one door opening; reported as time spent below it)."""

LATERAL_GAP_THRESHOLD_M = 0.5
"""Lateral gap to a side-by-side vehicle below which the pass is "tight" [m] (ours:
SUMO's default ``minGapLat`` is 0.6 m for cars)."""

HEADWAY_THRESHOLD_S = 1.0
"""Time headway below which following is "short" [s] (ours: half the common 2 s rule;
the formation's own ``leader.time_gap`` defaults to 1.5 s)."""

INTERACTION_RANGE_M = 100.0
"""Pairs of vehicles whose centres are farther apart are not evaluated [m]; also the
"near the formation" window ahead of the front member and behind the last one."""

V_STANDSTILL_MPS = 0.1
"""Below this speed a time headway is undefined (NaN) [m/s]."""


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
