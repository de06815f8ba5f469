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

from pathlib import Path

SSM_MEASURES = "TTC DRAC PET"
SSM_THRESHOLDS = "3.0 3.0 2.0"
"""TTC [s], DRAC [m/s^2], PET [s]: an encounter beyond all three is not written."""
SSM_RANGE_M = 50.0
"""Foes farther than this from the equipped vehicle are not considered [m]."""


def ssm_args(mode: str, member_ids: list[str], xml_path: Path) -> list[str]:
    """SUMO command-line options of the SSM device for ``mode`` ("members", "all" or "off")."""
    if mode == "off" or (mode == "members" and not member_ids):
        return []
    # "members": the members' vType carries has.ssm.device (sumo/adapter.py); SUMO's
    # --device.ssm.explicit id list is kept from the first simulation of a libsumo process
    who = ["--device.ssm.probability", "1"] if mode == "all" else []
    return who + ["--device.ssm.file", str(xml_path), "--device.ssm.measures", SSM_MEASURES,
                  "--device.ssm.thresholds", SSM_THRESHOLDS, "--device.ssm.range", repr(SSM_RANGE_M)]
