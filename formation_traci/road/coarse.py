"""How coarse a lane polyline is, and what the reference line's fit makes of it
(road/smoothing.py ``fit_within`` with a lane band): the smoothing length from the spacing of
the polyline's corners, and the band a member's centre may use in its lane.

A road of curvature kappa drawn with chords of length l (shape points on the road, SUMO
driving straight between them) lies ``kappa l^2 / 8`` off each chord's midpoint: 3.0 m for
R = 1,200 m and l = 170 m. A line of that curvature stays within half of it of the polyline
(an arc concentric with the road, the vertices that far outside it, the chord midpoints that
far inside); a line held closer must bend at the shape points, a wave of the spacing's
wavelength. On a coarse polyline (:func:`is_coarse`) the fit's smoothing length is
:data:`SPACING_FACTOR` times its corners' spacing, so the corners' wave is smoothed away, and
the band of each segment is widened to what its chord needs (:func:`band_widths`), at most to
the lane's (:func:`lane_tolerance`), so the road's curve fits in it. SUMO's own curves
(sampled every few metres) and straights keep the 160 m fit.

Everything here runs in plain Python floats (the same bits on every processor).
"""
from __future__ import annotations

import math

import numpy as np

SMOOTHING = 160.0
"""Smallest smoothing length of the fit [m] (wavelength of half response)."""
SPACING_FACTOR = 6.0
"""The smoothing length is at least this many times the spacing of the polyline's corners
(:func:`smoothing_length`): their wave (wavelength = spacing) passes at 6^-10 ~ 2e-8 [-]."""
SPACING_QUANTILE = 0.9
"""Quantile of the corners' spacings that sets the smoothing length [-]."""
CORNER_MIN_DEG = 0.2
"""A vertex turning less than this is no corner (a straight split by a node) [deg]."""
SMOOTHING_MAX = 800.0
"""Largest smoothing length [m] (a road curve of R = 1 km, wavelength 6.3 km, still passes
unbiased)."""
KNOTS_PER_SMOOTHING = 40.0
"""Knots per smoothing length (at least the default fit's 4 m spacing): the penalty weight,
``(L / 2 pi h)^10``, and with it the system's condition, stay those of the 160 m fit on 4 m
knots."""
WIDEN = 1.1
"""A segment's band is at least this times what its chord needs (:func:`chord_offsets`) [-]: the
concentric arc, and a tenth more for the line to vary."""
LANE_MARGIN = 0.2
"""The band is widened to half the narrowest lane's width less this at most [m]
(:func:`lane_tolerance`): a member's centre on the line, plus its tracking error on the curve
(~0.15 m), stays inside its SUMO lane."""
SETTINGS = (SMOOTHING, SPACING_FACTOR, SPACING_QUANTILE, CORNER_MIN_DEG, SMOOTHING_MAX,
            KNOTS_PER_SMOOTHING, WIDEN, LANE_MARGIN)
"""This module's settings (part of the road cache's key, through road/smoothing.py)."""


def lane_tolerance(width: float) -> float:
    """The widest band for lanes ``width`` wide [m]: half of it less :data:`LANE_MARGIN`."""
    return 0.5 * width - LANE_MARGIN


def turning(p: list) -> list[float]:
    """Signed turning angle at every vertex of the polyline ``p`` (list of (x, y)), left
    positive, 0 at both ends [rad]."""
    out = [0.0]
    for a, b, c in zip(p, p[1:], p[2:]):
        d = math.atan2(c[1] - b[1], c[0] - b[0]) - math.atan2(b[1] - a[1], b[0] - a[0])
        out.append(math.remainder(d, 2.0 * math.pi))
    return out + [0.0]


def smoothing_length(p: list) -> float:
    """The smoothing length [m] of the cleaned polyline ``p`` (list of (x, y)): :data:`SPACING_FACTOR`
    times the :data:`SPACING_QUANTILE` quantile of its corners' spacings (a corner: a vertex
    turning more than :data:`CORNER_MIN_DEG`; its spacing: the shorter of its two segments),
    within [:data:`SMOOTHING`, :data:`SMOOTHING_MAX`]. Curves sampled every few metres (SUMO's
    own) and straights give :data:`SMOOTHING`."""
    turn = math.radians(CORNER_MIN_DEG)
    delta = turning(p)
    spacing = sorted(min(math.dist(p[k - 1], p[k]), math.dist(p[k], p[k + 1]))
                     for k in range(1, len(p) - 1) if abs(delta[k]) > turn)
    if not spacing:
        return SMOOTHING
    q = spacing[int(SPACING_QUANTILE * (len(spacing) - 1))]
    return min(max(SMOOTHING, SPACING_FACTOR * q), SMOOTHING_MAX)


def chord_offsets(p: list) -> list[float]:
    """How far [m] a line of the road's own curvature keeps from each chord of the cleaned
    polyline ``p`` (list of (x, y)) at best: half the road's offset from it,
    ``l |delta_a + delta_b| / 32`` (module docstring)."""
    delta = turning(p)
    return [math.dist(p[k], p[k + 1]) * abs(delta[k] + delta[k + 1]) / 32.0 for k in range(len(p) - 1)]


def is_coarse(p: list, tolerance: float, lane_band: float) -> bool:
    """Whether the cleaned polyline ``p`` (list of (x, y)) is fitted as a coarse one: its
    corners' spacing asks for more than the 160 m fit (:func:`smoothing_length`), its chords
    ask for more than ``tolerance`` [m] (the :data:`SPACING_QUANTILE` quantile of
    :func:`chord_offsets`: most of the road is drawn coarsely, not one long segment of it), and
    none asks for more than ``lane_band`` [m] (a narrower lane than the chords need keeps the
    line to them)."""
    need = sorted(chord_offsets(p))
    return (smoothing_length(p) > SMOOTHING and need[int(SPACING_QUANTILE * (len(need) - 1))] > tolerance
            and need[-1] <= lane_band)


def band_widths(p: list, seg: np.ndarray, f: np.ndarray, tolerance: float, lane_band: float) -> np.ndarray:
    """The band [m] at each point checked (road/smoothing.py ``band_points``: on segment ``seg``
    of the cleaned polyline ``p``, at fraction ``f`` along it): ``tolerance``, widened on a
    segment to :data:`WIDEN` times what its chord needs (:func:`chord_offsets`), at most to
    ``lane_band``; a vertex takes the wider of its two segments'."""
    delta = turning(p)
    width = [min(lane_band, max(tolerance, WIDEN * math.dist(p[k], p[k + 1]) * abs(delta[k] + delta[k + 1]) / 32.0))
             for k in range(len(p) - 1)]
    return np.array([max(width[k], width[k - 1]) if x == 0.0 and k > 0 else width[k]
                     for k, x in zip(seg.tolist(), f.tolist())])
