"""The road cache (sumo/road_cache.py) and the warm start without scipy (issue 18, set-up).

A run from a cached reference line is the run from a fitted one, bit for bit; a damaged
entry is rebuilt; a warm process (numba and road caches filled) loads neither scipy's fitting
modules nor numba's compiler registries.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import formation_traci.road.smoothing as smoothing
from formation_traci.road.geometry import ReferenceLine
from formation_traci.road.line_pack import packed
from formation_traci.scenario import load_scenario
from formation_traci.sumo import road_cache, road_setup
from formation_traci.sumo.road_setup import build_road
from formation_traci.runner import run_scenario
from sumo_nets import net_path

ROOT = Path(__file__).resolve().parents[1]
CURVED = ROOT / "scenarios" / "highway" / "curved_3lane.toml"
SHORT = {"run.duration": 2.0, "traffic.warmup": 5.0}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty road cache of this test, nothing kept in the process."""
    d = tmp_path / "road_cache"
    monkeypatch.setenv(road_cache.ENV, str(d))
    road_setup._REFERENCE_CACHE.clear()
    yield d
    road_setup._REFERENCE_CACHE.clear()


def _no_fit(*_a, **_k):
    raise AssertionError("the line was fitted although the cache holds it")


def _tables(out: Path) -> dict:
    """Every recorded table's columns as raw bytes (NaN and sign bits included)."""
    got = {}
    for p in sorted(out.rglob("*.parquet")):
        t = pq.read_table(p)
        for name in t.column_names:
            a = t.column(name).to_numpy(zero_copy_only=False)
            got[(p.name, name)] = a.tobytes() if a.dtype != object else repr(a.tolist())
    return got


def test_a_run_from_the_cached_line_is_the_run_from_the_fitted_line(cache, tmp_path, monkeypatch):
    sc = load_scenario(CURVED, **SHORT)
    r = run_scenario(sc, tmp_path / "cold", scenario_path=CURVED, progress=False)
    assert r.status == "completed", r.reason
    assert len(list(cache.glob("road-*.npz"))) == 1
    road_setup._REFERENCE_CACHE.clear()
    monkeypatch.setattr(smoothing, "fit_within", _no_fit)  # the warm run must read the entry
    r = run_scenario(sc, tmp_path / "warm", scenario_path=CURVED, progress=False)
    assert r.status == "completed", r.reason
    cold, warm = _tables(tmp_path / "cold"), _tables(tmp_path / "warm")
    assert cold.keys() == warm.keys() and len(cold) > 20
    assert [k for k in cold if cold[k] != warm[k]] == []
    meta = [json.loads((tmp_path / d / "run.json").read_text()) for d in ("cold", "warm")]
    assert [m["steps_done"] for m in meta] == [40, 40] and meta[0]["members"] == meta[1]["members"]


def test_the_cached_line_has_the_fitted_arrays_and_evaluates_the_same(cache):
    sc = load_scenario(CURVED)
    road = build_road(sc, CURVED)
    fitted = road.line
    road_setup._REFERENCE_CACHE.clear()
    again = build_road(sc, CURVED)
    cached = again.line
    assert again.fit == road.fit and road.fit["smoothing_length_m"] > 0
    assert again.segments == road.segments
    assert cached is not fitted and cached.length == fitted.length
    for name in ReferenceLine.ARRAYS:
        assert np.array_equal(getattr(cached, name), getattr(fitted, name)), name
    s = np.linspace(-20.0, fitted.length + 20.0, 2001)
    assert fitted.frame(s).position.tobytes() == cached.frame(s).position.tobytes()
    assert fitted.curvature(s).tobytes() == cached.curvature(s).tobytes()
    xy = fitted.from_frenet(s, 1.7)
    assert [a.tobytes() for a in fitted.to_frenet(xy)] == [a.tobytes() for a in cached.to_frenet(xy)]
    # scipy's objects are rebuilt from the arrays on demand, equal to the fit's
    u = np.linspace(0.0, 100.0, 11)
    assert np.array_equal(cached.curve(u), fitted.curve(u))
    assert np.array_equal(cached.u_of_s(s[:50]), fitted.u_of_s(s[:50]))


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other key"])
def test_a_damaged_entry_is_rebuilt_without_error(cache, damage):
    sc = load_scenario(CURVED)
    line = build_road(sc, CURVED).line
    (entry,) = cache.glob("road-*.npz")
    good = entry.read_bytes()
    if damage == "garbage":
        entry.write_bytes(b"not a cache entry")
    elif damage == "truncated":
        entry.write_bytes(good[: len(good) // 2])
    else:  # a valid file whose key is not this entry's
        with np.load(entry) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays["meta"]))
        meta["key"] = "0" * 64
        arrays["meta"] = np.array(json.dumps(meta))
        with open(entry, "wb") as f:
            np.savez(f, **arrays)
    road_setup._REFERENCE_CACHE.clear()
    again = build_road(sc, CURVED).line
    assert again.frame(np.arange(0.0, line.length, 7.0)).position.tobytes() == \
        line.frame(np.arange(0.0, line.length, 7.0)).position.tobytes()
    assert entry.read_bytes() == good  # rewritten whole
    assert [p.name for p in cache.iterdir()] == [entry.name]  # no temporary file left


