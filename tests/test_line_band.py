"""The reference line's fit within road.fit_tolerance (road/smoothing.py, road/band_qp.py;
issue 32 item 5): a corner of a few degrees gives the P-spline's own, gentle bend, predicted
from its transfer function, and a sharper corner is held within the tolerance of the polyline
everywhere, with a curvature that stays of order (corner angle / smoothing length)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from formation_traci.road.band_qp import box_forces
from formation_traci.road.geometry import ReferenceLine, clean_polyline
from formation_traci.road.line_fit import LINE_FIT_DEFAULT
from formation_traci.road.smoothing import SMOOTHING, band_points, deviation, fit_within

L = SMOOTHING
H0 = 2.0 * (math.pi / 10) / math.sin(math.pi / 10)
"""Peak of the P-spline's impulse response times L: (1/pi) int_0^inf H dw with
H = 1 / (1 + (w L / 2 pi)^10), int_0^inf dx / (1 + x^10) = (pi/10) / sin(pi/10)."""
DEV = (1.0 / (2.0 * math.pi ** 2)) * (math.pi / 10) / math.sin(math.pi / 10)
"""Distance of the free fit from a corner's vertex per (angle x L): int_0^inf t h(t) dt =
(1/pi) int_0^inf (1 - H) / w^2 dw = L / (2 pi^2) int_0^inf x^8 / (1 + x^10) dx."""


def corner(deg: float, spacing: float = 50.0, leg: float = 1500.0) -> np.ndarray:
    """A straight with one corner of ``deg`` degrees (left) at the origin, vertices every
    ``spacing`` m (an OSM-like polyline)."""
    x = np.arange(-leg, leg + spacing, spacing)
    a = math.radians(deg)
    return np.stack([np.where(x < 0, x, x * math.cos(a)), np.where(x < 0, 0.0, x * math.sin(a))], axis=1)


def dense_deviation(line: ReferenceLine, xy) -> float:
    """Largest distance of the polyline, sampled every 0.25 m, from the line [m]."""
    s, d = line.to_frenet(clean_polyline(xy, 1e-3, 0.25))
    return float(np.abs(d[(s >= 0) & (s <= line.length)]).max())


def peak_curvature(line: ReferenceLine) -> float:
    return float(np.abs(line.curvature(np.linspace(0.0, line.length, 60001))).max())


@pytest.mark.parametrize("deg", [1.0, 3.0])
def test_a_corner_that_fits_gets_the_pspline_bend(deg):
    """1 and 3 deg corners lie within 0.6 m of the free 160 m fit (0.144 m per degree): the
    line is that fit, its peak curvature 2.033 delta / L and its distance from the vertex
    0.0515 delta L, both within 1 % (the continuous transfer function against the discrete
    spline on 4 m knots)."""
    xy = corner(deg)
    line, length, dev = fit_within(xy, 0.6)
    a = math.radians(deg)
    free = ReferenceLine.from_points(xy, replace(LINE_FIT_DEFAULT, smoothing_length=SMOOTHING))
    assert np.array_equal(line.coef, free.coef)  # nothing held: the free fit, bit for bit
    assert length == L
    assert peak_curvature(line) == pytest.approx(H0 * a / L, rel=0.01)
    assert dev == pytest.approx(DEV * a * L, rel=0.01)


@pytest.mark.parametrize("deg,spacing", [(6.0, 50.0), (8.0, 50.0), (8.0, 10.0)])
def test_a_sharper_corner_is_held_within_the_tolerance_everywhere(deg, spacing):
    """6 and 8 deg (free fit 0.86 and 1.15 m off): the line is within 0.6 m of the polyline
    at every 0.25 m of it (not only at the vertices), and its peak curvature is at most
    2.7 delta / L (measured 2.28 and 2.57: 12 and 26 % above the free bend), far below the
    4 m-knot spline's 40 m fit of the polyline (about 2 delta / 40 m)."""
    xy = corner(deg, spacing)
    line, _, dev = fit_within(xy, 0.6)
    a = math.radians(deg)
    assert DEV * a * L > 0.6  # the free fit would leave the band
    assert dev <= 0.6 and deviation(line, xy) == dev
    assert dense_deviation(line, xy) <= 0.6
    assert H0 * a / L < peak_curvature(line) <= 2.7 * a / L


def test_band_points_cut_segments_into_an_even_number_of_pieces():
    pts, u = band_points(np.array([[0.0, 0.0], [4.0, 0.0], [16.0, 0.0]]))
    np.testing.assert_array_equal(pts[:, 0], [0.0, 2.0, 4.0, 7.0, 10.0, 13.0, 16.0])
    np.testing.assert_array_equal(u, pts[:, 0])


def test_box_forces_against_the_closed_form_of_two_coupled_values():
    """Box [-1, 1], M = [[2, 1], [1, 2]] for two values and an uncoupled third inside the
    box. w0 = (3, 0): binding value 0 at 1 takes lam0 = (1 - 3) / 2 = -1 and moves value 1 to
    0 + 1 * lam0 = -1, on its bound without force; w0 = (3, 0.5): value 1 ends inside at -0.5;
    w0 = (3, -1.5): value 1 would end at -2.5, so both bind and M lam = (1 - 3, -1 + 1.5)
    gives lam = (-1.5, 1), each pushing into the box. The third value never gets a force."""
    M = [[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]]
    for w0 in ([3.0, 0.0, 0.5], [3.0, 0.5, 0.0]):  # value 1 ends at -1 and at -0.5
        lam = box_forces(M, w0, [-1.0] * 3, [1.0] * 3)
        assert list(lam) == [0] and lam[0] == pytest.approx(-1.0, abs=1e-15)
    lam = box_forces(M, [3.0, -1.5, 0.0], [-1.0] * 3, [1.0] * 3)  # both bound: solve 2x2
    # [[2, 1], [1, 2]] lam = (1 - 3, -1 + 1.5) = (-2, 0.5): lam = (-1.5, 1.0)
    assert lam[0] == pytest.approx(-1.5, abs=1e-15) and lam[1] == pytest.approx(1.0, abs=1e-15)
