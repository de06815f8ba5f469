"""Versions for run.json and cache keys without importlib.metadata's start-up cost
(formation_traci/core/versions.py), and pyarrow imported only when the first part is written."""
from __future__ import annotations

import importlib.metadata as md
import platform
import subprocess
import sys
from pathlib import Path

import pytest

from formation_traci.run.scenario_run import RECORDED_DISTRIBUTIONS, versions
from formation_traci.core.versions import installed_versions, platform_name

ROOT = Path(__file__).resolve().parents[1]


def _metadata_version(dist: str) -> str:
    try:
        return md.version(dist)
    except md.PackageNotFoundError:
        return "not installed"


def test_installed_versions_are_importlib_metadatas():
    names = RECORDED_DISTRIBUTIONS + ("dask", "distributed", "numba", "no-such-distribution")
    got = installed_versions(names)
    assert got == {d: _metadata_version(d) for d in names}
    assert got["no-such-distribution"] == "not installed"


def _fake_dist(site: Path, dirname: str, version: str) -> None:
    d = site / dirname
    d.mkdir(parents=True)
    (d / "METADATA").write_text(f"Metadata-Version: 2.1\nName: fake-dist\nVersion: {version}\n")


def test_the_first_dist_info_on_sys_path_wins_with_the_names_normalised(tmp_path, monkeypatch):
    _fake_dist(tmp_path / "a", "Fake_Dist-1.2.3.dist-info", "1.2.3")
    _fake_dist(tmp_path / "b", "fake_dist-9.9.dist-info", "9.9")
    monkeypatch.setattr(sys, "path", [str(tmp_path / "a"), str(tmp_path / "b")] + sys.path)
    assert installed_versions(("fake-dist",)) == {"fake-dist": "1.2.3"} == {"fake-dist": md.version("fake-dist")}


def _platform_without_processor() -> str:
    text, u = platform.platform(), platform.uname()
    if u.processor and u.processor not in ("unknown", u.machine):
        text = text.replace(f"-{u.processor}-", "-", 1)
    return text


def test_an_egg_info_first_on_sys_path_is_read_as_importlib_metadata_reads_it(tmp_path, monkeypatch):
    egg = tmp_path / "a" / "fake_dist.egg-info"
    egg.mkdir(parents=True)
    (egg / "PKG-INFO").write_text("Metadata-Version: 2.1\nName: fake-dist\nVersion: 3.0\n")
    _fake_dist(tmp_path / "b", "fake_dist-9.9.dist-info", "9.9")
    monkeypatch.setattr(sys, "path", [str(tmp_path / "a"), str(tmp_path / "b")] + sys.path)
    assert installed_versions(("fake-dist",)) == {"fake-dist": "3.0"} == {"fake-dist": md.version("fake-dist")}


def test_platform_name_is_platforms_without_the_processor():
    assert platform_name() == _platform_without_processor()


def test_run_json_versions():
    v = versions()
    assert v["python"] == platform.python_version() and v["platform"] == _platform_without_processor()
    assert all(v[d] == _metadata_version(d) for d in RECORDED_DISTRIBUTIONS)


FIRST_STEP = """
import json, sys, tempfile, threading
from pathlib import Path

importers = []
class Watch:  # records which thread imports pyarrow (finds nothing itself)
    def find_spec(self, name, path=None, target=None):
        if name == "pyarrow":
            importers.append(threading.current_thread().name)
        return None
sys.meta_path.insert(0, Watch())
from formation_traci.scenario import load_scenario
from formation_traci.sim.recorder import Recorder
from formation_traci.runner import run_scenario
seen = []
end_step = Recorder.end_step
def hook(self, k, t, report=None):
    end_step(self, k, t, report)
    if k == 1:
        seen.append(any(m == "pyarrow" or m.startswith("pyarrow.") for m in sys.modules))
Recorder.end_step = hook
path = sys.argv[1]
sc = load_scenario(path, **{"run.duration": 0.1})
out = Path(tempfile.mkdtemp()) / "run"
r = run_scenario(sc, out, scenario_path=path, progress=False)
import pandas as pd
n = len(pd.read_parquet(out / "trajectories.parquet"))
print(json.dumps({"status": r.status, "pyarrow_at_first_step": seen[0], "rows": n,
                  "importers": importers}))
"""


@pytest.mark.jit_off
def test_pyarrow_is_imported_by_the_writer_thread_and_the_tables_are_written():
    """pyarrow (~40-50 ms) is imported by the writer thread with the first part, not by the
    stepping thread and not before the run's first step (the tables are complete as before)."""
    path = ROOT / "scenarios" / "thesis" / "dynamic_case4_straight.toml"
    r = subprocess.run([sys.executable, "-c", FIRST_STEP, str(path)], capture_output=True, text=True,
                       cwd=ROOT, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    import json
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["status"] == "completed" and not got["pyarrow_at_first_step"]
    assert got["importers"] and all(t.startswith("parquet-writer") for t in got["importers"])
    assert got["rows"] == 3 * 4  # t = 0, 0.05, 0.1 (step 0.05 s): the 3 members and the virtual car
