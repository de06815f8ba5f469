"""The compiled dispatch of the built-in control laws: :func:`law_input_at` calls the law
whose code (control/laws/__init__.py BUILTIN) a member has. Registering a built-in law is one
name in BUILTIN and one branch here; a law registered at run time (``register_law``) gets a
dispatch of its own (control/laws/__init__.py ``law_kernels``)."""
from __future__ import annotations

from ...kernels import kernel
from . import acc, cacc_path, cacc_ploeg, virtual_structure

VIRTUAL_STRUCTURE = 0
ACC = 1
CACC_PATH = 2
CACC_PLOEG = 3


@kernel
def law_input_at(code, kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx, tvy, tax,
                 tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c):
    """Member i's model input under its law ``code`` (the tuple every law's ``input_at``
    returns: control/laws/virtual_structure.py)."""
    if code == ACC:
        return acc.input_at(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx, tvy,
                            tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c)
    if code == CACC_PATH:
        return cacc_path.input_at(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx,
                                  tvy, tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c)
    if code == CACC_PLOEG:
        return cacc_ploeg.input_at(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx,
                                   tvy, tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c)
    return virtual_structure.input_at(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py,
                                      tvx, tvy, tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c)


def runtime_dispatch(code, kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx, tvy,
                     tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c):
    """The dispatch of a fleet with a law registered at run time (code -1): compiled per law
    with ``LAW`` bound to its ``input_at`` and ``builtin`` to :func:`law_input_at`
    (kernels.rebind; sim/fleet.py)."""
    if code >= 0:
        return builtin(code, kind, x, i, theta_star_i, speed_in_i, L, gains, px, py,  # noqa: F821
                       tvx, tvy, tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c)
    return LAW(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx, tvy,  # noqa: F821
               tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c)
