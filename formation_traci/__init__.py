"""formation-traci: highway formation control experiments inside SUMO traffic.

The physics and controllers follow ``shared/seed/formation_control_thesis.txt``; equation
numbers in docstrings refer to it. See docs/model.md for every equation and deviation.
"""
__version__ = "0.1.0"

import os as _os
import sys as _sys

if _sys.argv[:1] == ["-m"] or _os.path.basename(_sys.argv[0] if _sys.argv else "") == "formation-traci":
    # started as a command (python -m formation_traci.X, or the console script): from this first
    # moment SIGINT/SIGTERM end it with exit 130 (each command installs its own handling later)
    from .core.interrupt import exit_130_on_signals as _early

    _early()
