"""One kernel compilation covers every scenario kind.

numba compiles a kernel when it is first called, and some kernels are called only by some
scenario kinds: the maneuver planner's slots (control/maneuvers/transition.py), the [comm]
channel (comm/link.py), the free-space virtual car (control/reference_free.py) and compiled
step (sim/free_step.py), and some only on rare steps: the recorder's rows of a step whose part
file ends inside it (sim/record_rows.py). A process that
has compiled kernels (a cold cache: kernels.py printed its notice) therefore also compiles
these, on empty inputs of the types a run passes, before it ends: the next maneuver, comm or
free-space run loads them from the cache instead of compiling again. A warm process (nothing
compiled) does nothing here.
"""
from __future__ import annotations

from ..core import kernel_notice, kernels


def compile_every_kind() -> bool:
    """Compile the kernels of the scenario kinds this process did not run, if it compiled
    kernels at all; True when it did."""
    if not kernels.compiled_in_this_process():
        return False
    from ..comm.link import warm_kernels as comm
    from ..control.maneuvers.transition import warm_kernels as maneuvers
    from ..control.reference_free import warm_kernels as free_space
    from .free_path import warm_kernels as free_step
    from .record_rows import warm_kernels as record_rows

    for warm in (maneuvers, comm, free_space, free_step, record_rows):
        warm()
    kernel_notice.WATCH.finished()  # how long the compilation took (stderr)
    return True
