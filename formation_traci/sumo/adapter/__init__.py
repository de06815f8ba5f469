"""The only module that talks to SUMO (libsumo in-process, or traci over a socket).

It owns starting/stepping/closing SUMO, inserting and placing the formation members with
``vehicle.moveToXY``, batched reads through subscriptions. The frame conversions (SUMO's
front bumper and degrees clockwise from north against our CoG and radians counter-clockwise
from +x), the constants and the result dataclasses are in sumo/types.py; the neighbour
reads in sumo/adapter/neighbours.py and the socket connection in sumo/adapter/connect.py work on the
module object this adapter imports (``self.api``) and import no SUMO themselves. Outside
these modules code sees only numpy arrays and the small dataclasses. Friction, member types and
the release of a member are in sumo/adapter/vehicles.py (the same way). SUMO behaviours relied
on here are documented in docs/sumo.md (each with the test that shows it).
"""
from __future__ import annotations

from operator import itemgetter

import numpy as np

from .connect import attach_socket, follow_view, start_socket
from .lane_ends import LaneEnds
from .ramp_reads import RampReads
from .member_reads import MemberReads
from .neighbours import NeighbourReads
from ..traffic import BASE_TYPES
from .vehicles import VehicleSetup
from ..types import (GUI_VIEW, GUI_ZOOM, KEEP_ROUTE, LANE_CHANGE_MODE_DEFAULT,  # noqa: F401
                         MATCH_THRESHOLD, ORDINARY_CLASS, REMOVED_REASONS, ROUTE_AHEAD_M,
                         SPEED_MODE_DEFAULT,
                         START_TIMEOUT_S, MemberType, Neighbours, StepEvents, SumoError,
                         cog_to_sumo, sumo_binary, sumo_to_cog)



_QUIET = StepEvents((), (), ())
"""What a step without collisions, teleports or arrivals reports (shared, read-only tuples)."""


def _api(backend: str):
    if backend == "libsumo":
        import libsumo as api
    elif backend == "traci":
        import traci as api
    else:  # pragma: no cover - validated by the schema
        raise ValueError(backend)
    from libsumo import constants as tc  # the same module as traci.constants
    return api, tc


