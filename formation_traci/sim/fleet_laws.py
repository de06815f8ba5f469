"""The members' law codes and parameter rows (control/laws) for the Fleet (sim/fleet.py), and
the fallback of a CACC member on radio loss: it runs the ACC law on its ACC block (the
controller.acc time gap, larger than a CACC's: docs/platoon_laws.md) while its beacons are timed
out (comm/link.py ``timed_out``) and its own law again when they return (events
``law_fallback`` / ``law_recovered``, sim/loop.py)."""
from __future__ import annotations

import numpy as np

from ..control.laws import law_code, law_module
from ..control.laws.dispatch import ACC, CACC_PATH, CACC_PLOEG, law_input_at, runtime_dispatch
from ..core.kernels import rebind

FALLS_BACK = (CACC_PATH, CACC_PLOEG)
"""Law codes that fall back to ACC on radio loss."""


def pack_laws(cfg):
    """Every member's law code (n,), the law parameters (n, most PARAMS of its laws) and the
    one law registered at run time among them (or None)."""
    laws = cfg.law if isinstance(cfg.law, (tuple, list)) else (cfg.law,) * cfg.n
    codes = np.array([law_code(name) for name in laws], dtype=np.int64)
    runtime = sorted({name for name, c in zip(laws, codes) if c < 0})
    if len(runtime) > 1:
        raise ValueError(f"one fleet runs at most one law registered at run time, not {runtime}")
    packs = {name: np.asarray(law_module(name).pack(cfg), dtype=float) for name in set(laws)}
    L = np.zeros((cfg.n, max(p.shape[1] for p in packs.values())))
    for i, name in enumerate(laws):
        L[i, :packs[name].shape[1]] = packs[name][i]
    return codes, L, (runtime[0] if runtime else None)


_RUNTIME_KERNELS: dict = {}


def law_kernels(law: str | None, step, signals):
    """(step kernel, signal kernel): ``step`` and ``signals`` (sim/fleet.py, cached, or a
    model variant's step: sim/fleet_models.py) when every law is built in, else compiled
    copies that also dispatch to ``law``, registered at run time (control/laws), made once
    per law and kernels."""
    if law is None:
        return step, signals
    mod = law_module(law)
    key = (law, id(step), id(signals))
    got = _RUNTIME_KERNELS.get(key)
    if got is None or got[0] is not mod or got[1] is not step or got[2] is not signals:
        disp = rebind(runtime_dispatch, LAW=mod.input_at, builtin=law_input_at)
        got = _RUNTIME_KERNELS[key] = (mod, step, signals, rebind(step, law_input_at=disp),
                                       rebind(signals, law_input_at=disp))
    return got[3], got[4]


def fallback_switches(law: np.ndarray, base: np.ndarray, pred: np.ndarray, rows,
                      lost) -> list[tuple[int, bool]]:
    """Set ``law`` (in place) of the members ``rows`` to ACC where ``lost`` and their ``base``
    law is a CACC, else to ``base``; the members switched: (index, fell back). A column's head
    (``pred`` -1) runs the virtual structure under every platoon law: it never switches."""
    out = []
    for i, gone in zip(rows, lost):
        if base[i] not in FALLS_BACK or pred[i] < 0:
            continue
        want = ACC if gone else base[i]
        if law[i] != want:
            law[i] = want
            out.append((int(i), bool(gone)))
    return out
