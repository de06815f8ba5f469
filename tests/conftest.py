"""Test setup: tests/ importable, for the shared scaffolding in run_helpers.py; the road cache
(sumo/road_cache.py) of the session in a temporary directory, never the user's cache; a test
module's ``SESSION_START`` started when one of its tests is to run (long, self-contained work
of real processes that then runs beside the rest of the suite: test_startup_compile.py) and
its ``SESSION_END`` at the session's end."""
import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

if "FORMATION_TRACI_CACHE" not in os.environ:
    _ROAD_CACHE = tempfile.mkdtemp(prefix="formation-traci-road-cache-")
    os.environ["FORMATION_TRACI_CACHE"] = _ROAD_CACHE  # subprocesses of the tests too
    atexit.register(shutil.rmtree, _ROAD_CACHE, ignore_errors=True)


def _session_hooks(session, name: str):
    """The distinct ``name`` functions of the modules of the tests to run."""
    seen = []
    for item in session.items:
        fn = getattr(getattr(item, "module", None), name, None)
        if fn is not None and fn not in seen:
            seen.append(fn)
    return seen


def pytest_collection_finish(session):
    if session.config.option.collectonly:
        return
    for start in _session_hooks(session, "SESSION_START"):
        start()


def pytest_sessionfinish(session):
    for stop in _session_hooks(session, "SESSION_END"):
        stop()
