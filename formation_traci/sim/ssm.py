"""SUMO's SSM device output (XML) converted to ssm.parquet after a road run."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..record.columns import SSM_COLUMNS
from ..record.writer import ChunkedTable


def convert_ssm(xml_path: Path, out: Path, t0: float, members: set[str]) -> None:
    """SUMO's SSM XML (one <conflict> per encounter) -> ssm.parquet; a truncated file keeps
    the conflicts read before the damage."""
    if not xml_path.exists():
        return
    table = ChunkedTable(out, SSM_COLUMNS, chunk_rows=100_000, labels=[""])
    f = lambda v: float(v) if v not in (None, "", "NA") else np.nan
    try:
        for _, el in ET.iterparse(xml_path):
            if el.tag != "conflict":
                continue
            ego, foe = el.get("ego", ""), el.get("foe", "")
            ttc, drac, pet = el.find("minTTC"), el.find("maxDRAC"), el.find("PET")
            table.append({
                "begin": f(el.get("begin")) - t0, "end": f(el.get("end")) - t0,
                "ego": table.code(ego), "foe": table.code(foe),
                "member_involved": ego in members or foe in members,
                "min_ttc": f(ttc.get("value")) if ttc is not None else np.nan,
                "min_ttc_time": (f(ttc.get("time")) - t0) if ttc is not None else np.nan,
                "max_drac": f(drac.get("value")) if drac is not None else np.nan,
                "max_drac_time": (f(drac.get("time")) - t0) if drac is not None else np.nan,
                "pet": f(pet.get("value")) if pet is not None else np.nan}, 1)
            el.clear()
    except ET.ParseError:
        pass  # keep what was parsed
    table.close()