class SumoAdapter(MemberReads, NeighbourReads, VehicleSetup, LaneEnds, RampReads):
    """One SUMO simulation. Call :meth:`start`, then per step :meth:`read_members` ->
    :meth:`place` -> :meth:`step` -> :meth:`set_true_speeds`, and :meth:`close` at the end
    (also after errors)."""

    def __init__(self, backend: str = "libsumo", gui: bool = False):
        self.api, self.tc = _api(backend)
        self.backend = backend
        self.gui = gui
        self.version = ""
        self.members: dict[str, MemberType] = {}
        self._member_lane: dict[str, str] = {}  # member -> its lane at the last change of lanes
        self._context: dict[str, float] = {}  # vehicle -> radius of its context subscription
        self._subscribed: set[str] = set()  # vehicles with a variable subscription
        self._routes: dict[str, tuple[list[str], np.ndarray]] = {}  # id -> edges, edge lengths [m]
        self._window: dict[str, tuple[str, int]] = {}  # member -> (route id, first edge index)
        self._lane_geometry: dict[str, tuple[float, int, str]] = {}  # lane -> (width [m], lanes of its edge, edge)
        self._bodies: dict[str, tuple[float, float, str]] = {}  # vehicle -> (length, width [m], vType)
        self._overlap: dict[str, str] = {}  # member -> the neighbour lane its body reaches into
        self._ends: dict[str, tuple[float, str]] = {}  # member -> its lane's end (sumo/adapter/lane_ends.py)
        self._end_of: dict = {}  # (lane, vClass, next edge) -> lane end or None (sumo/adapter/lane_ends.py)
        self._window_lane: dict[str, str] = {}  # member -> lane its route window was last checked on
        self._member_get = None  # itemgetter of the members' subscription variables
        self._all_here = np.ones(0, dtype=bool)  # read_members' 'present' when SUMO has them all
        self._settled = None  # (ids, lanes, half widths, half lane widths) of _track_lanes
        # libsumo's compiled module (None: traci): its functions without their wrappers
        self._compiled = fast = getattr(self.api, "_libsumo", None)
        v = self.api.vehicle
        self._move_xy = v.moveToXY if fast is None else fast.vehicle_moveToXY
        self._set_previous_speed = v.setPreviousSpeed if fast is None else fast.vehicle_setPreviousSpeed
        self._set_speed = v.setSpeed if fast is None else fast.vehicle_setSpeed
        # libsumo's simulationStep also runs its step listeners (traci's API): the package adds none
        self._sim_step = self.api.simulationStep if fast is None else fast.simulation_step
        self._all_results = (v.getAllSubscriptionResults if fast is None
                             else fast.vehicle_getAllSubscriptionResults)
        self._started = False
        self.native = None  # sumo/adapter/native_reads.py's module once libsumo started (or None)
        self.departed: dict[str, int] = {}  # flow id -> vehicles SUMO inserted (see count_departures)
        self.departures: list[tuple[str, float]] = []  # (vehicle id, SUMO time [s]) of every insertion
        self._proc = None  # the SUMO process of the traci backend

    # -- lifecycle -------------------------------------------------------------------
    @property
    def started(self) -> bool:
        """True from :meth:`start` (or :meth:`attach`) until :meth:`close`."""
        return self._started

    def start(self, args: list[str]) -> str:
        """Start SUMO with command-line ``args`` (without the binary); returns SUMO's version."""
        cmd = [sumo_binary(self.gui and self.backend == "traci")] + list(args)
        if self.backend == "traci":
            return self._start_socket(cmd)
        try:
            _, self.version = self.api.start(cmd)
        except Exception as exc:
            raise SumoError(f"SUMO did not start: {exc}") from exc
        self._started = True
        from .native_reads import load  # the C++ reads of sumo/native (None: SWIG's)
        self.native = load(self._compiled.__file__)
        if self.native is not None:
            self.native.clear()  # the bodies it keeps are of the last simulation's vehicles
        return self.version

    def _start_socket(self, cmd: list[str]) -> str:
        """traci: SUMO as a process, connected within START_TIMEOUT_S (sumo/adapter/connect.py)."""
        self.version, self._proc = start_socket(self.api, cmd)
        self._started = True
        return self.version

    def follow(self, vehicle_id: str) -> None:
        """sumo-gui: keep the view on ``vehicle_id`` (a member), zoomed to the formation."""
        if self.gui and self.backend == "traci":
            follow_view(self.api, vehicle_id)

    def attach(self, port: int) -> str:
        """Connect (traci) to a SUMO started elsewhere with ``--remote-port port``."""
        self.version = attach_socket(self.api, port)
        self._started = True
        return self.version

    def close(self) -> None:
        if self._started:
            try:
                self.api.close(wait=False) if self._proc is not None else self.api.close()
            except Exception:  # closing a dead connection must not hide the real error
                pass
            self._started = False
        if self._proc is not None:  # sumo-gui quits on --quit-on-end; never wait forever
            try:
                self._proc.wait(10)
            except Exception:
                self._proc.kill()
                self._proc.wait(10)
            self._proc = None

    @property
    def time(self) -> float:
        """SUMO's simulation time [s]."""
        return self.api.simulation.getTime()

    def simulation_step(self) -> None:
        """Advance SUMO by one step (no member handling; used for the warm-up)."""
        self.api.simulationStep()
        if self.departed:
            self._count_departed()

    def count_departures(self, flow_ids) -> None:
        """Count, from now on, the vehicles SUMO inserts for each flow (SUMO names them
        ``<flow id>.<n>``) in :attr:`departed`."""
        self.departed = {f: 0 for f in flow_ids}

    def _count_departed(self) -> None:
        counts = self.departed
        ids = self.api.simulation.getDepartedIDList()
        if ids:
            t = self.api.simulation.getTime()
            self.departures.extend((vid, t) for vid in ids)  # every vehicle: (id, SUMO time [s])
        for vid in ids:
            flow = vid.rpartition(".")[0]
            if flow in counts and vid not in self.members:
                counts[flow] += 1

    # -- network helpers -------------------------------------------------------------
    def add_route(self, route_id: str, edges: list[str]) -> None:
        self.api.route.add(route_id, edges)
        self.know_route(route_id, edges)

    def _advance_route_window(self, vid: str, lane_id: str) -> None:
        """Give member ``vid`` the route up to :data:`ROUTE_AHEAD_M` beyond the end of its
        current edge, when it has entered a new edge (``setRoute`` from the current edge on;
        SUMO puts the edges already driven in front)."""
        if not lane_id or lane_id.startswith(":") or vid not in self._window:
            return
        route_id, start = self._window[vid]
        edges, lengths = self._routes[route_id]
        edge = lane_id.rsplit("_", 1)[0]
        if start >= 0 and edges[start] == edge:
            self._window_lane[vid] = lane_id  # nothing to do until the lane changes
            return
        try:
            i = edges.index(edge, max(start, 0))
        except ValueError:
            return  # not on the formation's route: SUMO's own checks report it
        ahead = np.cumsum(lengths[i + 1:])
        end = i + 2 + int(np.searchsorted(ahead, ROUTE_AHEAD_M))
        try:
            self.api.vehicle.setRoute(vid, edges[i:end])
        except self.api.TraCIException:
            return  # e.g. on a junction: the next edge tries again
        self._window[vid] = (route_id, i)
        self._window_lane[vid] = lane_id

    # -- members ---------------------------------------------------------------------
    def insert_member(self, vid: str, route_id: str, mt: MemberType, x, y, psi, v) -> None:
        """Add a member and pin it to its CoG pose (x, y [m], psi [rad]) with speed v [m/s];
        it appears in SUMO at that exact pose during the next step."""
        self.members[vid] = mt
        self.api.vehicle.add(vid, route_id, typeID=mt.id, depart="now", departLane="best",
                             departPos="base", departSpeed=f"{max(float(v), 0.0):.6f}")
        self.api.vehicle.setSpeedMode(vid, 0)
        self.api.vehicle.setLaneChangeMode(vid, 0)
        self.api.vehicle.subscribe(vid, self._member_vars())
        self._subscribed.add(vid)
        self._window[vid] = (route_id, self._route_from_entry(vid, route_id, x, y))
        self._move(vid, x, y, psi)

    def _route_from_entry(self, vid: str, route_id: str, x: float, y: float) -> int:
        """Before its insertion, member ``vid`` gets the route ``route_id`` from the edge
        before the one at its CoG (x, y) [m] on (SUMO keeps no edge of it behind then): the
        index of its first edge in ``route_id``, or -1 when it keeps the whole route (its
        edge is the route's first or second, or not on the route)."""
        edges = self._routes[route_id][0]
        if len(edges) < 3:
            return -1
        edge = self.api.simulation.convertRoad(float(x), float(y))[0]
        start = edges.index(edge) - 1 if edge in edges else -1
        if start < 1:
            return -1
        self.api.vehicle.setRoute(vid, edges[start:])
        return start

    def add_twin_vehicle(self, vid: str, route_id: str, mt: MemberType, x, y, psi, v) -> None:
        """A member as the same-demand twin has it: a vehicle of the member's type ``mt`` (its
        body) on the formation's route ``route_id``, entering at the member's CoG pose (x, y
        [m], psi [rad]) with speed v [m/s] during the next step, then driven by SUMO's own
        models like the traffic's vehicles of its kind (sumo/traffic.py BASE_TYPES: the
        ordinary vehicle class, acceleration, deceleration, minimum gap, driver imperfection
        and top speed; default speed and lane-change modes) and read as any other vehicle."""
        api = self.api.vehicle
        api.add(vid, route_id, typeID=mt.id, depart="now", departLane="best",
                departPos="base", departSpeed=f"{max(float(v), 0.0):.6f}")
        kind = ORDINARY_CLASS.get(mt.vclass, "passenger")
        api.setVehicleClass(vid, kind)  # lanes closed to the members are open to it
        drv = BASE_TYPES["truck" if kind == "truck" else "car"]  # SUMO's driver of its kind
        api.setAccel(vid, float(drv["accel"]))
        api.setDecel(vid, float(drv["decel"]))
        api.setEmergencyDecel(vid, float(drv["emergencyDecel"]))
        api.setMinGap(vid, float(drv["minGap"]))
        api.setImperfection(vid, float(drv["sigma"]))
        api.setMaxSpeed(vid, float(drv["maxSpeed"]))
        xf, yf, ang = cog_to_sumo(x, y, psi, mt.d_front)
        self._move_front(vid, float(xf), float(yf), float(ang), x, y)

    def _member_vars(self):
        tc = self.tc
        self._member_keys = (tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LANE_ID, tc.VAR_LANE_INDEX,
                             tc.VAR_LANEPOSITION_LAT, tc.VAR_LANEPOSITION)
        self._member_get = itemgetter(*self._member_keys)
        return [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LANE_ID, tc.VAR_LANE_INDEX,
                tc.VAR_LANEPOSITION, tc.VAR_LANEPOSITION_LAT]

    def _move(self, vid, x, y, psi):
        xf, yf, ang = cog_to_sumo(x, y, psi, self.members[vid].d_front)
        self._move_front(vid, float(xf), float(yf), float(ang), x, y)

    def _move_front(self, vid, xf: float, yf: float, angle_deg: float, x, y):
        """moveToXY with SUMO's front-bumper pose; (x, y) is the CoG, for the message."""
        try:
            self.api.vehicle.moveToXY(vid, "", -1, xf, yf, angle_deg, KEEP_ROUTE, MATCH_THRESHOLD)
        except self.api.TraCIException as exc:
            raise SumoError(_refusal(vid, (x, y), exc)) from exc

    def place(self, ids: list[str], xf, yf, angle, v, pos) -> list[tuple[str, str]]:
        """Pin members to SUMO's front bumper ``xf``, ``yf`` [m] and ``angle`` [deg] for the
        coming step, with speed ``v`` [m/s, not below 0] at its end (sumo/types.py
        sumo_placement's rows; CoG ``pos`` (n, 2) [m] for the messages). Returns (id, message)
        of moves SUMO refused.

        A member whose body overlaps a neighbour lane (as last read, :meth:`read_members`) is
        first put on that lane (``moveTo``) so that the ``moveToXY`` is a lane change: SUMO
        then registers the member on both lanes (its "shadow lane") and followers in the
        other lane see it (docs/sumo.md). Each move is followed by ``setSpeed`` with the
        member's speed (docs/sumo.md, "SUMO's speed of a member").
        """
        move, set_speed, overlap, ends, refused = self._move_xy, self._set_speed, self._overlap, self._ends, []
        for i, (vid, a, b, c, vi) in enumerate(zip(ids, xf.tolist(), yf.tolist(), angle.tolist(),
                                                   v.tolist())):
            if overlap or ends:
                # a lane that does not lead on for the member (sumo/adapter/lane_ends.py)
                hint = self._cross_end(vid, vi, overlap.get(vid))
                if hint is not None:
                    self._hint_lane(vid, hint)
            try:
                move(vid, "", -1, a, b, c, KEEP_ROUTE, MATCH_THRESHOLD)
                set_speed(vid, vi)
            except self.api.TraCIException as exc:
                refused.append((vid, _refusal(vid, pos[i], exc)))
        return refused

    def _hint_lane(self, vid: str, other: str) -> None:
        """Put member ``vid`` on lane ``other`` at its lane position (``moveTo``)."""
        try:
            pos = min(self.api.vehicle.getLanePosition(vid), self.api.lane.getLength(other) - 0.1)
            self.api.vehicle.moveTo(vid, other, max(pos, 0.0))
        except self.api.TraCIException:
            pass  # only a hint for SUMO's lane bookkeeping

    def step(self) -> StepEvents:
        """One SUMO step; returns the collisions, teleports and arrivals it reported."""
        try:
            self._sim_step(0.0)
        except Exception as exc:
            raise SumoError(f"SUMO raised during the step to t = {self.time:.2f} s: {exc}") from exc
        sim = self.api.simulation
        collisions, teleports, arrived = (sim.getCollisions(), sim.getStartingTeleportIDList(),
                                          sim.getArrivedIDList())
        if self.departed:
            self._count_departed()
        if not (collisions or teleports or arrived):
            return _QUIET  # nothing reported (most steps)
        for vid in arrived:
            self._bodies.pop(vid, None)
        if self.native is not None and arrived:
            self.native.forget(list(arrived))
        return StepEvents([(c.collider, c.victim, c.lane) for c in collisions], list(teleports),
                          list(arrived))

    def set_true_speeds(self, ids: list[str], v, a) -> None:
        """Tell SUMO each member's true speed [m/s, not below 0: sumo/types.py sumo_placement]
        and acceleration [m/s^2] (it would infer a half-step-late mean speed clamped to the lane
        limit from the distance moved)."""
        set_speed = self._set_previous_speed
        for vid, vi, ai in zip(ids, v.tolist(), a.tolist()):
            try:
                set_speed(vid, vi, ai)
            except self.api.TraCIException:
                pass  # removed during the step: the next read_members reports it

    def move_rows(self, ids: list[str], xf, yf, angle, pos, v) -> dict[str, str]:
        """moveToXY of the members ``ids`` to SUMO's front bumper ``xf``, ``yf`` [m] and
        ``angle`` [deg], then ``setSpeed`` with their speed ``v`` [m/s, not below 0] at the end
        of the coming step (float64 rows; CoG ``pos`` (n, 2) [m] for the messages), through the
        C++ reads when they are there; returns the refused moves as :meth:`place` does, {SUMO id:
        message} (sumo/fused_path.py: no member reaches into a neighbour lane)."""
        if self.native is not None:
            refused = self.native.move_all(ids, xf, yf, angle, KEEP_ROUTE, MATCH_THRESHOLD, v)
            return {vid: _refusal(vid, pos[ids.index(vid)], msg) for vid, msg in refused}
        move, set_speed, refused = self._move_xy, self._set_speed, {}
        for i, (vid, a, b, c, vi) in enumerate(zip(ids, xf.tolist(), yf.tolist(), angle.tolist(),
                                                   v.tolist())):
            try:
                move(vid, "", -1, a, b, c, KEEP_ROUTE, MATCH_THRESHOLD)
                set_speed(vid, vi)
            except self.api.TraCIException as exc:
                refused[vid] = _refusal(vid, pos[i], exc)
        return refused

    def tell_speeds(self, ids: list[str], v, a) -> None:
        """:meth:`set_true_speeds` with the speeds (not below 0) and accelerations given
        (float64 arrays), through the C++ reads when they are there."""
        if self.native is not None:
            self.native.set_previous_speeds(ids, v, a)
        else:
            self.set_true_speeds(ids, v, a)

    def remove_vehicle(self, vid: str) -> None:
        """Take a vehicle out of SUMO. Its subscriptions are dropped first: libsumo 1.28 raises
        "Vehicle is not known" at the next step when a vehicle with a (context) subscription is
        vaporised through TraCI (docs/sumo.md)."""
        radius = self._context.pop(vid, None)
        if radius is not None:
            self.api.vehicle.unsubscribeContext(vid, self.tc.CMD_GET_VEHICLE_VARIABLE, radius)
        if vid in self._subscribed:
            self._subscribed.discard(vid)
            self.api.vehicle.unsubscribe(vid)
        self._window.pop(vid, None)
        self._overlap.pop(vid, None)
        self._ends.pop(vid, None)
        self._bodies.pop(vid, None)
        if self.native is not None:
            self.native.forget([vid])
        self.api.vehicle.remove(vid, self.tc.REMOVE_VAPORIZED)


def _refusal(vid: str, at, why) -> str:
    """The message of a refused moveToXY of ``vid`` whose CoG was to go to ``at`` (x, y) [m]."""
    return f"moveToXY refused for {vid} at ({at[0]:.2f}, {at[1]:.2f}): {why}"
