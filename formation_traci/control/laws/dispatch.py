"""The compiled dispatch of the built-in control laws: :func:`law_input_at` calls the law
whose code (control/laws/__init__.py BUILTIN) a member has. Registering a built-in law is one
name in BUILTIN and one branch here; a law registered at run time (``register_law``) gets a
dispatch of its own (control/laws/__init__.py ``law_kernels``)."""
from __future__ import annotations

from ...core.kernels import kernel
from . import acc, cacc_path, cacc_ploeg, virtual_structure

VIRTUAL_STRUCTURE = 0
ACC = 1
CACC_PATH = 2
CACC_PLOEG = 3


@kernel(inline="always")
def law_input_at(fleet, state, i, target, v_cap_i, a_cap_i):
    """Member i's model input under its law ``fleet.law[i]`` (the tuple every law's
    ``input_at`` returns: control/laws/__init__.py)."""
    code = fleet.law[i]
    if code == ACC:
        return acc.input_at(fleet, state, i, target, v_cap_i, a_cap_i)
    if code == CACC_PATH:
        return cacc_path.input_at(fleet, state, i, target, v_cap_i, a_cap_i)
    if code == CACC_PLOEG:
        return cacc_ploeg.input_at(fleet, state, i, target, v_cap_i, a_cap_i)
    return virtual_structure.input_at(fleet, state, i, target, v_cap_i, a_cap_i)


def runtime_dispatch(fleet, state, i, target, v_cap_i, a_cap_i):
    """The dispatch of a fleet with a law registered at run time (code -1): compiled per law
    with ``LAW`` bound to its ``input_at`` and ``builtin`` to :func:`law_input_at`
    (kernels.rebind; sim/fleet.py)."""
    if fleet.law[i] >= 0:
        return builtin(fleet, state, i, target, v_cap_i, a_cap_i)  # noqa: F821
    return LAW(fleet, state, i, target, v_cap_i, a_cap_i)  # noqa: F821
