"""formation-traci: highway formation control experiments inside SUMO traffic.

The physics and controllers follow ``shared/seed/formation_control_thesis.txt``; equation
numbers in docstrings refer to it. See docs/model.md for every equation and deviation.
"""
__version__ = "0.1.0"
