"""The C++ extension of sumo/adapter/native_reads.py against libsumo's SWIG results, in a real SUMO: the
members' and neighbours' tables bit for bit at every step, the moves (and the refused ones,
with SWIG's message), the cached build, the switch. The extension must build here (CI has gcc
and Python's headers): a machine where it does not fails these tests, it does not skip them.

One SUMO in this process (libsumo.start once, module fixture); the builds run in subprocesses.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import libsumo
import libsumo._libsumo as _ls
import numpy as np
import pytest

from formation_traci.sumo.adapter import native_reads

ROOT = Path(__file__).resolve().parents[1]
NET = ROOT / "sumo_nets" / "straight3.net.xml"
C = libsumo.constants
POS, ANG, SPD, ACC, LANE, LIDX = (C.VAR_POSITION, C.VAR_ANGLE, C.VAR_SPEED, C.VAR_ACCELERATION,
                                  C.VAR_LANE_ID, C.VAR_LANE_INDEX)
LAT, LPOS = C.VAR_LANEPOSITION_LAT, C.VAR_LANEPOSITION
MEMBERS = ["m0", "m1", "m2", "m3", "m4"]
SLOTS = [(0.0, 1), (-20.0, 0), (-40.0, 1), (-60.0, 0), (-80.0, 1)]  # (along [m], lane): lane 2 free
LANE_Y = [-8.75, -5.25, -1.75]
DT, SPEED, KEEP, THRESHOLD = 0.1, 20.0, 1, 5.0  # the flows (~33 m/s) overtake on lane 2
OWNERS = ["m0", "m4"]  # context subscriptions (overlapping: a vehicle in both once)


def _routes(path: Path) -> Path:
    types = ['type="car" ', "", ""]  # two vTypes among the neighbours
    flows = "".join(
        f'  <flow id="f{ln}" {types[ln]}route="r" begin="0" end="1000" vehsPerHour="1500" departLane="{ln}" '
        f'departSpeed="max" departPos="base"/>\n' for ln in range(3))
    path.write_text('<routes>\n  <vType id="member" length="4.5" width="1.8" maxSpeed="40" sigma="0"/>\n'
                    '  <vType id="car" length="5.2" width="2.0" sigma="0.5"/>\n'
                    f'  <route id="r" edges="entry main"/>\n{flows}</routes>\n')
    return path


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """The extension (it must load) and a running SUMO with the five members on entry."""
    mod = native_reads.load(_ls.__file__)
    assert mod is not None, f"the extension did not load: {native_reads.REASON}"
    assert mod.info()["object"] == _ls.__file__
    mod.clear()
    rou = _routes(tmp_path_factory.mktemp("native") / "r.rou.xml")
    libsumo.start(["sumo", "-n", str(NET), "-r", str(rou), "--step-length", str(DT), "--no-step-log",
                   "true", "--no-warnings", "true", "--seed", "7", "--collision.action", "warn"])
    try:
        for vid, (along, ln) in zip(MEMBERS, SLOTS):  # before the flows block the entry
            libsumo.vehicle.add(vid, "r", "member", depart="now", departLane=str(ln),
                                departPos=str(240.0 + along), departSpeed=str(SPEED))
            libsumo.vehicle.setSpeedMode(vid, 0)
            libsumo.vehicle.setLaneChangeMode(vid, 0)
            libsumo.vehicle.setSpeed(vid, SPEED)
            libsumo.vehicle.subscribe(vid, [POS, ANG, LANE, LIDX, LAT, LPOS])
        for _ in range(100):  # warm-up: the flows close up from behind
            libsumo.simulationStep()
        for owner, radius in zip(OWNERS, (200.0, 100.0)):
            libsumo.vehicle.subscribeContext(owner, C.CMD_GET_VEHICLE_VARIABLE, radius,
                                             [POS, ANG, SPD, ACC, LANE, LIDX])
        libsumo.simulationStep()
        yield mod
    finally:
        libsumo.close()
        mod.clear()


# ---- the SWIG path + the Python extraction (sumo/adapter/member_reads.py, sumo/adapter/neighbours.py) ---------
def swig_members(ids):
    res = _ls.vehicle_getAllSubscriptionResults()
    rows = [res.get(vid) for vid in ids]
    if not all(rows):
        return None
    tb = np.array([(*r[POS], r[ANG], r[LAT], r[LPOS]) for r in rows], dtype=float).reshape(-1, 5)
    return tb, [r[LANE] for r in rows], [r[LIDX] for r in rows]


BODIES: dict = {}


def swig_neighbours(exclude):
    ctx = _ls.vehicle_getAllContextSubscriptionResults()
    rows = {}
    for part in ctx.values():
        rows.update(part)
    ids = sorted(vid for vid in rows if vid not in exclude)
    if not ids:
        return None
    recs = [rows[vid] for vid in ids]
    for vid in ids:
        if vid not in BODIES:
            BODIES[vid] = (_ls.vehicle_getLength(vid), _ls.vehicle_getWidth(vid), _ls.vehicle_getTypeID(vid))
    bods = [BODIES[vid] for vid in ids]
    tb = np.array([(*r[POS], r[ANG], r[SPD], r[ACC], b[0], b[1]) for r, b in zip(recs, bods)], dtype=float)
    return (ids, [b[2] for b in bods], [r[LANE] for r in recs], tb,
            np.array([r[LIDX] for r in recs], dtype=np.int64))


def same_array(a, b):
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


def assert_same_members(native, swig):
    assert (native is None) == (swig is None)
    if swig is not None:
        assert same_array(native[0], swig[0]) and native[0].flags.c_contiguous
        assert native[1] == swig[1] and native[2] == swig[2]
        assert all(type(k) is int for k in native[2])


def assert_same_neighbours(native, swig):
    assert (native is None) == (swig is None)
    if swig is not None:
        assert native[:3] == swig[:3]
        assert same_array(native[3], swig[3]) and same_array(native[4], swig[4])


def swig_refusal(vid, x, y, angle):
    with pytest.raises(libsumo.TraCIException) as exc:
        _ls.vehicle_moveToXY(vid, "", -1, x, y, angle, KEEP, THRESHOLD)
    return str(exc.value)


# ---- the tests --------------------------------------------------------------------------------
def test_tables_and_moves_equal_swig_at_every_step(sim):
    mod = sim
    along = np.array([a for a, _ in SLOTS])
    ys = np.array([LANE_Y[ln] for _, ln in SLOTS])
    angle, v, a = np.full(5, 90.0), np.full(5, SPEED), np.zeros(5)
    v_list, a_list = v.tolist(), a.tolist()
    members = dict.fromkeys(MEMBERS, True)
    xf = swig_members(MEMBERS)[0][0, 0]
    xs = None  # the x of the last moves
    times = {k: [] for k in ("swig_members", "native_members", "swig_neighbours", "native_neighbours",
                             "swig_moves", "native_moves")}
    rows, pc = [], time.perf_counter_ns
    for k in range(200):
        libsumo.simulationStep() if k % 2 == 0 else mod.step()
        exclude = members if k % 3 else set(MEMBERS)
        calls = [("swig_members", swig_members, (MEMBERS,)), ("native_members", mod.member_table, (MEMBERS,)),
                 ("swig_neighbours", swig_neighbours, (exclude,)),
                 ("native_neighbours", mod.neighbour_table, (OWNERS, exclude))]
        got = {}
        for name, fn, args in (calls if k % 2 else calls[1::-1] + calls[:1:-1]):  # either goes first
            t0 = pc()
            got[name] = fn(*args)
            times[name].append(pc() - t0)
        assert_same_members(got["native_members"], got["swig_members"])
        assert_same_neighbours(got["native_neighbours"], got["swig_neighbours"])
        rows.append(0 if got["swig_neighbours"] is None else len(got["swig_neighbours"][0]))
        if xs is not None:  # the last moves took effect in this SUMO
            np.testing.assert_allclose(got["native_members"][0][:, 0], xs, atol=1e-6)
            np.testing.assert_allclose(got["native_members"][0][:, 1], ys, atol=1e-6)
        if k % 10 == 5:  # the copies of getAll*SubscriptionResults give the same
            mod.use_store(False)
            assert_same_members(mod.member_table(MEMBERS), got["swig_members"])
            assert_same_neighbours(mod.neighbour_table(OWNERS, exclude), got["swig_neighbours"])
            mod.use_store(True)
        if k == 100:  # a neighbour leaves; its body stays cached until forgotten
            gone = got["swig_neighbours"][0][0]
            libsumo.vehicle.remove(gone)
        xf += SPEED * DT
        xs = xf + along
        t0 = pc()
        if k % 2:
            refused = mod.move_all(MEMBERS, xs, ys, angle, KEEP, THRESHOLD)
            mod.set_previous_speeds(MEMBERS, v, a)
            times["native_moves"].append(pc() - t0)
            assert refused == []
        else:
            poses = zip(MEMBERS, xs.tolist(), ys.tolist(), angle.tolist(), v_list, a_list)
            for vid, x, y, h, vv, aa in poses:
                _ls.vehicle_moveToXY(vid, "", -1, x, y, h, KEEP, THRESHOLD)
                _ls.vehicle_setPreviousSpeed(vid, vv, aa)
            times["swig_moves"].append(pc() - t0)
    assert sum(r > 0 for r in rows) > 150 and max(rows) > 5, rows
    bodies = mod.bodies()
    assert bodies == {vid: BODIES[vid] for vid in bodies} and set(bodies) == set(BODIES)
    assert gone in bodies and gone not in _ls.vehicle_getIDList()
    mod.forget([gone, "never-seen"])
    assert gone not in mod.bodies()
    med = {k: np.median(t) / 1000.0 for k, t in times.items()}
    print(f"\nper call [us], median over the steps, {np.mean(rows):.1f} neighbours: "
          + ", ".join(f"{k} {t:.1f}" for k, t in med.items()))


def _m4_leaves() -> None:
    """Member m4 (a context owner) leaves the run, once, as sumo/adapter/__init__.py removes one: each
    test that needs it gone says so (a test selected alone with -k passes too)."""
    if "m4" not in libsumo.vehicle.getIDList():
        return
    libsumo.vehicle.unsubscribeContext("m4", C.CMD_GET_VEHICLE_VARIABLE, 100.0)  # as sumo/adapter/__init__.py
    libsumo.vehicle.unsubscribe("m4")  # does: else libsumo 1.28's next step fails
    libsumo.vehicle.remove("m4")  # an owner: neighbour_table skips an owner without results
    libsumo.simulationStep()


def test_a_member_that_left(sim):
    mod = sim
    _m4_leaves()
    assert mod.member_table(MEMBERS) is None and swig_members(MEMBERS) is None
    assert_same_members(mod.member_table(MEMBERS[:4]), swig_members(MEMBERS[:4]))
    assert_same_neighbours(mod.neighbour_table(OWNERS, set(MEMBERS)), swig_neighbours(set(MEMBERS)))
    mod.set_previous_speeds(MEMBERS, np.full(5, SPEED), np.zeros(5))  # m4 skipped silently
    assert mod.member_table([])[0].shape == (0, 5) and mod.neighbour_table([], None) is None


def swig_all(exclude):
    """sumo/adapter/neighbours.py's SWIG extraction of every vehicle's variable subscription."""
    rows = {vid: r for vid, r in _ls.vehicle_getAllSubscriptionResults().items() if r}
    ids = sorted(vid for vid in rows if vid not in exclude)
    if not ids:
        return None
    for vid in ids:
        if vid not in BODIES:
            BODIES[vid] = (_ls.vehicle_getLength(vid), _ls.vehicle_getWidth(vid), _ls.vehicle_getTypeID(vid))
    recs, bods = [rows[vid] for vid in ids], [BODIES[vid] for vid in ids]
    tb = np.array([(*r[POS], r[ANG], r[SPD], r[ACC], b[0], b[1]) for r, b in zip(recs, bods)], dtype=float)
    return (ids, [b[2] for b in bods], [r[LANE] for r in recs], tb,
            np.array([r[LIDX] for r in recs], dtype=np.int64))


def test_every_vehicles_table_equals_swig_at_every_step(sim):
    """all_table(exclude): every vehicle subscribed with the neighbours' variables (a twin, or a
    run that records every vehicle), as neighbour_table's rows, bit for bit against the SWIG
    extraction at every step while vehicles enter, members are excluded and one leaves."""
    mod = sim
    seen, subscribed = [], set()
    for k in range(60):
        for vid in set(_ls.vehicle_getIDList()) - set(MEMBERS) - subscribed:
            _ls.vehicle_subscribe(vid, [POS, ANG, SPD, ACC, LANE, LIDX])
            subscribed.add(vid)
        libsumo.simulationStep() if k % 2 == 0 else mod.step()
        exclude = set(MEMBERS) if k % 3 else dict.fromkeys(MEMBERS, True)
        want = swig_all(exclude)
        assert_same_neighbours(mod.all_table(exclude), want)
        if k % 10 == 5:
            mod.use_store(False)
            assert_same_neighbours(mod.all_table(exclude), want)
            mod.use_store(True)
        if k == 30:  # one leaves, as sumo/adapter/__init__.py removes a vehicle
            _ls.vehicle_unsubscribe(want[0][0])
            libsumo.vehicle.remove(want[0][0])
            subscribed.discard(want[0][0])
        seen.append(0 if want is None else len(want[0]))
    for vid in subscribed & set(_ls.vehicle_getIDList()):  # the other tests read no such rows
        _ls.vehicle_unsubscribe(vid)
    assert min(seen) >= 10 and max(seen) > min(seen), seen  # vehicles read; some entered


def test_poses_are_the_getters_values(sim):
    """poses(ids): every vehicle's getPosition, getAngle, getLength, getWidth, bit for bit (the
    insertion room check's reads); an unknown vehicle is SUMO's error, as through SWIG."""
    mod = sim
    ids = list(_ls.vehicle_getIDList())
    assert len(ids) >= 10
    want = np.array([(*_ls.vehicle_getPosition(v), _ls.vehicle_getAngle(v), _ls.vehicle_getLength(v),
                      _ls.vehicle_getWidth(v)) for v in ids], dtype=float).reshape(-1, 5)
    assert same_array(mod.poses(ids), want)
    assert len(set(want[:, 3])) > 1  # several bodies read
    assert mod.poses([]).shape == (0, 5)
    with pytest.raises(libsumo.TraCIException):
        mod.poses(ids[:1] + ["nope"])


def test_refused_moves_carry_swigs_message(sim):
    mod = sim
    _m4_leaves()
    tb = mod.member_table(["m1", "m2"])[0]
    far = (1e5, 500.0, 90.0)
    expected = [("m1", swig_refusal("m1", *far)), ("nope", swig_refusal("nope", 300.0, -5.25, 90.0)),
                ("m4", swig_refusal("m4", 300.0, -5.25, 90.0))]
    assert "nope" in expected[1][1] and "m1" in expected[0][1]
    x2 = tb[1, 0] + SPEED * DT
    refused = mod.move_all(["m1", "nope", "m2", "m4"], [far[0], 300.0, x2, 300.0],  # lists or arrays
                           [far[1], -5.25, tb[1, 1], -5.25], np.full(4, 90.0), KEEP, THRESHOLD)
    assert refused == expected
    libsumo.simulationStep()
    assert abs(mod.member_table(["m2"])[0][0, 0] - x2) < 1e-6  # the refusals stopped no other move


def test_switched_off(monkeypatch):
    monkeypatch.setenv(native_reads.ENV, "off")
    assert native_reads.load(_ls.__file__) is None
    assert "off" in native_reads.REASON


# ---- builds in fresh processes ----------------------------------------------------------------
CHILD = """
import json, time
import libsumo._libsumo as sw
from formation_traci.sumo.adapter import native_reads as nr
t = time.perf_counter()
m = nr.load(sw.__file__)
print(json.dumps({"ok": m is not None, "reason": nr.REASON, "file": getattr(m, "__file__", None),
                  "seconds": time.perf_counter() - t, "object": m.info()["object"] if m else None}))
