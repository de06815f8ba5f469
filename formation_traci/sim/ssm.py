"""SUMO's SSM device: which vehicles carry it, and its XML output converted to ``ssm.parquet``.

``sumo.ssm = "members"`` (the default) equips only the formation members (``--device.ssm.explicit``):
SUMO then measures every encounter of a member (as ego, with any foe within range) at the cost of a
handful of devices instead of one per vehicle. Conflicts between background vehicles are measured
from the recording by the analysis (``analysis/conflicts.py``). ``"all"`` equips every vehicle (the
oracle the recording-based measures are checked against; ~10x the cost of a run without it).
Thresholds and range are those of docs/outputs.md.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..record.columns import SSM_COLUMNS
from ..record.writer import ChunkedTable

SSM_MEASURES = "TTC DRAC PET"
SSM_THRESHOLDS = "3.0 3.0 2.0"
"""TTC [s], DRAC [m/s^2], PET [s]: an encounter beyond all three is not written."""
SSM_RANGE_M = 50.0
"""Foes farther than this from the equipped vehicle are not considered [m]."""


def ssm_args(mode: str, member_ids: list[str], xml_path: Path) -> list[str]:
    """SUMO command-line options of the SSM device for ``mode`` ("members", "all" or "off")."""
    if mode == "off" or (mode == "members" and not member_ids):
        return []
    who = (["--device.ssm.probability", "1"] if mode == "all"
           else ["--device.ssm.explicit", ",".join(member_ids)])
    return who + ["--device.ssm.file", str(xml_path), "--device.ssm.measures", SSM_MEASURES,
                  "--device.ssm.thresholds", SSM_THRESHOLDS, "--device.ssm.range", repr(SSM_RANGE_M)]


def _num(v) -> float:
    return float(v) if v not in (None, "", "NA") else np.nan


def _point(el, line) -> tuple[float, float]:
    """SUMO's position of a measure (``"x,y"`` [m]) in road coordinates (s, d) [m]."""
    pos = el.get("position") if el is not None else None
    if line is None or not pos or pos == "NA":
        return np.nan, np.nan
    try:
        x, y = (float(c) for c in pos.split(",")[:2])
    except ValueError:
        return np.nan, np.nan
    s, d = line.to_frenet(np.array([[x, y]]))
    return float(np.ravel(s)[0]), float(np.ravel(d)[0])


def convert_ssm(xml_path: Path, out: Path, t0: float, members: set[str], line=None) -> None:
    """SUMO's SSM XML (one ``<conflict>`` per encounter and device) -> ``ssm.parquet``, times on
    the formation clock (SUMO's minus ``t0`` [s]); with the reference ``line``, where SUMO put the
    minimum TTC in road coordinates. A truncated file keeps the conflicts read before the damage."""
    if not xml_path.exists():
        return
    table = ChunkedTable(out, SSM_COLUMNS, chunk_rows=100_000, labels=[""])
    try:
        for _, el in ET.iterparse(xml_path):
            if el.tag != "conflict":
                continue
            ego, foe = el.get("ego", ""), el.get("foe", "")
            ttc, drac, pet = el.find("minTTC"), el.find("maxDRAC"), el.find("PET")
            g = (lambda e, k: _num(e.get(k)) if e is not None else np.nan)
            s, d = _point(ttc, line)
            table.append({
                "begin": _num(el.get("begin")) - t0, "end": _num(el.get("end")) - t0,
                "ego": table.code(ego), "foe": table.code(foe),
                "member_involved": ego in members or foe in members,
                "min_ttc": g(ttc, "value"), "min_ttc_time": g(ttc, "time") - t0,
                "max_drac": g(drac, "value"), "max_drac_time": g(drac, "time") - t0,
                "pet": g(pet, "value"), "min_ttc_type": g(ttc, "type"),
                "min_ttc_s": s, "min_ttc_d": d}, 1)
            el.clear()
    except ET.ParseError:
        pass  # keep what was parsed
    table.close()
