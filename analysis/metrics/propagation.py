"""How a disturbance on one member grows or decays across the 2-D formation.

Members are grouped into *columns* (same lateral offset, within a tolerance) and *rows*
(same longitudinal offset). Along a column the disturbance travels front to back, as in a
platoon's string stability; along a row it travels sideways away from the member whose
error peaked highest (the disturbed one). For every pair of neighbours the ratio of the
follower's to the leader's peak and RMS formation error is reported: above 1 the
disturbance grows along that direction.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

PROPAGATION_COLUMNS = ("direction", "group", "source", "target", "peak_ratio", "rms_ratio",
                       "grows")


def _groups(offsets: dict[str, tuple[float, float]], axis: int, tol: float) -> list[list[str]]:
    """Members sharing offset[axis] within ``tol`` [m] (a column: axis 1; a row: axis 0)."""
    ids = sorted(offsets, key=lambda m: offsets[m][axis])
    out: list[list[str]] = []
    for m in ids:
        if out and abs(offsets[m][axis] - offsets[out[-1][0]][axis]) <= tol:
            out[-1].append(m)
        else:
            out.append([m])
    return [g for g in out if len(g) > 1]


def propagation(offsets: dict[str, tuple[float, float]], e_peak: dict[str, float],
                e_rms: dict[str, float], tol: float = 0.5) -> pd.DataFrame:
    """Neighbour-to-neighbour error ratios along columns and rows.

    Parameters
    ----------
    offsets : dict
        Member id -> (along, across) offset [m] (along: ahead positive; across: left positive).
    e_peak, e_rms : dict
        Member id -> peak and RMS formation error [m].
    tol : float
        Offsets closer than this [m] count as the same column / row.

    Returns
    -------
    DataFrame
        Columns :data:`PROPAGATION_COLUMNS`; ``direction`` is ``"column"`` (front to back)
        or ``"row"`` (outwards from the row's member with the largest peak error).
    """
    rows = []
    for k, col in enumerate(_groups(offsets, 1, tol)):
        chain = sorted(col, key=lambda m: -offsets[m][0])  # front first
        rows += _pairs("column", k, list(zip(chain, chain[1:])), e_peak, e_rms)
    for k, row in enumerate(_groups(offsets, 0, tol)):
        chain = sorted(row, key=lambda m: offsets[m][1])  # right to left
        src = int(np.nanargmax([e_peak.get(m, np.nan) for m in chain])) \
            if any(np.isfinite(e_peak.get(m, np.nan)) for m in chain) else 0
        pairs = [(chain[i], chain[i - 1]) for i in range(src, 0, -1)]
        pairs += [(chain[i], chain[i + 1]) for i in range(src, len(chain) - 1)]
        rows += _pairs("row", k, pairs, e_peak, e_rms)
    return pd.DataFrame(rows, columns=list(PROPAGATION_COLUMNS))


def _pairs(direction, group, pairs, e_peak, e_rms):
    out = []
    for a, b in pairs:
        pr = _ratio(e_peak.get(b), e_peak.get(a))
        out.append({"direction": direction, "group": group, "source": a, "target": b,
                    "peak_ratio": pr, "rms_ratio": _ratio(e_rms.get(b), e_rms.get(a)),
                    "grows": bool(pr > 1.0) if np.isfinite(pr) else None})
    return out


def _ratio(num, den) -> float:
    num = np.nan if num is None else float(num)
    den = np.nan if den is None else float(den)
    return num / den if np.isfinite(num) and np.isfinite(den) and den > 0 else np.nan