def test_the_cache_directory(monkeypatch, tmp_path):
    monkeypatch.setenv(road_cache.ENV, "off")
    assert road_cache.cache_dir() is None
    monkeypatch.delenv(road_cache.ENV)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert road_cache.cache_dir() == tmp_path / "formation_traci"
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    if sys.platform.startswith("linux"):
        assert road_cache.cache_dir() == tmp_path / "xdg" / "formation-traci"


def test_the_oldest_entries_beyond_the_limit_are_dropped(cache, monkeypatch):
    monkeypatch.setattr(road_cache, "MAX_ENTRIES", 2)
    cache.mkdir()
    names = [f"road-{i:040x}.npz" for i in range(3)]  # entries of earlier runs, oldest first
    for i, name in enumerate(names):
        old = cache / name
        old.write_bytes(b"x")
        os.utime(old, ns=(10 ** 9 * (i + 1), 10 ** 9 * (i + 1)))
    foreign = cache / "road-mine.npz"  # not a name the cache writes: never deleted
    foreign.write_bytes(b"y")
    os.utime(foreign, ns=(1, 1))
    build_road(load_scenario(CURVED), CURVED)
    ours = sorted(p.name for p in cache.iterdir() if p != foreign)
    assert names[2] in ours and names[0] not in ours
    assert len(ours) == 2 and foreign.read_bytes() == b"y"


