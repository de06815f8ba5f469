"""Reference line of a lane polyline: the road's curvature within a lateral tolerance.

SUMO's lanes on networks built from OpenStreetMap are coarse polylines: the LuST motorway
has a corner every ~58 m, mostly 1-3 deg, up to 7.4 deg. The 40 m smoothing of
:data:`~.geometry.LINE_FIT_DEFAULT` (made for shapes sampled every 4 m) keeps each corner as
a short bend of ~150 m radius, and members feel the polyline (a_lat swinging by 1-2 m/s^2
every corner at 30 m/s) on a road of ~1.6 km radius.

:func:`fit_within` fits the P-spline of :class:`~.geometry.ReferenceLine` with the smoothing
length :data:`SMOOTHING` (160 m: corners 58 m apart pass at 4e-5 of their amplitude, a road
curve of radius R, wavelength 2 pi R, unbiased) and holds it within ``tolerance`` [m] of the
lane centre at the polyline's vertices and at points at most :data:`BAND_SPACING` apart on
its segments (:func:`band_points`), measured along the curve's normal. Where the free fit
leaves that band, the penalised least-squares problem is solved under the constraints
``|d_j| <= BAND_MARGIN * tolerance`` (the P-spline with inequality constraints; road/band_qp.py
solves the quadratic programme exactly, with the constraints linearised at the line and
re-linearised until every point is within the tolerance). The result is the fit of least
penalty (the least curvature variation at the 160 m scale) that keeps to the lane: only the
corners that do not fit bend sharper, and they bend no more than the band forces.

An isolated corner of angle delta on a straight (small angles, from the P-spline's transfer
function ``H = 1 / (1 + (L / wavelength)^10)``, L = :data:`SMOOTHING`): the free fit's peak
curvature is ``delta h(0) = 2.033 delta / L`` (``h(0) = (2 / L) (pi/10) / sin(pi/10)``) and it
passes ``0.0515 delta L`` from the vertex (``(L / 2 pi^2) (pi/10) / sin(pi/10)``): 0.144 m per
degree at 160 m, so corners up to 4.2 deg fit a 0.6 m band free; sharper ones are held in it,
with a peak curvature of 2.28 delta / L at 6 deg and 2.57 delta / L at 8 deg
(tests/test_line_band.py).

A line whose free fit stays in the band (every bundled network: curves sampled every 4 m) is
that fit, unchanged.

Given ``lane_band`` (the default ``road.fit_tolerance``), a polyline drawn with shape points far
apart (road/coarse.py ``is_coarse``: a 1,200 m arc with a point every 170 m, its chords 3.0 m
inside it) gets a smoothing length of 6 times its corners' spacing and, segment by segment, the
band its chords need, up to ``lane_band``: the road's curvature, not its corners
(docs/sumo.md, "Roads drawn with shape points far apart"). Measured on LuST (tests/test_realnet.py, docs/sumo.md "Real networks").
"""
from __future__ import annotations

import math

import numpy as np

from .geometry import LINE_FIT_DEFAULT, LineFit, ReferenceLine, clean_polyline
from .band_qp import box_forces
from .coarse import (KNOTS_PER_SMOOTHING, SETTINGS as COARSE_SETTINGS, SMOOTHING, band_widths,  # noqa: F401
                     is_coarse, lane_tolerance, smoothing_length)
from .line_fit import _DEGREE, chord_lengths, pspline_system, solve_banded_spd, solve_pspline

FIT_TOLERANCE_DEFAULT = 0.6
"""Largest lateral distance of the reference line from SUMO's lane centre [m] (road.fit_tolerance's
default on a finely drawn road; on a coarse one the default is the lane's band, road/coarse.py)."""
BAND_SPACING = 5.0
"""Largest spacing of the points the tolerance is checked at along a polyline segment [m]."""
BAND_MARGIN = 0.98
"""The constraints hold the line within this fraction of the tolerance [-] (the rest absorbs
their linearisation)."""
RIDGE = 1e-9
"""Added to the diagonal of the constraints' matrix, relative to its largest entry [-]: a
constraint yields by ``RIDGE * max(M_jj) * lam_j`` (nanometres), and bound points too close
together for the fit to tell apart stay solvable."""
BAND_ROUNDS = 8
"""Most linearisations of the band constraints."""
COARSE_STEPS = 1000
"""Most bounds of the band's quadratic programme on a coarse polyline (more: the lane's band is
narrower than its chords need, and the 160 m fit within the tolerance is used) [-]."""
COARSE_SLACK = 0.05
"""A coarse polyline's long fit is used if within the lane's band plus this [m]."""
FIT_SETTINGS = repr((LINE_FIT_DEFAULT, COARSE_SETTINGS, BAND_SPACING, BAND_MARGIN, RIDGE, BAND_ROUNDS,
                     COARSE_STEPS, COARSE_SLACK))
