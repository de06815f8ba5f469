"""Test setup: tests/ importable, for the shared scaffolding in run_helpers.py; the road cache
(sumo/road_cache.py) of the session in a temporary directory, never the user's cache."""
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