def test_an_unwritable_cache_is_skipped(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache directory would be")
    monkeypatch.setenv(road_cache.ENV, str(blocker / "cache"))
    road_setup._REFERENCE_CACHE.clear()
    line = build_road(load_scenario(CURVED), CURVED).line
    road_setup._REFERENCE_CACHE.clear()
    assert line.length > 100.0 and not (blocker / "cache").exists()


FIRST_STEP = """
import sys
from formation_traci.scenario import load_scenario
from formation_traci.runner import run_scenario
from sumo_nets import net_path
path, out, extra = sys.argv[1], sys.argv[2], eval(sys.argv[3])
sc = load_scenario(path, **{"run.duration": 0.25, **extra})  # a few compiled steps too
r = run_scenario(sc, out, scenario_path=path, progress=False, force=True)
assert r.status == "completed", r.reason
print(sorted(m for m in sys.modules if m.startswith(("scipy.", "numba.np.arraymath"))))
"""
HEAVY = ("scipy.interpolate", "scipy.sparse", "scipy.optimize", "scipy.special", "scipy.spatial",
         "scipy.linalg", "numba.np.arraymath")


def _first_step(path: Path, out: Path, env: dict, extra=None) -> list[str]:
    r = subprocess.run([sys.executable, "-c", FIRST_STEP, str(path), str(out), repr(extra or {})],
                       capture_output=True, text=True, env=env, cwd=out.parent, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    return eval(r.stdout.strip().splitlines()[-1])


def test_a_warm_start_imports_neither_scipy_nor_numbas_compiler(tmp_path):
    """A road run and a free-space run with warm caches read their line and load their
    kernels: scipy's fitting modules (0.4 s) and numba's lowering registries or its arraymath
    module with scipy.linalg (0.3 s) stay out, also once the compiled step has run (a kernel
    that calls numba's np.searchsorted loads arraymath with its first call). (On main before
    issue 18's start-up work a warm road run imported scipy.interpolate, .optimize, .sparse,
    .special and .linalg.)"""
    env = dict(os.environ, PYTHONPATH=str(ROOT), FORMATION_TRACI_CACHE=str(tmp_path / "cache"))
    road = ROOT / "scenarios" / "highway" / "straight_3lane_light.toml"
    no_warmup = {"traffic.warmup": 0.0}
    cold = _first_step(road, tmp_path / "r0", env, no_warmup)
    assert "scipy.interpolate" in cold  # the fit needs it
    warm = _first_step(road, tmp_path / "r1", env, no_warmup)
    assert [m for m in warm if m.startswith(HEAVY)] == []
    free = ROOT / "scenarios" / "thesis" / "dynamic_case4_straight.toml"
    _first_step(free, tmp_path / "f0", env)
    assert [m for m in _first_step(free, tmp_path / "f1", env) if m.startswith(HEAVY)] == []


WRITER = """
import sys
from pathlib import Path
from formation_traci.scenario import load_scenario
from formation_traci.sumo import road_cache, road_setup
from formation_traci.road.line_pack import packed
path = Path(sys.argv[1])
road = road_setup.build_road(load_scenario(path), path)  # fitted (or read) once
key = sys.argv[2]
for _ in range(int(sys.argv[3])):
    road_cache.store(key, ["a", "b"], road.line, packed(road.line), {"n": 1})
"""


def test_an_entry_rewritten_by_other_processes_always_reads_back_whole(cache):
    """The docstring's safety claim: while other processes (a sweep's cases starting
    together) write the same entry, a reader never sees a torn file, and no temporary file is
    left behind."""
    key = "f" * 64
    fitted = build_road(load_scenario(CURVED), CURVED).line
    road_cache.store(key, ["a", "b"], fitted, packed(fitted), {"n": 1})
    env = dict(os.environ, **{road_cache.ENV: str(cache)})
    procs = [subprocess.Popen([sys.executable, "-c", WRITER, str(CURVED), key, "40"], env=env,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    reads = torn = 0
    while any(p.poll() is None for p in procs):
        got = road_cache.load(key)
        reads += 1
        torn += got is None or got[0] != ["a", "b"]
    for p in procs:
        err = p.communicate()[1]
        assert p.returncode == 0, err[-2000:]
    assert reads > 0 and torn == 0
    got = road_cache.load(key)
    for name in ReferenceLine.ARRAYS:
        assert np.array_equal(getattr(got[1], name), getattr(fitted, name)), name
    assert [p.name for p in cache.iterdir() if not p.name.startswith("road-")] == []


@pytest.mark.parametrize("change", ["cpu", "sumolib", "road_setup"])
def test_the_key_changes_with_the_cpu_sumolib_and_the_code_that_stores_the_entry(monkeypatch, change):
    """A line fitted on another CPU kind (numpy's SIMD loops), read by another sumolib or
    stored by other set-up code is another entry (a cache may be shared by a cluster)."""
    args = (str(net_path("curved3")), ("main",), 1, 0.05, smoothing.FIT_SETTINGS)
    monkeypatch.setattr(road_cache, "_CODE_DIGEST", [])
    before = road_cache.entry_key(*args)
    monkeypatch.setattr(road_cache, "_CODE_DIGEST", [])
    if change == "cpu":
        monkeypatch.setattr(road_cache, "_cpu_features", lambda: "SSE2")
    elif change == "sumolib":
        real = road_cache.installed_versions
        monkeypatch.setattr(road_cache, "installed_versions",
                            lambda names: {**real(names), **({"sumolib": "0.0.1"} if "sumolib" in names else {})})
    else:
        real_read = Path.read_bytes
        monkeypatch.setattr(Path, "read_bytes", lambda self: real_read(self) + (
            b"# edited" if self.name == "road_setup.py" else b""))
    assert road_cache.entry_key(*args) != before