"""The settings of :func:`fit_within` beyond the tolerance (part of the road cache's key)."""
_NEWTON_STEPS = 6
"""Newton steps of the projection of the band's points onto c(u), from their chord length."""


def band_points(xy, min_segment: float = LINE_FIT_DEFAULT.min_segment, parts: bool = False):
    """The points the tolerance is checked at: the polyline's vertices and, on each segment,
    the points that cut it into ``2 ceil(length / (2 BAND_SPACING))`` equal pieces (its
    midpoint among them), (m, 2) [m] in driving order, and their chord length along the
    polyline (m,) [m]; with ``parts``, also each point's segment (m,) and fraction along it."""
    p = clean_polyline(xy, min_segment, 1e9)
    u = chord_lengths(p)
    seg = np.diff(u)
    pieces = 2 * np.maximum(1, np.ceil(seg / (2.0 * BAND_SPACING))).astype(int)
    f = np.concatenate([np.arange(k) / k for k in pieces.tolist()] + [[0.0]])  # fraction along
    i = np.concatenate([np.full(k, j) for j, k in enumerate(pieces.tolist())] + [[len(seg) - 1]])
    f[-1] = 1.0
    a, b = p[i], p[i + 1]
    pts = a + f[:, None] * (b - a)
    return (pts, u[i] + f * seg[i], i, f) if parts else (pts, u[i] + f * seg[i])


def deviation(line: ReferenceLine, xy) -> float:
    """Largest distance [m] of the polyline's points (:func:`band_points`) from the line."""
    pts, _ = band_points(xy)
    s, d = line.to_frenet(pts)
    inside = (s >= 0.0) & (s <= line.length)
    return float(np.max(np.abs(d[inside]), initial=0.0))


def _offsets(curve, q: np.ndarray, u0: np.ndarray):
    """Nearest points of c(u) to q (m, 2) from the guesses u0 (m,) by Newton's method on
    (q - c(u)) . c'(u) = 0: their u [m], c(u) (m, 2) [m], unit left normal (m, 2) and the
    offset d = n . (q - c) of q [m] (left positive); elementwise numpy only (no reduction)."""
    lo, hi = float(curve.t[_DEGREE]), float(curve.t[-_DEGREE - 1])
    u = np.clip(u0, lo, hi)
    d1, d2 = curve.derivative(1), curve.derivative(2)
    for _ in range(_NEWTON_STEPS):
        r, c1, c2 = q - curve(u), d1(u), d2(u)
        f = r[:, 0] * c1[:, 0] + r[:, 1] * c1[:, 1]
        fp = r[:, 0] * c2[:, 0] + r[:, 1] * c2[:, 1] - (c1[:, 0] ** 2 + c1[:, 1] ** 2)
        u = np.clip(u - f / fp, lo, hi)
    return (u, *_normal_offset(curve, d1, q, u))


def _normal_offset(curve, d1, q: np.ndarray, u: np.ndarray):
    """c(u), the unit left normal at u and the offset n . (q - c(u)) [m] of q."""
    c, c1 = curve(u), d1(u)
    g = np.sqrt(c1[:, 0] ** 2 + c1[:, 1] ** 2)
    n = np.stack([-c1[:, 1] / g, c1[:, 0] / g], axis=1)
    return c, n, n[:, 0] * (q[:, 0] - c[:, 0]) + n[:, 1] * (q[:, 1] - c[:, 1])


