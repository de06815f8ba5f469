"""SUMO's SSM output (XML, one ``<conflict>`` per encounter) converted to ``ssm.parquet``
while the run goes on: at every cut of the tables the conflicts SUMO has written so far are
appended, so a killed run keeps them; a truncated file keeps the conflicts before the damage."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from run_contract.columns import SSM_COLUMNS

from .writer import ChunkedTable

READ_BYTES = 1 << 20
"""Bytes of the XML read per call of the parser [B]."""


def _num(v) -> float:
    return float(v) if v not in (None, "", "NA") else math.nan


def _road_point(el, line) -> tuple[float, float]:
    """SUMO's position of a measure (``"x,y"`` [m]) in road coordinates (s, d) [m]."""
    pos = el.get("position") if el is not None else None
    if line is None or not pos or pos == "NA":
        return math.nan, math.nan
    try:
        x, y = (float(c) for c in pos.split(",")[:2])
    except ValueError:
        return math.nan, math.nan
    s, d = line.to_frenet(np.array([[x, y]]))
    return float(np.ravel(s)[0]), float(np.ravel(d)[0])


class SsmConverter:
    """Incremental SSM XML -> Parquet. ``t0`` [s]: SUMO time of the formation's t = 0 (the
    warm-up); ``members``: ids flagged in ``member_involved``; ``line``: the reference line
    (anything with ``to_frenet(xy) -> (s, d)`` [m]) for where SUMO put the minimum TTC."""

    def __init__(self, xml_path: Path, out: Path, t0: float, members: set[str], line=None):
        self.line = line
        self.xml_path = Path(xml_path)
        self.out = Path(out)
        self.t0 = float(t0)
        self.members = set(members)
        self.table: ChunkedTable | None = None  # created once SUMO has created its file
        self._parser = ET.XMLPullParser(events=("start", "end"))
        self._pos = 0
        self._root = None
        self._broken = False
        self.t_max = math.inf  # conflicts beginning later (formation time [s]) are left out: the drain

    def update(self) -> None:
        """Append the conflicts SUMO has written since the last call."""
        if self._broken or not self.xml_path.exists():
            return
        if self.table is None:
            self.table = ChunkedTable(self.out, SSM_COLUMNS, chunk_rows=100_000, labels=[""])
        with open(self.xml_path, "rb") as f:
            f.seek(self._pos)
            while True:
                data = f.read(READ_BYTES)
                if not data:
                    break
                self._pos += len(data)
                try:
                    self._parser.feed(data)
                    self._consume()
                except ET.ParseError:
                    self._broken = True  # keep what was parsed
                    return

    def _consume(self) -> None:
        for event, el in self._parser.read_events():
            if event == "start":
                if self._root is None:
                    self._root = el
                continue
            if el.tag != "conflict":
                continue
            self._append(el)
            if self._root is not None:
                try:
                    self._root.remove(el)
                except ValueError:
                    pass

    def _append(self, el) -> None:
        t0, table = self.t0, self.table
        ego, foe = el.get("ego", ""), el.get("foe", "")
        if _num(el.get("begin")) - t0 > self.t_max:
            return
        ttc, drac, pet = el.find("minTTC"), el.find("maxDRAC"), el.find("PET")
        s, d = _road_point(ttc, self.line)
        table.append({
            "begin": _num(el.get("begin")) - t0, "end": _num(el.get("end")) - t0,
            "ego": table.code(ego), "foe": table.code(foe),
            "member_involved": ego in self.members or foe in self.members,
            "min_ttc": _num(ttc.get("value")) if ttc is not None else math.nan,
            "min_ttc_time": (_num(ttc.get("time")) - t0) if ttc is not None else math.nan,
            "max_drac": _num(drac.get("value")) if drac is not None else math.nan,
            "max_drac_time": (_num(drac.get("time")) - t0) if drac is not None else math.nan,
            "pet": _num(pet.get("value")) if pet is not None else math.nan,
            "min_ttc_type": _num(ttc.get("type")) if ttc is not None else math.nan,
            "min_ttc_s": s, "min_ttc_d": d}, 1)
