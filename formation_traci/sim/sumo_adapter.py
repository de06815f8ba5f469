"""The only module that talks to SUMO (libsumo in-process, or traci over a socket).

It owns starting/stepping/closing SUMO, inserting and placing the formation members with
``vehicle.moveToXY``, batched reads through subscriptions, and every frame conversion:
SUMO's vehicle position is the front bumper and its angle is degrees clockwise from north;
ours is the centre of gravity (CoG) and radians counter-clockwise from +x
(:func:`cog_to_sumo`, :func:`sumo_to_cog`). Outside this module code sees only numpy
arrays and the small dataclasses below. SUMO behaviours relied on here are documented in
docs/sumo.md (each with the test that shows it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from operator import itemgetter

import numpy as np

KEEP_ROUTE = 1
"""moveToXY keepRoute bits: 1 = map only onto edges of the member's route (never off the road,
never a different carriageway); sublane mode keeps the exact lateral position."""

MATCH_THRESHOLD = 5.0
"""moveToXY raises instead of silently snapping a pose farther than this from the road [m]."""

ROUTE_AHEAD_M = 1000.0
"""A member's route in SUMO reaches at least this far past the end of its current edge [m].
``moveToXY`` with keepRoute=1 searches every edge of the vehicle's route (ahead of it and
behind it) for the nearest lane, so on a route of many edges a member carries only the part of
the formation's route up to here, moved on whenever it enters the next edge (SUMO keeps the
edges already driven in the route; docs/sumo.md)."""

SPEED_MODE_DEFAULT = 31
"""SUMO's default speed mode: all safe-speed, acceleration and right-of-way checks on
(https://sumo.dlr.de/docs/TraCI/Change_Vehicle_State.html#speed_mode_0xb3)."""
LANE_CHANGE_MODE_DEFAULT = 1621
"""SUMO's default lane change mode (TraCI/Change_Vehicle_State.html#lane_change_mode_0xb6)."""

REMOVED_REASONS = ("arrived", "vanished")

ORDINARY_CLASS = {"custom1": "passenger", "custom2": "truck"}
"""SUMO class a released member drives on with: the members' own classes are kept off some
junction lanes of real networks (road/lanes.py), an ordinary vehicle is not."""


def cog_to_sumo(x, y, psi, d_front):
    """CoG pose [m, m, rad CCW from +x] -> SUMO front bumper [m, m] and angle [deg, CW from north]."""
    xf = x + d_front * np.cos(psi)
    yf = y + d_front * np.sin(psi)
    angle = np.mod(90.0 - np.degrees(psi), 360.0)
    return xf, yf, angle


def sumo_to_cog(xf, yf, angle_deg, d_front):
    """SUMO front bumper [m] and angle [deg, CW from north] -> CoG [m] and heading [rad CCW from +x]."""
    psi = np.radians(90.0 - np.asarray(angle_deg, dtype=float))
    return xf - d_front * np.cos(psi), yf - d_front * np.sin(psi), psi


@dataclass(frozen=True)
class MemberType:
    """SUMO vType of a formation member."""

    id: str
    length: float  # [m]
    width: float  # [m]
    d_front: float  # CoG to front bumper [m]
    color: tuple[int, int, int]
    vclass: str  # SUMO vehicle class
    max_speed: float = 70.0  # [m/s] above anything a member reaches, so SUMO never clamps
    ssm_device: bool = False  # SUMO's SSM device on members of this type (sumo.ssm = "members")


@dataclass
class StepEvents:
    """What SUMO reported during one step (ids are SUMO vehicle ids)."""

    collisions: list[tuple[str, str, str]] = field(default_factory=list)  # (collider, victim, lane)
    teleports: list[str] = field(default_factory=list)
    arrived: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Neighbours:
    """Vehicles near the members after a step (one entry per vehicle), CoG frame."""

    ids: list[str]
    types: list[str]
    x: np.ndarray  # centre of the vehicle [m]
    y: np.ndarray
    heading: np.ndarray  # [rad]
    v: np.ndarray  # [m/s]
    a: np.ndarray  # [m/s^2]
    length: np.ndarray  # [m]
    width: np.ndarray  # [m]
    lane_ids: list[str]
    lane_index: np.ndarray


class SumoError(RuntimeError):
    """SUMO refused a command or raised during a step."""


def _api(backend: str):
    if backend == "libsumo":
        import libsumo as api
    elif backend == "traci":
        import traci as api
    else:  # pragma: no cover - validated by the schema
        raise ValueError(backend)
    from libsumo import constants as tc  # the same module as traci.constants
    return api, tc


START_TIMEOUT_S = 30
"""A SUMO started over a socket (traci backend, sumo-gui) that does not accept the connection
within this many seconds is killed and the run fails with what SUMO printed [s]."""

GUI_VIEW = "View #0"
"""sumo-gui's default view (the one that follows the formation)."""

GUI_ZOOM = 400.0
"""Zoom of that view while following a member [%]: about 150 m of road across the window."""


def sumo_binary(gui: bool = False) -> str:
    """Path of the sumo (or sumo-gui) binary of the eclipse-sumo wheel."""
    import sumolib
    return sumolib.checkBinary("sumo-gui" if gui else "sumo")


class SumoAdapter:
    """One SUMO simulation. Call :meth:`start`, then per step :meth:`place` -> :meth:`step`
    -> :meth:`after_step`, and :meth:`close` at the end (also after errors)."""

    def __init__(self, backend: str = "libsumo", gui: bool = False):
        self.api, self.tc = _api(backend)
        self.backend = backend
        self.gui = gui
        self.version = ""
        self.members: dict[str, MemberType] = {}
        self._member_lane: dict[str, tuple[str, int, float]] = {}
        self._context: dict[str, float] = {}  # vehicle -> radius of its context subscription
        self._subscribed: set[str] = set()  # vehicles with a variable subscription
        self._routes: dict[str, tuple[list[str], np.ndarray]] = {}  # id -> edges, edge lengths [m]
        self._window: dict[str, tuple[str, int]] = {}  # member -> (route id, first edge index)
        self._lane_geometry: dict[str, tuple[float, int]] = {}  # lane -> (width [m], lanes of its edge)
        self._bodies: dict[str, tuple[float, float, str]] = {}  # vehicle -> (length, width [m], vType)
        self._started = False
        self.departed: dict[str, int] = {}  # flow id -> vehicles SUMO inserted (see count_departures)
        self._proc = None  # the SUMO process of the traci backend

    # -- lifecycle -------------------------------------------------------------------
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
        return self.version

    def _start_socket(self, cmd: list[str]) -> str:
        """traci: start SUMO as a process and connect within START_TIMEOUT_S; a SUMO that exits
        or never listens is killed and its own message raised (never a hang)."""
        import contextlib
        import io
        import subprocess
        import tempfile

        import sumolib

        port = sumolib.miscutils.getFreeSocketPort()
        err = tempfile.TemporaryFile()
        proc = subprocess.Popen(cmd + ["--remote-port", str(port)], stdout=err, stderr=err)
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # traci prints every retry
                self.api.init(port, numRetries=START_TIMEOUT_S, proc=proc)
            self.version = self.api.getVersion()[1]
        except Exception as exc:
            if proc.poll() is None:
                proc.kill()
            proc.wait(10)
            err.seek(0)
            said = err.read().decode(errors="replace").strip()
            raise SumoError(f"SUMO did not start ({type(exc).__name__}: {exc})"
                            + (f": {said[-2000:]}" if said else "")) from None
        finally:
            err.close()
        self._proc = proc
        self._started = True
        return self.version

    def follow(self, vehicle_id: str) -> None:
        """sumo-gui: keep the view on ``vehicle_id`` (a member), zoomed to the formation."""
        if not (self.gui and self.backend == "traci"):
            return
        try:
            self.api.gui.trackVehicle(GUI_VIEW, vehicle_id)
            self.api.gui.setZoom(GUI_VIEW, GUI_ZOOM)
        except Exception:  # a view without tracking is still a view: never fail the run
            pass

    def attach(self, port: int) -> str:
        """Connect (traci) to a SUMO started elsewhere with ``--remote-port port``."""
        try:
            self.api.init(port)
            self.version = self.api.getVersion()[1]
        except Exception as exc:
            raise SumoError(f"could not attach to SUMO on port {port}: {exc}") from exc
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
        for vid in self.api.simulation.getDepartedIDList():
            flow = vid.rpartition(".")[0]
            if flow in counts and vid not in self.members:
                counts[flow] += 1

    # -- network helpers -------------------------------------------------------------
    def set_friction(self, mu: float) -> None:
        """Set the friction of every edge of the network [-] (SUMO's cars with the friction
        device slow down on slippery lanes). ``edge.setFriction``: the traci server rejects
        ``lane.setFriction`` in SUMO 1.28."""
        for edge in self.api.edge.getIDList():
            if not edge.startswith(":"):
                self.api.edge.setFriction(edge, mu)

    def add_route(self, route_id: str, edges: list[str]) -> None:
        self.api.route.add(route_id, edges)
        lengths = np.array([self.api.lane.getLength(f"{e}_0") for e in edges])
        self._routes[route_id] = (list(edges), lengths)

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

    def forbid_lanes(self, lanes, vclasses) -> None:
        """Disallow vehicle classes on lanes (added to each lane's disallowed classes)."""
        for lane in lanes:
            have = list(self.api.lane.getDisallowed(lane))
            self.api.lane.setDisallowed(lane, sorted(set(have) | set(vclasses)))

    def add_member_type(self, mt: MemberType) -> None:
        vt = self.api.vehicletype
        vt.copy("DEFAULT_VEHTYPE", mt.id)
        vt.setLength(mt.id, mt.length)
        vt.setWidth(mt.id, mt.width)
        vt.setColor(mt.id, (*mt.color, 255))
        vt.setVehicleClass(mt.id, mt.vclass)
        vt.setMaxSpeed(mt.id, mt.max_speed)
        vt.setMinGap(mt.id, 0.5)
        vt.setImperfection(mt.id, 0.0)
        vt.setSpeedDeviation(mt.id, 0.0)
        vt.setAccel(mt.id, 10.0)
        vt.setDecel(mt.id, 10.0)
        vt.setEmergencyDecel(mt.id, 12.0)
        vt.setMaxSpeedLat(mt.id, 10.0)
        if mt.ssm_device:  # by the type, not --device.ssm.explicit: SUMO keeps that id list
            vt.setParameter(mt.id, "has.ssm.device", "true")  # from the first run of a process

    def release(self, vid: str, accel: float, decel: float, exit_edge: str = "") -> str:
        """Hand member ``vid`` over to SUMO's own driver model at its lane, position and
        speed: its route becomes the rest of the formation's route from its edge (or, with
        ``exit_edge``, SUMO's route to that edge: ``changeTarget``), its acceleration and
        deceleration ``accel`` / ``decel`` [m/s^2], SUMO's safe-speed and lane-change checks
        are on again (their default modes), and from now on it is an ordinary vehicle (a
        neighbour). Returns its lane id; raises SumoError when the exit cannot be reached."""
        v = self.api.vehicle
        window = self._window.pop(vid, None)
        lane = self._member_lane.pop(vid, ("", -1, 0.0))[0]
        mt = self.members.get(vid)
        if mt is not None and mt.vclass in ORDINARY_CLASS:  # lanes closed to members open again
            v.setVehicleClass(vid, ORDINARY_CLASS[mt.vclass])
        if window is not None and lane and not lane.startswith(":"):
            edges = self._routes[window[0]][0]
            edge = lane.rsplit("_", 1)[0]
            if edge in edges:
                try:
                    v.setRoute(vid, edges[edges.index(edge):])
                except self.api.TraCIException:
                    pass  # keeps its window; SUMO reports it at the window's end
        if exit_edge:
            try:
                v.changeTarget(vid, exit_edge)
            except self.api.TraCIException as exc:
                raise SumoError(f"no route from {lane or 'its lane'} to the exit {exit_edge}: {exc}") from None
        v.setAccel(vid, accel)
        v.setDecel(vid, decel)
        v.setSpeedMode(vid, SPEED_MODE_DEFAULT)
        v.setLaneChangeMode(vid, LANE_CHANGE_MODE_DEFAULT)
        self.members.pop(vid, None)
        return lane

    def add_driven(self, vid: str, edges: list[str], lane: int, pos: float, speed: float,
                   mt: MemberType, accel: float, decel: float) -> None:
        """A vehicle of type ``mt`` that SUMO drives: on ``edges[0]`` lane ``lane``, front
        bumper ``pos`` [m] from the edge's start, ``speed`` [m/s] (inserted as soon as SUMO
        finds it safe), acceleration / deceleration ``accel`` / ``decel`` [m/s^2], keeping
        its lane (lane-change mode 0). A joining member before the join takes it over."""
        rid = f"{vid}_entry"
        self.api.route.add(rid, list(edges))
        self.api.vehicle.add(vid, rid, typeID=mt.id, depart="now", departLane=str(int(lane)),
                             departPos=f"{max(pos, 0.0):.3f}", departSpeed=f"{max(speed, 0.0):.3f}")
        self.api.vehicle.setAccel(vid, accel)
        self.api.vehicle.setDecel(vid, decel)
        self.api.vehicle.setLaneChangeMode(vid, 0)

    def take_over(self, vid: str, mt: MemberType, route_id: str) -> None:
        """Join: SUMO vehicle ``vid`` becomes a member where it is: vType ``mt`` (SUMO keeps
        its front bumper where it is), no safe-speed or lane-change checks of its own, placed
        by moveToXY from the next step on along the formation's route ``route_id`` from its
        edge (the route window, as for an inserted member)."""
        self.members[vid] = mt
        self._bodies.pop(vid, None)
        v = self.api.vehicle
        v.setType(vid, mt.id)
        v.setSpeedMode(vid, 0)
        v.setLaneChangeMode(vid, 0)
        v.subscribe(vid, self._member_vars())  # replaces a neighbour subscription
        self._subscribed.add(vid)
        self._window[vid] = (route_id, -1)

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
        self._window[vid] = (route_id, -1)
        self._move(vid, x, y, psi)

    def _member_vars(self):
        tc = self.tc
        return [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LANE_ID, tc.VAR_LANE_INDEX,
                tc.VAR_LANEPOSITION, tc.VAR_LANEPOSITION_LAT, tc.VAR_SPEED]

    def _move(self, vid, x, y, psi):
        xf, yf, ang = cog_to_sumo(x, y, psi, self.members[vid].d_front)
        self._move_front(vid, float(xf), float(yf), float(ang), x, y)

    def _move_front(self, vid, xf: float, yf: float, angle_deg: float, x, y):
        """moveToXY with SUMO's front-bumper pose; (x, y) is the CoG, for the message."""
        try:
            self.api.vehicle.moveToXY(vid, "", -1, xf, yf, angle_deg, KEEP_ROUTE, MATCH_THRESHOLD)
        except self.api.TraCIException as exc:
            raise SumoError(f"moveToXY refused for {vid} at ({x:.2f}, {y:.2f}): {exc}") from exc

    def place(self, ids: list[str], x, y, psi) -> list[tuple[str, str]]:
        """Pin members to CoG poses for the coming step. Returns (id, message) of moves SUMO refused.

        A member whose body overlaps a neighbour lane is first put on that lane (``moveTo``)
        so that the ``moveToXY`` is a lane change: SUMO then registers the member on both
        lanes (its "shadow lane") and followers in the other lane see it (docs/sumo.md).
        """
        refused = []
        d_front = np.array([self.members[vid].d_front for vid in ids])
        xf, yf, ang = (a.tolist() for a in cog_to_sumo(np.asarray(x), np.asarray(y), np.asarray(psi), d_front))
        for i, vid in enumerate(ids):
            mt = self.members[vid]
            info = self._member_lane.get(vid)
            if info is not None:
                lane_id, lane_index, lat = info
                other = self._overlapped_lane(lane_id, lane_index, lat, mt.width)
                if other is not None:
                    try:
                        pos = min(self.api.vehicle.getLanePosition(vid),
                                  self.api.lane.getLength(other) - 0.1)
                        self.api.vehicle.moveTo(vid, other, max(pos, 0.0))
                    except self.api.TraCIException:
                        pass  # only a hint for SUMO's lane bookkeeping
            try:
                self._move_front(vid, xf[i], yf[i], ang[i], x[i], y[i])
            except SumoError as exc:
                refused.append((vid, str(exc)))
        return refused

    def _overlapped_lane(self, lane_id: str, lane_index: int, lat: float, width: float):
        if not lane_id or lane_id.startswith(":"):
            return None
        edge = lane_id.rsplit("_", 1)[0]
        geo = self._lane_geometry.get(lane_id)
        if geo is None:
            geo = self._lane_geometry[lane_id] = (self.api.lane.getWidth(lane_id),
                                                  self.api.edge.getLaneNumber(edge))
        lane_w, n_lanes = geo
        if abs(lat) + width / 2 <= lane_w / 2:
            return None
        other = lane_index + (1 if lat > 0 else -1)
        if other < 0 or other >= n_lanes:
            return None
        return f"{edge}_{other}"

    def step(self) -> StepEvents:
        """One SUMO step; returns the collisions, teleports and arrivals it reported."""
        try:
            self.api.simulationStep()
        except Exception as exc:
            raise SumoError(f"SUMO raised during the step to t = {self.time:.2f} s: {exc}") from exc
        sim = self.api.simulation
        ev = StepEvents()
        for c in sim.getCollisions():
            ev.collisions.append((c.collider, c.victim, c.lane))
        ev.teleports = list(sim.getStartingTeleportIDList())
        ev.arrived = list(sim.getArrivedIDList())
        if self.departed:
            self._count_departed()
        for vid in ev.arrived:
            self._bodies.pop(vid, None)
        return ev

    def set_true_speeds(self, ids: list[str], v, a) -> None:
        """Tell SUMO each member's true speed [m/s] and acceleration [m/s^2] (it would infer
        a half-step-late mean speed clamped to the lane limit from the distance moved)."""
        for i, vid in enumerate(ids):
            try:
                self.api.vehicle.setPreviousSpeed(vid, float(max(v[i], 0.0)), float(a[i]))
            except self.api.TraCIException:
                pass  # removed during the step: the next read_members reports it

    def read_members(self, ids: list[str]):
        """Where SUMO put each member: CoG x, y [m], heading [rad], lane id, lane index,
        lateral position in the lane [m]; ``present`` is False for members SUMO no longer has."""
        tc = self.tc
        res = self.api.vehicle.getAllSubscriptionResults()
        n = len(ids)
        xf, yf, ang, lat, d_front = ([math.nan] * n for _ in range(5))
        lane_index = [-1] * n
        lanes = [""] * n
        present = [False] * n
        for i, vid in enumerate(ids):
            r = res.get(vid)
            if not r:
                self._member_lane.pop(vid, None)
                continue
            present[i] = True
            xf[i], yf[i] = r[tc.VAR_POSITION]
            ang[i], d_front[i] = r[tc.VAR_ANGLE], self.members[vid].d_front
            lanes[i] = lane = r[tc.VAR_LANE_ID]
            lane_index[i] = li = r[tc.VAR_LANE_INDEX]
            lat[i] = r[tc.VAR_LANEPOSITION_LAT]
            self._member_lane[vid] = (lane, li, lat[i])
            self._advance_route_window(vid, lane)
        x, y, psi = sumo_to_cog(np.array(xf), np.array(yf), np.array(ang), np.array(d_front))
        lane_index, lat, present = np.array(lane_index, dtype=int), np.array(lat), np.array(present, dtype=bool)
        self.lane_pos = np.array([res[vid][tc.VAR_LANEPOSITION] if present[i] else math.nan
                                  for i, vid in enumerate(ids)])  # front bumper along its lane [m]
        return x, y, psi, lanes, lane_index, lat, present

    # -- neighbours ------------------------------------------------------------------
    def subscribe_neighbours(self, vid: str, radius: float) -> None:
        """Context subscription: every vehicle within ``radius`` [m] of member ``vid`` (one per
        formation: overlapping subscriptions would return the same vehicles several times)."""
        tc = self.tc
        self.api.vehicle.subscribeContext(vid, tc.CMD_GET_VEHICLE_VARIABLE, radius, self._neighbour_vars())
        self._context[vid] = radius

    def _neighbour_vars(self):
        """Variables that change every step; length, width and type are read once per vehicle."""
        tc = self.tc
        return [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_ACCELERATION, tc.VAR_LANE_ID,
                tc.VAR_LANE_INDEX]

    def _body(self, vid: str) -> tuple[float, float, str]:
        """Length [m], width [m] and vType of a vehicle (read on first sight, then cached)."""
        body = self._bodies.get(vid)
        if body is None:
            v = self.api.vehicle
            body = self._bodies[vid] = (v.getLength(vid), v.getWidth(vid), v.getTypeID(vid))
        return body

    def subscribe_departed(self) -> None:
        """Subscribe every vehicle that entered in the last step (recording 'all' vehicles);
        the first call also subscribes the vehicles already on the road."""
        if not getattr(self, "_subscribed_all", False):
            self._subscribed_all = True
            fresh = self.api.vehicle.getIDList()
        else:
            fresh = self.api.simulation.getDepartedIDList()
        for vid in fresh:
            if vid not in self.members:
                self.api.vehicle.subscribe(vid, self._neighbour_vars())
                self._subscribed.add(vid)

    def neighbours(self, all_vehicles: bool) -> Neighbours:
        """Non-member vehicles from the context subscriptions (or from all subscriptions)."""
        tc = self.tc
        rows: dict[str, dict] = {}
        if all_vehicles:
            for vid, r in self.api.vehicle.getAllSubscriptionResults().items():
                if vid not in self.members and r:
                    rows[vid] = r
        else:
            for ego, ctx in self.api.vehicle.getAllContextSubscriptionResults().items():
                for vid, r in ctx.items():
                    if vid not in self.members:
                        rows[vid] = r
        ids = sorted(rows)
        get = itemgetter(tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_ACCELERATION,
                         tc.VAR_LANE_INDEX, tc.VAR_LANE_ID)
        cols = list(zip(*(get(rows[vid]) for vid in ids))) or [()] * 6
        body = list(zip(*(self._body(vid) for vid in ids))) or [()] * 3
        xy = np.array(cols[0], dtype=float).reshape(-1, 2)
        ang, v, a = (np.array(c, dtype=float) for c in cols[1:4])
        li, lanes = np.array(cols[4], dtype=int), list(cols[5])
        length, width, types = np.array(body[0], dtype=float), np.array(body[1], dtype=float), list(body[2])
        x, y, psi = sumo_to_cog(xy[:, 0], xy[:, 1], ang, length / 2.0)  # centre of the body
        return Neighbours(ids, types, x, y, psi, v, a, length, width, lanes, li)

    def vehicle_bodies(self):
        """Every vehicle in SUMO: ids, body centre x, y [m], heading [rad], length, width [m]
        (direct getters: used once, at insertion)."""
        v = self.api.vehicle
        ids = list(v.getIDList())
        n = len(ids)
        xf, yf, ang, length, width = (np.empty(n) for _ in range(5))
        for i, vid in enumerate(ids):
            xf[i], yf[i] = v.getPosition(vid)
            ang[i], length[i], width[i] = v.getAngle(vid), v.getLength(vid), v.getWidth(vid)
        x, y, psi = sumo_to_cog(xf, yf, ang, length / 2.0)
        return ids, x, y, psi, length, width

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
        self._bodies.pop(vid, None)
        self.api.vehicle.remove(vid, self.tc.REMOVE_VAPORIZED)

    def vehicle_ids(self) -> list[str]:
        return list(self.api.vehicle.getIDList())