def _band_solve(knots, lhs, rhs, c0, q, lin: dict, edge: np.ndarray, ridge: bool, max_steps: int):
    """The fit of the system (knots, lhs, rhs) closest to the free fit ``c0`` (n_coef, 2)
    with ``|n_j . (c(u_j) - q_j)| <= edge_j`` at the points lin = {j: (u_j, n_j)} (band_qp.py;
    ``ridge``: :data:`RIDGE` added, for smoothing lengths above 160 m);
    returns the spline and the forces {j: lam_j}."""
    from scipy.interpolate import BSpline

    keys = sorted(lin)
    u = np.array([lin[j][0] for j in keys])
    nrm = np.array([lin[j][1] for j in keys])
    rows = BSpline.design_matrix(u, knots, _DEGREE)  # B_j, one row per point
    bands = [lhs.diagonal(-k) for k in range(_DEGREE + 1)]
    z = solve_banded_spd(bands, rows.T.toarray())  # H^-1 B_j^T per column
    gram = np.asarray(rows @ z)  # B_j H^-1 B_k^T (scipy.sparse's own loops)
    cos = nrm[:, None, 0] * nrm[None, :, 0] + nrm[:, None, 1] * nrm[None, :, 1]
    at = np.asarray(rows @ c0)
    w0 = nrm[:, 0] * (at[:, 0] - q[keys, 0]) + nrm[:, 1] * (at[:, 1] - q[keys, 1])
    m = len(keys)
    M = (gram * cos).tolist()
    ridge = RIDGE * max(M[k][k] for k in range(m)) if ridge else 0.0
    for k in range(m):  # points a few metres apart on a long smoothing length: near-dependent
        M[k][k] += ridge
    hi = [float(edge[j]) for j in keys]
    lam = box_forces(M, w0.tolist(), [-x for x in hi], hi, max_steps)
    force = np.zeros((m, 2))
    for k, v in lam.items():
        force[k] = v * nrm[k]
    curve = solve_pspline(knots, lhs, rhs + np.asarray(rows.T @ force))
    return curve, {keys[k]: v for k, v in lam.items()}


def fit_within(xy, tolerance: float = FIT_TOLERANCE_DEFAULT, base: LineFit = LINE_FIT_DEFAULT,
               lane_band: float | None = None) -> tuple[ReferenceLine, float, float]:
    """The P-spline of the polyline ``xy`` (n, 2) [m], held within a band of it (module
    docstring).

    Parameters
    ----------
    tolerance : float
        The band [m]: the 160 m fit held within it everywhere.
    lane_band : float or None
        If given [m], a coarse polyline (road/coarse.py ``smoothing_length`` above 160 m) gets
        that smoothing length and ``max(tolerance, lane_band)`` as its band instead; a finely
        drawn one is fitted as without it.

    Returns
    -------
    line, smoothing_length, deviation
        The fitted line, the smoothing length used [m] and its largest distance from the
        polyline's points of :func:`band_points` [m] (above the band only if
        :data:`BAND_ROUNDS` linearisations did not bring every point within it).
    """
    if lane_band is not None:
        corners = clean_polyline(xy, base.min_segment, 1e9).tolist()
        if is_coarse(corners, BAND_MARGIN * tolerance, BAND_MARGIN * max(tolerance, lane_band)):
            length = smoothing_length(corners)
            _, _, seg, frac = band_points(xy, base.min_segment, parts=True)
            band = band_widths(corners, seg, frac, tolerance, max(tolerance, lane_band))
            try:
                got = _fit_band(xy, band, base, length, COARSE_STEPS)
            except ValueError:  # the band cannot hold a smooth line: the chords' own fit
                got = None
            if got is not None and got[2] <= float(band.max()) + COARSE_SLACK:
                return got
    return _fit_band(xy, tolerance, base, SMOOTHING, 2000)


def _fit_band(xy, tolerance, base: LineFit, length: float, max_steps: int):
    """:func:`fit_within` at the smoothing ``length`` [m] within ``tolerance`` [m] (a float, or
    one per point of :func:`band_points`); the band's quadratic programme gives up after
    ``max_steps`` bounds (ValueError)."""
    fit = LineFit(length, max(base.knot_spacing, length / KNOTS_PER_SMOOTHING), base.max_segment,
                  base.min_segment)
    pts = clean_polyline(xy, fit.min_segment, fit.max_segment)
    knots, lhs, rhs = pspline_system(chord_lengths(pts), pts, fit)
    q, u_chord = band_points(xy, fit.min_segment)
    free = curve = solve_pspline(knots, lhs, rhs)
    lin: dict = {}
    for _ in range(BAND_ROUNDS):
        u_q, _, n, d = _offsets(curve, q, u_chord)
        interior = (u_q > knots[_DEGREE]) & (u_q < knots[-_DEGREE - 1])
        out = np.flatnonzero(interior & (np.abs(d) > tolerance)).tolist()
        if not out:
            break
        for j in set(lin) | set(out):  # the constraints linearised at the line they bind
            lin[j] = (float(u_q[j]), n[j].copy())
        curve, _ = _band_solve(knots, lhs, rhs, np.asarray(free.c), q, lin,
                               BAND_MARGIN * np.broadcast_to(tolerance, len(q)), length > SMOOTHING, max_steps)
    line = ReferenceLine.from_curve(pts, curve)
    return line, length, deviation(line, xy)