"""


def _child(env, **extra):
    env = {**env, **extra}
    return subprocess.Popen([sys.executable, "-c", CHILD], env=env, cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _result(proc):
    out, err = proc.communicate(timeout=180)
    assert proc.returncode == 0, err
    return {**json.loads(out.strip().splitlines()[-1]), "stderr": err}


@pytest.fixture
def env(tmp_path):
    """The environment of a child, and a compiler that answers --version like the real one but
    fails (and writes a log) when it is asked to compile."""
    real = os.environ.get("CXX") or shutil.which("g++") or shutil.which("c++")
    assert real, "no C++ compiler"
    fake = tmp_path / "fake-cxx"
    fake.write_text(f'#!/bin/sh\nif [ "$1" = "--version" ]; then exec {real} --version; fi\n'
                    f'echo "$@" >> "{tmp_path / "fake.log"}"\nexit 1\n')
    fake.chmod(0o755)
    base = {k: v for k, v in os.environ.items() if k != native_reads.ENV}
    return base, str(fake), tmp_path / "fake.log"


def test_concurrent_first_builds_then_a_cached_load_without_compiler(env, tmp_path):
    base, fake, log = env
    cache = tmp_path / "cache"
    first = [_child(base, FORMATION_TRACI_CACHE=str(cache)) for _ in range(2)]
    built = [_result(p) for p in first]
    assert all(b["ok"] for b in built), built
    assert all(b["object"].endswith("_libsumo.so") for b in built)
    files = sorted(p.name for p in (cache / "native").iterdir())
    assert len(files) == 1 and files[0].startswith("_sumo_reads-"), files  # no temporary left
    again = _result(_child(base, FORMATION_TRACI_CACHE=str(cache), CXX=fake))
    assert again["ok"] and Path(again["file"]).name == files[0] and not log.exists(), again
    # a build announces itself with its bound and says how long it took; a cached load is silent
    assert any(native_reads.NOTICE in b["stderr"] and f"at most {native_reads.TIMEOUT:.0f} s" in b["stderr"]
               and "the C++ reads built in" in b["stderr"] for b in built), [b["stderr"] for b in built]
    assert native_reads.NOTICE not in again["stderr"], again["stderr"]
    print(f"\nfirst builds {[round(b['seconds'], 2) for b in built]} s, cached load {again['seconds']:.3f} s")
    fresh = _result(_child(base, FORMATION_TRACI_CACHE=str(tmp_path / "empty"), CXX=fake))
    assert not fresh["ok"] and "build failed" in fresh["reason"] and log.exists()  # the fake is asked


def test_cache_off_builds_in_a_temporary_directory(env):
    base, fake, log = env
    off = _result(_child(base, FORMATION_TRACI_CACHE="off"))
    assert off["ok"], off
    assert not Path(off["file"]).exists()  # imported, then deleted
    none = _result(_child(base, FORMATION_TRACI_CACHE="off", CXX=fake))
    assert not none["ok"] and log.exists()
    missing = _result(_child(base, FORMATION_TRACI_CACHE="off", CXX=str(Path(fake).with_name("no-cxx"))))
    assert not missing["ok"] and missing["reason"], missing
