"""The report's summary: verdicts against the seed's limits and the headline numbers.

Each verdict is ``(text, ok)``: ``ok`` True (within the limit), False (not) or None (no
limit, or not computable). Percentages of time are over the member's recorded duration;
the worst member is named.
"""
from __future__ import annotations

import math
import pandas as pd

from analysis.load.run_data import describe_issues
from analysis.metrics import comfort
from analysis.runs.member_columns import to_float

FALLING_BACK_FACTOR = 3.0
"""A member whose peak error is this many times the formation's median peak is named as
falling back (or out of place) in the headline [-]."""


def _worst(members: pd.DataFrame, col: str, largest: bool = True) -> tuple[str, float] | None:
    if col not in members.columns:
        return None
    v = pd.to_numeric(members[col], errors="coerce").dropna()
    if v.empty:
        return None
    mid = v.idxmax() if largest else v.idxmin()
    return str(mid), float(v[mid])


def _share(members: pd.DataFrame, col: str, inside: bool) -> tuple[str, float] | None:
    """Worst member's share of time [%] inside (``inside``) or outside a band from a time column."""
    if col not in members.columns:
        return None
    t = pd.to_numeric(members[col], errors="coerce")
    d = pd.to_numeric(members["duration_s"], errors="coerce")
    share = (100.0 * t / d).where(d > 0).clip(0.0, 100.0)  # sample sums can exceed the span by dt
    if not inside:
        share = 100.0 - share
    share = share.dropna()
    if share.empty:
        return None
    mid = share.idxmin()
    return str(mid), float(share[mid])


def verdicts(members: pd.DataFrame, run: dict, issues, fleet: dict | None = None) -> list[tuple[str, bool | None]]:
    """The summary lines of one run (see the module docstring); ``fleet`` (several
    formations: analysis/runs/fleet.py fleet_aggregate): the formation-level lines give the
    worst over the formations and name it."""
    out: list[tuple[str, bool | None]] = [incident_headline(run)]
    s = _share(members, "t_lat_comfortable_s", inside=True)
    if s:
        out.append((f"lateral acceleration within the comfortable band (|a_lat| < "
                    f"{comfort.LAT_ACC_COMFORTABLE:g} m/s^2, seed 3.1.2) {s[1]:.1f} % of the time "
                    f"(worst member: {s[0]})", s[1] >= 95.0))
    s = _share(members, "t_lon_above_comfort_s", inside=False)
    if s:
        out.append((f"longitudinal acceleration within {comfort.LON_ACC_COMFORT:g} m/s^2 (seed "
                    f"3.1.5) {s[1]:.1f} % of the time (worst member: {s[0]})", s[1] >= 95.0))
    w = _worst(members, "jerk_lon_1s_peak_mps3")
    if w:
        out.append((f"longitudinal jerk averaged over 1 s at most {w[1]:.2f} m/s^3 outside "
                    f"emergency brakes (ISO 15622: {comfort.JERK_ACC_LIMIT:g}; worst member: {w[0]})",
                    w[1] <= comfort.JERK_ACC_LIMIT))
    w = _worst(members, "aw_lat_mps2")
    if w:
        out.append((f"ISO 2631 weighted lateral acceleration a_w at most {w[1]:.3f} m/s^2 "
                    f"(worst member: {w[0]})", None))
    high = [f"{mid} ({ax})" for mid, r in members.iterrows() for ax in ("lon", "lat")
            if str(r.get(f"aw_crest_over_9_{ax}")) == "True"]  # bool or numpy bool
    if high:
        out.append((f"ISO 2631 crest factor above 9 for {', '.join(high)}: the basic r.m.s. may "
                     "underestimate shocks; MTVV and VDV (clause 6.3) in the members table", False))
    for col, what in (("friction_over_s", "friction circle (eq 3.16)"),
                      ("traction_over_s", "traction limit (eq 3.14)"),
                      ("slip_over_s", "tire slip limit")):
        w = _worst(members, col)
        if w:
            out.append((f"{what} exceeded for {w[1]:.2f} s (worst member: {w[0]})", w[1] == 0.0))
    out.append(_error_headline(members))
    if fleet is not None:
        out.append(fleet_headline(fleet))
    else:
        shape = to_float(run.get("shape_error_max_m"))
        if math.isfinite(shape):
            out.append((f"shape error (members relative to each other) at most {shape:.3g} m", None))
    n_err = sum((i["severity"] if isinstance(i, dict) else i.severity) == "error" for i in issues)
    out.append((describe_issues(issues), n_err == 0))
    return out


