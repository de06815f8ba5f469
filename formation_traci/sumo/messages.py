"""SUMO's messages on the formation's clock (docs/sumo.md, "One clock").

SUMO is started with ``--no-warnings --error-log sumo/messages.log``: nothing of SUMO's reaches
the terminal. After the run every warning and error of that file becomes a ``sumo_message``
event at formation time ``t = SUMO time + step - warm-up`` (SUMO stamps a message with the time the
step began; our events of the same step, e.g. collisions, are at the time it ends), negative
during the warm-up; messages without a time, e.g. at loading, get ``-warm-up``; with SUMO's text
where ``time=...`` is rewritten on the formation's clock. run.json ``sumo.messages`` counts
them by kind, run.json ``sumo_messages`` by kind and by cause (a formation member named in the
message, or the background traffic), and one summary line goes to stderr.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

_TIME = re.compile(r"time=(-?[0-9]+(?:\.[0-9]+)?)")
_VEHICLE = re.compile(r"[Vv]ehicle '([^']+)'")
KINDS = (("no connection to the next edge", "lane_end_stop"),
         ("emergency braking", "emergency_braking"), ("collision with", "collision"),
         ("teleport", "teleport"), ("waited too long", "insertion_delay"),
         ("could not be inserted", "insertion_failed"))
"""(text in SUMO's message, kind) pairs; anything else is ``other``. A collision is SUMO's
report "...; collision with vehicle '...'" (or "junction collision with ..."): other messages
that name the word, e.g. a vType's deceleration "to prevent collisions", are not."""
SUMO_ARGS = ["--no-warnings", "true"]
"""SUMO options that keep warnings off the terminal (they still reach ``--error-log``)."""


def message_kind(text: str) -> str:
    low = text.lower()
    for needle, kind in KINDS:
        if needle in low:
            return kind
    return "other"


CAUSES = ("members", "background")
"""Who a message is about: a formation member (``members``) or any other vehicle, or none."""


def record_messages(path: Path, t0: float, add_event, step: float = 0.0,
                    t_max: float = float("inf"), members=frozenset()) -> dict:
    """Turn SUMO's error log into events; returns the counts for run.json.

    Parameters
    ----------
    path : Path
        SUMO's ``--error-log`` file.
    t0 : float
        Warm-up [s]: formation time = SUMO time - t0.
    add_event : callable
        ``add_event(t, kind, vehicle_id, other_id, detail)``.
    step : float
        SUMO's step length [s], added to SUMO's stamp (the start of the step).
    t_max : float
        Formation time [s] after which messages are left out (the sections' drain).
    members : set of str
        SUMO ids of the formation's members: a message naming one is the members'.

    ``by_cause`` of the counts: {kind: {"members": n, "background": n}} for every kind of
    :data:`KINDS` and ``other`` (run.json ``sumo_messages``).
    """
    by_cause = {kind: dict.fromkeys(CAUSES, 0) for kind in [k for _, k in KINDS] + ["other"]}
    counts = {"warnings": 0, "errors": 0, "during_warmup": 0, "by_kind": {}, "by_cause": by_cause}
    if not path.exists():
        return counts
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        level, _, text = line.partition(": ")
        if level not in ("Warning", "Error") or not text:
            continue
        counts["warnings" if level == "Warning" else "errors"] += 1
        m = _TIME.search(text)
        t = float(m.group(1)) + step - t0 if m else -t0
        if t > t_max + 1e-9:
            continue
        if t < 0:
            counts["during_warmup"] += 1
        kind = message_kind(text)
        counts["by_kind"][kind] = counts["by_kind"].get(kind, 0) + 1
        if m:
            text = text[:m.start()] + f"t={t:.2f} s (formation clock)" + text[m.end():]
        v = _VEHICLE.search(text)
        by_cause[kind]["members" if v and v.group(1) in members else "background"] += 1
        add_event(round(t, 6), "sumo_message", v.group(1) if v else "", kind, f"{level}: {text}")
    return counts


def summary_line(counts: dict) -> str | None:
    """One line for stderr, or None when SUMO said nothing."""
    n = counts["warnings"] + counts["errors"]
    if n == 0:
        return None
    causes = counts.get("by_cause", {})
    parts = []
    for k, v in sorted(counts["by_kind"].items()):
        c = causes.get(k)
        who = f" ({c['members']} about members)" if c else ""
        parts.append(f"{v} {k.replace('_', ' ')}{who}")
    kinds = ", ".join(parts) or "none up to the formation's end"
    return (f"SUMO: {counts['warnings']} warnings, {counts['errors']} errors ({kinds}; "
            f"{counts['during_warmup']} in the warm-up), recorded as sumo_message events on the "
            f"formation's clock (events.parquet)")


def report(path: Path, t0: float, add_event, step: float, t_max: float = float("inf"),
           members=frozenset()) -> dict:
    """:func:`record_messages` and the summary line on stderr."""
    counts = record_messages(path, t0, add_event, step, t_max, members)
    line = summary_line(counts)
    if line:
        print(line, file=sys.stderr)
    return counts


def sumo_outputs_meta(meta: dict, sc, rec, sumo_dir: Path, t0: float, member_d_front: dict,
                      t_max: float = float("inf"), member_v: dict | None = None,
                      members=frozenset()) -> None:
    """After the run: SUMO's messages up to formation time ``t_max`` as events (run.json
    ``sumo.messages`` by kind, ``sumo_messages`` by kind and cause: ``members`` are the
    members' SUMO ids, the keys of ``member_d_front`` too), the FCD up to then in the frame asked for (one naming of the columns
    in both frames, units in the metadata), and which clock and frame each output uses."""
    inc = rec.incidents
    member_ids = set(members) | set(member_d_front)

    def add_event(t, kind, vid, other, detail):
        rec.add_event(t, kind, vid, other, detail)
        if inc is not None:
            inc.sumo_message(other, vid in member_ids)
    counts = report(sumo_dir / "messages.log", t0, add_event, sc.run.step, t_max, member_ids)
    meta["sumo_messages"] = counts.pop("by_cause")
    meta["sumo"]["messages"] = counts
    if sc.sumo.fcd:
        from .fcd import cut_fcd, rewrite_fcd
        cut_fcd(sumo_dir / "fcd.parquet", t0, sc.run.step, t_max)  # the formation's part only
        rewrite_fcd(sumo_dir / "fcd.parquet", sc.sumo.fcd_frame, t0, member_d_front, sc.run.step,
                    member_v)
    meta["sumo"]["clock"] = ("trajectories, background, events, ssm: formation time t = SUMO time - warmup, "
                             "centre of gravity; sumo/*.log, sumo/*.xml: SUMO time; sumo/fcd.parquet: "
                             f"{'formation' if sc.sumo.fcd_frame == 'formation' else 'SUMO'} frame")
