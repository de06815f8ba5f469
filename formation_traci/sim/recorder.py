"""Recording of a run: trajectories, events and background vehicles as chunked Parquet.

The rows beside the members' signal rows (sim/fleet_rows.py) are written by the kernels of
sim/record_rows.py: the virtual cars' rows, the road and SUMO columns, the background rows and
the limits' test, the same kernels the compiled step of a road run calls (sumo/fused_step.py).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from run_contract.columns import (BACKGROUND_COLUMNS, COMFORT_COLUMNS, DEFAULT_FORMATION_ID, EVENT_COLUMNS,
                                  TRAJECTORY_COLUMNS, VIRTUAL_CAR_ID)

from ..record.columns import FILLED_BY_CALLER, SIGNAL_COLUMNS
from ..record.writer import ChunkedTable
from .record_rows import background_rows, beyond_limits, road_rows, vc_row, vc_rows
from .table_cuts import TableCuts
from .table_records import SignalRows, TableBuffers
from .incident_log import INCIDENT_EVENT_KINDS, IncidentLog


STEPS_PER_CHUNK = 1200
"""Outer steps per trajectory part file (60 s of simulated time at the default 0.05 s step)."""
BACKGROUND_CHUNK_ROWS = 50_000
"""Rows per background part file at most (a part also ends every STEPS_PER_CHUNK steps)."""

MAX_SLIP = np.radians(10.0)
"""Tire slip beyond which the Magic Formula fit of Table 3.2 is far past its peak [rad]."""
MAX_FRICTION_USAGE = 1.0
"""Friction circle (eq 3.16): above 1 the tires cannot deliver the accelerations."""
MAX_SPEED = 60.0
"""Speeds above this are outside anything the parameters were meant for [m/s]."""

_VC_COLUMNS = ("t", "x", "y", "heading", "v", "yaw_rate", "a_lon", "a_lat", "s", "d")
_ROAD_COLUMNS = ("s", "d", "lane_index", "sumo_gap", "slot", "leader_age_s")
"""The road and SUMO columns, sim/record_rows.py road_rows' order (FILLED_BY_CALLER after t
and vehicle_id)."""


class Recorder(TableCuts):
    """Owns the run's tables; every ``add_*`` appends rows, :meth:`flush` writes the rest.

    ``formation_of`` maps vehicle ids (members, the virtual car) to their formation's id: the
    ``formation_id`` column of the trajectory, comfort and event tables (record/writer.py
    derived columns); by default every member and the virtual car are ``formation_id``'s.
    ``vc_ids``: the formations' virtual cars, one row each per step after the members' (a
    one-formation run: 'vc')."""

    def __init__(self, out_dir: Path, member_ids: list[str], with_sumo: bool,
                 periods_per_step: int = 1, formation_id: str = DEFAULT_FORMATION_ID,
                 formation_of: dict[str, str] | None = None, vc_ids: list[str] | None = None):
        n = len(member_ids)
        vc_ids = [VIRTUAL_CAR_ID] if vc_ids is None else list(vc_ids)
        self.formation_of = (dict(formation_of) if formation_of is not None else
                             {v: formation_id for v in [*member_ids, VIRTUAL_CAR_ID]})
        self.comfort = ChunkedTable(out_dir / "comfort.parquet", COMFORT_COLUMNS,
                                    chunk_rows=n * STEPS_PER_CHUNK * max(1, periods_per_step),
                                    labels=list(member_ids), derived=self.formation_of)
        self._comfort_from = np.array([SIGNAL_COLUMNS.index(c.name) for c in COMFORT_COLUMNS
                                       if c.name in SIGNAL_COLUMNS],
                                      dtype=np.int64)  # signal column of each comfort value
        self.traj = ChunkedTable(out_dir / "trajectories.parquet", TRAJECTORY_COLUMNS,
                                 chunk_rows=(n + len(vc_ids)) * STEPS_PER_CHUNK,
                                 labels=list(member_ids) + vc_ids, progress_column="t",
                                 derived=self.formation_of)
        # the members' signal columns (x .. friction_usage) are consecutive float64 columns
        self._sig_block = self.traj.block(SIGNAL_COLUMNS)
        self._sig_index = {name: j for j, name in enumerate(SIGNAL_COLUMNS)}
        self._floats = [c.name for c in TRAJECTORY_COLUMNS if c.dtype == "float64"]
        self._float_block = self.traj.block(self._floats)
        self._vc_at = np.array([self._floats.index(c) for c in _VC_COLUMNS], dtype=np.int64)
        self.codes = np.arange(n, dtype=np.int32)
        self.vc_code = n
        self.vc_codes = np.arange(n, n + len(vc_ids), dtype=np.int32)  # one per formation
        self.events = ChunkedTable(out_dir / "events.parquet", EVENT_COLUMNS, chunk_rows=2000, labels=[""],
                                   derived=self.formation_of)
        self.background = None
        self.member_ids = list(member_ids)
        self._out_of_range = np.zeros(n, dtype=bool)
        if with_sumo:
            self.background = ChunkedTable(out_dir / "background.parquet", BACKGROUND_COLUMNS,
                                           chunk_rows=BACKGROUND_CHUNK_ROWS)
        self.event_counts: dict[str, int] = {}
        self.incident_log = IncidentLog(self.formation_of)  # who, when, where (sim/incident_log.py)
        self.incidents = None  # sim/incidents.py Incidents: set by the runner (runner.py)
        self.ssm = None  # record.ssm.SsmConverter: set by sumo/world.py when SUMO's SSM device is on
        self._latest: dict[str, float] = {}
        self._reported = -np.inf
        self._fast_init(n)

    def _fast_init(self, n: int) -> None:
        """Views and constants of the one-write-per-block paths (:meth:`add_step`,
        :meth:`add_periods`, :meth:`add_background`)."""
        self._extra_block = self.traj.block(FILLED_BY_CALLER[2:])
        if FILLED_BY_CALLER[2:] != _ROAD_COLUMNS:
            raise ValueError("sim/record_rows.py road_rows writes the columns of _ROAD_COLUMNS")
        self._nan_row = np.full(n, np.nan)  # a road column the world does not supply
        self._all = np.ones(n, dtype=np.bool_)
        ix = self._sig_index
        self._v_at, self._acc = ix["v"], slice(ix["a_lon"], ix["a_lat"] + 1)  # a_lon, a_lat follow
        if self._acc.stop - self._acc.start != 2:
            raise ValueError("a_lon and a_lat must be consecutive signal columns")
        self._all_in = np.ones(n, dtype=bool).tobytes()  # a mask with every member in the run
        self._sig_shape = (n, len(SIGNAL_COLUMNS))
        self._traj_ids = self.traj.column("vehicle_id")
        limits = dict(slip_front=MAX_SLIP, slip_rear=MAX_SLIP, friction_usage=MAX_FRICTION_USAGE,
                      v=MAX_SPEED)
        self._sig_limits = np.array([limits.get(c, np.inf) for c in SIGNAL_COLUMNS])
        self._any_out = False
        self._fixed_tables = [tb for name, tb in self.tables().items() if name != "ssm"]
        self.steps_per_chunk = STEPS_PER_CHUNK
        cf = self.comfort
        self._cf_t, self._cf_vals = cf.column("t"), cf.block(("v", "a_lon", "a_lat"))
        self._cf_ids = cf.column("vehicle_id")
        self._cf_block = cf.block([c.name for c in COMFORT_COLUMNS if c.dtype == "float64"])
        if self._floats[:len(SIGNAL_COLUMNS) + 1] != ["t", *SIGNAL_COLUMNS]:
            raise ValueError("member_signals writes t, then the signal columns, as table rows")
        bg = self.background
        if bg is not None:
            self._bg_floats = bg.block([c.name for c in BACKGROUND_COLUMNS if c.dtype == "float64"])
            self._bg_ints = bg.block([c.name for c in BACKGROUND_COLUMNS if c.dtype != "float64"])
            self._bg_key, self._bg_codes = ((), (), ()), None

    @property
    def buffers(self) -> TableBuffers:
        """The tables' buffers as the compiled step takes them (sim/table_records.py)."""
        bg = self.background is not None
        return TableBuffers(self._sig_limits, self._float_block, self._traj_ids, self._cf_block,
                            self._cf_ids, self._comfort_from, self._extra_block, self._vc_at,
                            self.vc_codes, self._bg_floats if bg else np.empty((0, 0)),
                            self._bg_ints if bg else np.empty((0, 0), dtype=np.int32))

    @property
    def any_out(self) -> bool:
        """A signal was beyond the recorder's limits at the last recorded step."""
        return self._any_out

    def tables(self) -> dict:
        """The run's tables by name (SSM only once SUMO has written its file)."""
        out = {"trajectories": self.traj, "comfort": self.comfort, "events": self.events}
        if self.background is not None:
            out["background"] = self.background
        if self.ssm is not None and self.ssm.table is not None:
            out["ssm"] = self.ssm.table
        return out

    def add_signal_rows(self, t, sig: np.ndarray, extra: dict, mask=None):
        """Record the members from the compiled path: ``sig`` is the (n, len(SIGNAL_COLUMNS))
        array of fleet.Fleet.signals (columns in trajectory order), ``extra`` the road and
        SUMO columns (s, d, lane_index, sumo_gap; (n,) arrays), ``mask`` the members still in
        the run."""
        self.flag_range(t, sig, mask)
        codes, active = self.codes, self._all
        if mask is not None and not mask.all():
            active = np.ascontiguousarray(mask, dtype=np.bool_)
            sig, codes = sig[mask], codes[mask]
        n = len(codes)
        tr = self.traj
        sl = tr.rows(n)
        self._sig_block[:, sl] = sig.T
        tr.column("t")[sl] = t
        tr.column("vehicle_id")[sl] = codes
        self._road_rows(extra, sl.start, active)
        tr.commit(n)

    def flag_range(self, t, sig: np.ndarray, mask=None) -> None:
        """A ``model_range`` event for every member (of ``mask``) whose signals (``sig`` as in
        :meth:`add_signal_rows`) left the model's range since the last call (slip, friction
        usage, speed)."""
        ix = self._sig_index
        slip = np.fmax(np.abs(sig[:, ix["slip_front"]]), np.abs(sig[:, ix["slip_rear"]]))
        self._flag_range(t, slip, sig[:, ix["friction_usage"]], sig[:, ix["v"]], mask)

    def add_comfort_rows(self, t, sig: np.ndarray, mask=None):
        """The members' speed and accelerations at one control period (``sig`` as in
        :meth:`add_signal_rows`) into ``comfort.parquet``."""
        codes = self.codes
        if mask is not None and not mask.all():
            sig, codes = sig[mask], codes[mask]
        n = len(codes)
        cf = self.comfort
        sl = cf.rows(n)
        cf.column("t")[sl] = t
        cf.column("vehicle_id")[sl] = codes
        for name, j in zip(("v", "a_lon", "a_lat"), self._comfort_from):
            cf.column(name)[sl] = sig[:, j]
        cf.commit(n)

    def add_comfort_periods(self, ts, vals: np.ndarray, mask=None):
        """The members' speed and accelerations at several control periods: ``vals``
        (len(ts), n, 3) holds v, a_lon, a_lat at times ``ts`` [s]; rows in the order of
        :meth:`add_comfort_rows` called once per period."""
        codes = self.codes
        if mask is not None and not mask.all():
            vals, codes = vals[:, mask], codes[mask]
        m, n = len(ts), len(codes)
        cf = self.comfort
        if cf.rows_buffered + m * n > cf.chunk_rows:  # a part ends inside: one period at a time
            for j, t in enumerate(ts):
                self._comfort_block(cf, [t], vals[j:j + 1], codes)
            return
        self._comfort_block(cf, ts, vals, codes)

    def _comfort_block(self, cf, ts, vals, codes):
        m, n = vals.shape[0], vals.shape[1]
        sl = cf.rows(m * n)
        cf.column("t")[sl].reshape(m, n)[:] = np.array(ts)[:, None]
        cf.column("vehicle_id")[sl].reshape(m, n)[:] = codes
        for q, name in enumerate(("v", "a_lon", "a_lat")):
            cf.column(name)[sl].reshape(m, n)[:] = vals[:, :, q]
        cf.commit(m * n)

    def signal_rows(self, mask) -> SignalRows | None:
        """Where sim/fleet.py member_signals writes the members' rows of the step itself
        (Fleet.signals_into; then :meth:`add_step` with ``written``), or None when it must
        not: a member out of the run (``mask``), a signal out of range at the step before
        (events), or a part ends inside the step."""
        n, tr, cf = len(self.codes), self.traj, self.comfort
        at, c_at = tr.rows_buffered, cf.rows_buffered
        if (self._any_out or at + n + len(self.vc_codes) > tr.chunk_rows or c_at + n > cf.chunk_rows
                or (mask is not None and mask.tobytes() != self._all_in)):
            return None
        return SignalRows(self._sig_limits, self._float_block, self._traj_ids, at, self._cf_block,
                          self._cf_ids, c_at, self._comfort_from)

    def add_step(self, t, sig: np.ndarray, extra: dict, mask, truth: np.ndarray,
                 written: bool = False) -> None:
        """The rows of one recorded step at t [s]: what :meth:`add_signal_rows` (t, sig, extra,
        mask), :meth:`add_comfort_rows` (t, sig, mask) and :meth:`add_vc` (t, the virtual car
        ``truth`` = Reference.truth, its s; (k, 8) with k formations: one row for each virtual
        car) write in that order, with one write per block of columns; ``written``: member_signals wrote the members' signal rows already (at
        :meth:`signal_rows`). Those three calls do it when a member is out of the run, a
        signal is (or was) out of range (events) or a part ends inside the step."""
        n, tr, cf = len(self.codes), self.traj, self.comfort
        at, c_at = tr.rows_buffered, cf.rows_buffered
        e, blk = at + n, self._float_block
        if not written:
            if (sig.shape != self._sig_shape or beyond_limits(sig, self._sig_limits)
                    or self.signal_rows(mask) is None):
                self.add_signal_rows(t, sig, extra, mask)
                self.add_comfort_rows(t, sig, mask)
                self.add_vcs(t, truth)
                return
            self._sig_block[:, at:e] = sig.T
            blk[0, at:e] = t
            self._traj_ids[at:e] = self.codes
            self._cf_t[c_at:c_at + n] = t
            self._cf_vals[0, c_at:c_at + n] = sig[:, self._v_at]
            self._cf_vals[1:, c_at:c_at + n] = sig[:, self._acc].T
            self._cf_ids[c_at:c_at + n] = self.codes
        self._road_rows(extra, at, self._all)
        # one row per virtual car on the road (a NaN row: its formation is parked)
        tr.commit(n + vc_rows(blk, self._traj_ids, e, self._vc_at, self.vc_codes, float(t),
                              _rows(truth)))
        cf.commit(n)

    def _road_rows(self, extra: dict, at: int, active: np.ndarray) -> int:
        """The road and SUMO columns (FILLED_BY_CALLER[2:]) of ``extra``'s (n,) arrays (NaN for a
        column ``extra`` lacks: free space, or a road step before the members are in SUMO) of
        the members with ``active``, from table row ``at`` (sim/record_rows.py road_rows)."""
        n, nan = len(self.codes), self._nan_row
        vals = [extra.get(name, nan) for name in _ROAD_COLUMNS]
        for q, v in enumerate(vals):
            if (type(v) is not np.ndarray or v.dtype != np.float64 or v.shape != (n,)
                    or not v.flags.c_contiguous):  # a scalar, integers, a view: as a float64 row
                vals[q] = np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)))
        return road_rows(self._extra_block, at, *vals, active)

    def period_rows(self, m: int, mask) -> tuple | None:
        """Where sim/fleet.py step_members writes control periods 1 .. m - 1 of the step
        itself (Fleet.step; then :meth:`add_periods` with ``written``), or None when it must
        not: one period only, a member out of the run or a part ends inside the step."""
        at, cf = self.comfort.rows_buffered, self.comfort
        if (m < 2 or (mask is not None and mask.tobytes() != self._all_in)
                or at + (m - 1) * len(self.codes) > cf.chunk_rows):
            return None
        return self._cf_block, self._cf_ids, at

    def add_periods(self, t, dt, vals: np.ndarray, mask=None, written: bool = False) -> None:
        """Control periods 1 .. m-1 of a step starting at t [s] with periods of dt [s]:
        ``vals`` (m, n, 3) from sim/fleet.py step_members. ``written``: step_members wrote
        them already, at :meth:`period_rows` (commit them); else as :meth:`add_comfort_periods`
        ([t + j dt for j = 1 .. m-1], vals[1:], mask)."""
        m = vals.shape[0]
        if written:
            self.comfort.commit((m - 1) * len(self.codes))
        elif m > 1:
            self.add_comfort_periods([t + j * dt for j in range(1, m)], vals[1:], mask)

    def _flag_range(self, t, slip, usage, v, mask):
        bad = (slip > MAX_SLIP) | (usage > MAX_FRICTION_USAGE) | (v > MAX_SPEED)
        if mask is not None:
            bad &= mask
        if bad.any():
            for i in np.flatnonzero(bad & ~self._out_of_range):
                self.add_event(t, "model_range", self.member_ids[i], "",
                               f"slip {np.degrees(slip[i]):.1f} deg, friction usage {usage[i]:.2f}, "
                               f"v {v[i]:.1f} m/s")
        self._out_of_range = bad
        self._any_out = bool(bad.any())

    def add_vcs(self, t, truth: np.ndarray) -> None:
        """One row per virtual car of ``truth`` ((8,) or (k, 8), Reference.truth) that is on the
        road (a NaN row: a formation waiting to depart or retired, sim/loop.py parked)."""
        truth, tr = _rows(truth), self.traj
        for f in range(min(len(truth), len(self.vc_codes))):
            if truth[f, 0] == truth[f, 0]:
                sl = tr.rows(1)
                vc_row(self._float_block, sl.start, self._vc_at, float(t), truth[f])
                self._traj_ids[sl.start] = self.vc_codes[f]
                tr.commit(1)

    def add_vc(self, t, vc, s=np.nan, code: int | None = None):
        """One row for a virtual car (``vc``: its LeaderState, ``s`` its arc length [m];
        ``code``: its vehicle_id code, default the first formation's); the member-only columns
        stay NaN (sim/record_rows.py vc_row)."""
        tr = self.traj
        sl = tr.rows(1)
        vc_row(self._float_block, sl.start, self._vc_at, float(t),
               np.array([vc.x, vc.y, vc.theta, vc.v, vc.omega, vc.v_dot, np.nan, s], dtype=np.float64))
        self._traj_ids[sl.start] = self.vc_code if code is None else code
        tr.commit(1)

    def add_event(self, t, kind, vehicle_id, other_id="", detail="", value=None):
        """One row of events.parquet; an incident kind (sim/incident_log.py) is also logged
        with ``value`` (its clearance, deceleration, ...)."""
        ev = self.events
        ev.append({"t": t, "kind": ev.code(kind), "vehicle_id": ev.code(vehicle_id),
                   "other_id": ev.code(other_id), "detail": ev.code(detail)}, 1)
        self.event_counts[kind] = self.event_counts.get(kind, 0) + 1
        if kind in INCIDENT_EVENT_KINDS:
            self.incident_log.add(t, kind, vehicle_id, other_id, value)

    def add_background(self, t, nb, s, d):
        """SUMO's vehicles near the formation at t [s] (``nb``: sumo/types.py Neighbours,
        ``s``, ``d`` their Frenet coordinates [m]): one write per block of columns; the
        string columns' codes are reused while the vehicles, their types and lanes are those
        of the step before (the usual step)."""
        n = len(nb.ids)
        if n == 0:
            return
        bg = self.background
        at = bg.rows_buffered
        if at + n > bg.chunk_rows:  # a part ends inside: the rows split over two parts
            self._append_background(t, nb, s, d)
            return
        codes = self.background_codes(nb.ids, nb.types, nb.lane_ids)
        background_rows(self._bg_floats, self._bg_ints, at, float(t), (nb.x, nb.y, nb.heading),
                        (nb.v, nb.a, nb.length, nb.width), (s, d), codes, nb.lane_index)
        bg.commit(n)

    def background_codes(self, ids, types, lane_ids) -> np.ndarray:
        """The background table's codes (3, m) of the vehicles ``ids``, their ``types`` and
        lanes, reused while they are those of the last call (the usual step)."""
        key = self._bg_key
        if not (ids == key[0] and types == key[1] and lane_ids == key[2]):
            bg = self.background
            self._bg_key = (list(ids), list(types), list(lane_ids))
            self._bg_codes = np.array([bg.codes(ids), bg.codes(types), bg.codes(lane_ids)])
        return self._bg_codes

    def _append_background(self, t, nb, s, d):
        """:meth:`add_background` written out column by column (ChunkedTable.append)."""
        bg = self.background
        bg.append({
            "t": t, "vehicle_id": bg.codes(nb.ids), "type": bg.codes(nb.types),
            "x": nb.x, "y": nb.y, "heading": nb.heading, "v": nb.v, "a": nb.a,
            "length": nb.length, "width": nb.width, "lane": bg.codes(nb.lane_ids),
            "lane_index": nb.lane_index.astype(np.int32), "s": s, "d": d}, len(nb.ids))


def _rows(truth: np.ndarray) -> np.ndarray:
    """Reference.truth ((8,) or (k, 8)) as a contiguous float64 (k, 8) array."""
    return np.ascontiguousarray(truth.reshape(-1, 8) if truth.ndim == 1 else truth, dtype=np.float64)
