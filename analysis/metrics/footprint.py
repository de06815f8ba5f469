"""Vehicle outlines: a member's body from run.json, body centre and corner points.

Every vehicle is an oriented rectangle: centre ``(x, y)`` [m], heading ``h`` [rad,
counter-clockwise from +x], length ``l`` and width ``w`` [m]. Members' rows give the centre
of gravity, which :func:`body_centre` moves to the body centre. Part of the traffic
interaction measures (:mod:`analysis.metrics.traffic`).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

__all__ = ["Footprint", "MEMBER_FOOTPRINTS", "member_footprint", "member_footprints", "body_centre",
           "rectangle_corners"]


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

def _num(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) and v > 0 else None


def _recorded_body(body: Any) -> Footprint | None:
    """A member's ``body`` as run.json recorded it, or None when it is missing or damaged."""
    if not isinstance(body, Mapping):
        return None
    values = {k: _num(body.get(k)) for k in ("length", "width", "a")}
    overhang = body.get("front_overhang")
    if None in values.values() or not isinstance(overhang, (int, float)) or overhang < 0:
        return None
    return Footprint(front_overhang=float(overhang), **values)


def member_footprints(scenario: Mapping[str, Any] | None,
                      members: Any = None) -> dict[str, Footprint]:
    """Each member's own body outline, by member id: the ``body`` run.json recorded for that
    member (a mixed formation's truck is a truck), else the formation's outline from
    :func:`member_footprint`.

    Parameters
    ----------
    scenario : mapping or None
        The validated scenario (``run.json`` ``scenario``), for members without a body.
    members : list of mappings or None
        ``run.json`` ``members`` (``id`` and ``body``: length, width, a, front_overhang [m]).

    Returns
    -------
    dict of str to Footprint
        One outline per member id (empty when run.json lists no members).
    """
    default = member_footprint(scenario, members)[0]
    out: dict[str, Footprint] = {}
    for m in members or []:
        if isinstance(m, Mapping) and m.get("id") is not None:
            out[str(m["id"])] = _recorded_body(m.get("body")) or default
    return out


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
    first = _recorded_body(bodies[0]) if bodies else None
    if first is not None:
        return first, "run.json members body"
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


