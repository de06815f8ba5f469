"""SUMO's SSM device: which vehicles carry it and what it measures (its XML output is converted
to ``ssm.parquet`` while the run goes on by ``record/ssm.py``).

``sumo.ssm = "members"`` (the default) equips only the formation members (``--device.ssm.explicit``):
SUMO then measures every encounter of a member (as ego, with any foe within range) at the cost of a
handful of devices instead of one per vehicle. Conflicts between background vehicles are measured
from the recording by the analysis (``analysis/metrics/conflicts.py``). ``"all"`` equips every
vehicle (the oracle the recording-based measures are checked against; ~10x the cost of a run without
it). Thresholds and range are those of docs/outputs.md.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

SSM_MEASURES = "TTC DRAC PET"
SSM_THRESHOLDS = "3.0 3.0 2.0"
"""TTC [s], DRAC [m/s^2], PET [s]: an encounter beyond all three is not written."""
SSM_RANGE_M = 50.0
"""Foes farther than this from the equipped vehicle are not considered [m]."""


def ssm_args(mode: str, member_ids: list[str], xml_path: Path) -> list[str]:
    """SUMO command-line options of the SSM device for ``mode`` ("members", "all" or "off")."""
    if mode == "off" or (mode == "members" and not member_ids):
        return []
    # "members": the members' vType carries has.ssm.device (sumo/adapter/__init__.py); SUMO's
    # --device.ssm.explicit id list is kept from the first simulation of a libsumo process
    who = ["--device.ssm.probability", "1"] if mode == "all" else []
    return who + ["--device.ssm.file", str(xml_path), "--device.ssm.measures", SSM_MEASURES,
                  "--device.ssm.thresholds", SSM_THRESHOLDS, "--device.ssm.range", repr(SSM_RANGE_M)]


SSM_ENCOUNTER_BYTES = 400.0
"""What SUMO 1.28's SSM device keeps per step of an open encounter of an equipped vehicle with
one foe [B]: it appends the step's times, positions, speeds, TTC and DRAC to the encounter until
the encounter closes (MSDevice_SSM::Encounter::add). Measured: five equipped vehicles within 50 m
of one another, 20 such encounters, ~8 kB per step (benchmarks/RESULTS.md)."""
SSM_MEMORY_WARN_BYTES = float(1 << 30)
"""A run whose members' mutual encounters would keep more than this [B] is warned about."""


class SsmMemoryWarning(UserWarning):
    """The members' SSM device will keep much memory by the end of the run (docs/sumo.md)."""


def member_encounter_bytes(mode: str, groups, duration_s: float, step_s: float) -> tuple[int, float]:
    """(ordered pairs of members within :data:`SSM_RANGE_M` of each other at the start, the bytes
    SUMO's SSM device keeps for their encounters by the end of a run of ``duration_s`` [s]) for
    ``mode`` (``sumo.ssm``); ``groups``: each formation's members' initial positions, (n, 2) [m].
    Members of one formation stay within range of one another, so their encounters stay open the
    whole run; the encounters with other vehicles close and are not counted (an estimate from
    below)."""
    if mode == "off":
        return 0, 0.0
    pairs = 0
    for pos in groups:
        pos = np.asarray(pos, dtype=float)
        d = np.hypot(pos[:, None, 0] - pos[None, :, 0], pos[:, None, 1] - pos[None, :, 1])
        pairs += int((d < SSM_RANGE_M).sum()) - len(pos)
    return pairs, SSM_ENCOUNTER_BYTES * pairs * round(duration_s / step_s)


def memory_note(mode: str, groups, duration_s: float, step_s: float) -> str | None:
    """The warning of a run whose members' SSM encounters would keep more than
    :data:`SSM_MEMORY_WARN_BYTES` (None: less)."""
    pairs, kept = member_encounter_bytes(mode, groups, duration_s, step_s)
    if kept <= SSM_MEMORY_WARN_BYTES:
        return None
    return (f"sumo.ssm = {mode!r}: SUMO's SSM device keeps every step of the members' encounters "
            f"with one another ({pairs} ordered member pairs within {SSM_RANGE_M:.0f} m): "
            f"~{kept / 1e9:.1f} GB or more by the end of this {duration_s:.0f} s run; "
            "sumo.ssm = \"off\" keeps the memory flat (docs/sumo.md)")


def warn_memory(sc, plan) -> None:
    """A warning (stderr, before the run) of a run whose members' SSM encounters would keep more
    than :data:`SSM_MEMORY_WARN_BYTES` (:func:`memory_note`; ``plan``: the run's sumo/plan.py
    RoadPlan). None for a run attached to a SUMO already running: its options, the SSM device's
    among them, are not this tool's."""
    if sc.sumo.attach_port is not None:
        return
    groups = [p.pos0 for _, p, _ in plan.formations] or [plan.pos0]
    note = memory_note(sc.sumo.ssm, groups, sc.run.duration, sc.run.step)
    if note is not None:
        warnings.warn(note, SsmMemoryWarning, stacklevel=3)
