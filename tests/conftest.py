"""Test setup: tests/ importable, for the shared scaffolding in run_helpers.py."""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
