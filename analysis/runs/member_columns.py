"""Column access for one member of a loaded run, with the reason when a column is missing
or all NaN, and small helpers over the record's contiguous segments (shared by the
per-member metrics of :mod:`analysis.runs.member_metrics` and :mod:`analysis.runs.member_comfort`).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from analysis.load.run_data import RunData

_TIRE_COLUMNS = ("slip_front", "slip_rear", "traction_force", "traction_force_max", "steer",
                 "steer_rate", "beta")


class MemberColumns:
    """Column access for one member with reasons for what is not available."""

    def __init__(self, data: RunData, g: pd.DataFrame):
        self.data, self.g = data, g
        self.unavailable: dict[str, str] = {}

    def col(self, name: str) -> np.ndarray | None:
        if name in self.data.missing_columns:
            return None
        x = self.g[name].to_numpy(dtype=float)
        return x if np.isfinite(x).any() else None

    def why(self, name: str) -> str:
        if name in self.data.missing_columns:
            return f"column '{name}' missing from the record"
        if name in _TIRE_COLUMNS and self.data.meta.get("model") == "kinematic":
            return f"'{name}' is all NaN (the kinematic model has no tires)"
        return f"'{name}' is all NaN"

    def need(self, group: str, *names: str) -> list[np.ndarray] | None:
        cols = [self.col(n) for n in names]
        missing = [n for n, c in zip(names, cols) if c is None]
        if missing:
            self.unavailable[group] = "; ".join(self.why(n) for n in missing)
            return None
        return cols


def to_float(x: Any) -> float:
    """``float(x)``, NaN for what is not a number (None, text)."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return math.nan
    return x


def covered_time_s(t: np.ndarray, segs: list[slice]) -> float:
    """Recorded time without the gaps: sum of the segment spans [s]."""
    return float(sum(t[s.stop - 1] - t[s.start] for s in segs))


def segment_sum(fn, segs: list[slice], *arrays: np.ndarray) -> float:
    """Sum over the segments of ``fn`` applied to each array's slice of the segment."""
    return float(sum(fn(*(a[s] for a in arrays)) for s in segs))


def per_segment(fn, segs: list[slice], a: np.ndarray, n_min: int) -> tuple[np.ndarray, int]:
    """``fn`` applied per segment of at least ``n_min`` samples (NaN elsewhere), and the
    number of shorter segments skipped."""
    out = np.full(a.shape, np.nan)
    skipped = 0
    for s in segs:
        if s.stop - s.start >= n_min:
            out[s] = fn(a[s])
        else:
            skipped += 1
    return out, skipped
