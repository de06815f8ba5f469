"""The recorded run's contract: what a run directory holds and the rules for writing it.

``columns`` names the tables' columns (dtypes, units), ``rundir`` the run directory itself
(the names the tool writes, ``--force``, the writer's lock, atomic writes), ``errors`` the
error of a sweep file or sweep directory that cannot be used. The simulator
(``formation_traci``) writes by these rules and the analysis (``analysis``) reads by them;
this package imports neither.
"""