INCIDENT_WORDS = {"member_collisions": "member collision(s) (bodies overlap)",
                  "member_removed": "member(s) removed from the run",
                  "emergency_brakes": "emergency brake(s)",
                  "stranded": "member(s) stranded (standing while v_ref > 2 m/s)",
                  "sumo_collision_artefacts": "SUMO collision report(s) our clearance refutes "
                                              "(lane-touching artefacts, not counted)"}


def incident_headline(run: dict) -> tuple[str, bool | None]:
    """The first summary line: the run's safety incidents (run.json 'incidents')."""
    counts = {k: run.get(k) for k in INCIDENT_WORDS}
    if all(v is None for v in counts.values()):
        return ("safety incidents: not recorded (a run.json without 'incidents')", None)
    bad = [f"{int(counts[k])} {w}" for k, w in INCIDENT_WORDS.items()
           if k != "sumo_collision_artefacts" and (counts[k] or 0) > 0]
    art = counts["sumo_collision_artefacts"] or 0
    tail = f"; {int(art)} {INCIDENT_WORDS['sumo_collision_artefacts']}" if art else ""
    if bad:
        return ("INCIDENTS: " + ", ".join(bad) + " (events.parquet)" + tail, False)
    return ("no safety incident: no member collision, removal, emergency brake or stranded "
            "member" + tail, True)


FLEET_HEADLINE = ("shape_error_max_m", "shape_error_rms_m", "shape_error_final_m", "string_stable",
                  "string_amplification", "energy_kwh_per_100km", "energy_saving_vs_alone")
"""Formation-level metrics the summary gives as their worst over the formations."""


def fleet_headline(fleet: dict) -> tuple[str, bool | None]:
    """Several formations: each formation-level metric's worst over the formations, named."""
    from analysis.runs.fleet import FORMATION_METRICS

    worst, which = fleet.get("worst") or {}, fleet.get("worst_formation") or {}
    parts = []
    for k in FLEET_HEADLINE:
        v = worst.get(k)
        if v is None or (isinstance(v, float) and not math.isfinite(v)):
            continue
        unit = FORMATION_METRICS.get(k, "-")
        shown = (f"{v:.3g}" if isinstance(v, float) else str(v)) + ("" if unit == "-" else f" {unit}")
        parts.append(f"{k} {shown} ({which.get(k)})")
    n = fleet.get("n_formations")
    if not parts:
        return (f"formation-level metrics of the {n} formations: not computed", None)
    return (f"worst over the {n} formations (formation in brackets): " + ", ".join(parts), None)


def _error_headline(members: pd.DataFrame) -> tuple[str, bool | None]:
    """Per-member worst formation error; names a member far behind the others."""
    peak = pd.to_numeric(members.get("e_max_m", pd.Series(dtype=float)), errors="coerce").dropna()
    if peak.empty:
        return ("formation error: not computed", None)
    per = ", ".join(f"{m} {v:.3g} m" for m, v in peak.items())
    worst = str(peak.idxmax())
    med = float(peak.median())
    lagging = len(peak) > 1 and peak[worst] > FALLING_BACK_FACTOR * max(med, 0.05)
    text = f"worst formation error per member (max |e|): {per}"
    if lagging:
        text += (f" — {worst} is {peak[worst] / max(med, 1e-9):.1f} x the median: it fell "
                 "back or out of its slot")
    return (text, not lagging)
