"""The shared warm-up: SUMO's traffic before the formation enters, simulated once per warm-up
key and saved as SUMO's state, every run with that key started from it (docs/sweeps.md,
"The shared warm-up").

A road run steps SUMO ``traffic.warmup / run.step`` times before its first step
(sumo/world.py ``SumoWorld.start``). What those steps give depends only on what SUMO was
started with and what was set up before them: the :func:`warm_key` hashes exactly that (SUMO's
command line with the run's own directory taken out, the content of every file it names: network,
routes as written, additional files; the members' route and vTypes, the friction, the lanes
closed to members, the flows counted; the warm-up steps; SUMO's version). A sweep's cases that
differ only in what SUMO does not see before the formation enters (the controller, [comm], the
maneuvers ...) and their twins share a key.

``start_warm`` with a cache directory: the first run of a key simulates the warm-up in a process
of its own (``python -m formation_traci.sumo.warm_state JOB``), which saves SUMO's state with its
random number generators (``--save-state.rng``, ``--save-state.precision 17``), the vehicles
inserted so far and SUMO's outputs of the warm-up into ``DIR/<key>/`` (a temporary directory
renamed when complete: a run never sees half an entry; ``warm.json`` holds the checksums of the
entry's files and its own, and a damaged entry is made again with a warning: sumo/warm_entry.py).
Runs of the same key at the same time wait for it on ``DIR/<key>.lock`` (``flock``, saying so on
stderr; a producer that dies releases it and the next run produces). Every run of the key, the first one included, then starts SUMO from the state
(``--load-state``, without the route file: the flows are in the state, and SUMO would otherwise
draw the loaded flows' next vehicles from an advanced random stream) and sets up again what the
state does not keep (the friction, the closed lanes, the members' vType attributes).

What SUMO 1.28's state does not hold, and how a run from it differs from the run that simulated
its warm-up itself (tests/test_warm_state.py): the sublane lane-change model's memory (SL2015's
speed-gain and keep-right wishes, its look-ahead speed, a lateral speed in progress) starts from
zero, lateral positions are kept to 17 decimals. The vehicles, their positions, speeds, lanes,
routes, the flows' next insertions and every random stream are as they were, so the first
recorded step (the background rows at t = 0) is the same, and the traffic then drifts apart as
two realisations of the same demand do. A run from the state is itself reproducible: every run
of a key starts from the same file in a process that has simulated nothing before (SUMO's
state loading depends on the vehicles a process created earlier, so the twin of a shared case
runs in a process of its own: sweep/case.py).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from .types import MemberType, SumoError
from .warm_entry import check_entry_path, key_lock, read_entry, remove_entry, seal

FORMAT = "formation-traci/warm-state/2"
"""Changes when what an entry holds or how it is made changes (part of the key)."""
STATE_FILE = "state.xml.gz"
WARM_JSON = "warm.json"
STATE_OPTIONS = ["--save-state.rng", "--save-state.precision", "17"]
"""Options of the producing SUMO: the random streams in the state, values to 17 decimals
(SUMO's default is 2)."""
MERGED_XML = ("sections.xml", "lanechanges.xml", "measure.xml")
"""SUMO's XML outputs whose warm-up part a run from the state gets from the entry."""
MERGED_TEXT = ("messages.log",)
"""Text outputs likewise (the warm-up's warnings are sumo_message events at t < 0)."""


@dataclass(frozen=True)
class WarmSetup:
    """What a road run sets up in SUMO before the warm-up (sumo/world.py start)."""

    flow_ids: tuple[str, ...]  # flows whose insertions are counted
    mu: float  # friction of every edge [-]
    route_id: str  # the members' route
    route: tuple[str, ...]  # its edges
    member_types: tuple[MemberType, ...]  # the members' vTypes (one per id)
    forbidden: tuple[str, ...]  # lanes closed to the members' classes
    vclasses: tuple[str, ...]  # the members' vehicle classes

    def apply(self, ad, loaded: bool = False) -> None:
        """Set it up on adapter ``ad``; ``loaded``: SUMO started from a state, which has the
        route and the vTypes (they are kept and set again, not added)."""
        ad.count_departures(list(self.flow_ids))
        ad.set_friction(self.mu)
        if loaded:
            ad.know_route(self.route_id, list(self.route))
        else:
            ad.add_route(self.route_id, list(self.route))
        for mt in self.member_types:
            ad.add_member_type(mt, exists=loaded)
        ad.forbid_lanes(list(self.forbidden), list(self.vclasses))

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> WarmSetup:
        mts = tuple(MemberType(**{**m, "color": tuple(m["color"])}) for m in d["member_types"])
        return cls(tuple(d["flow_ids"]), float(d["mu"]), d["route_id"], tuple(d["route"]), mts,
                   tuple(d["forbidden"]), tuple(d["vclasses"]))


def not_shareable(sc) -> str | None:
    """Why the warm-up of ``sc`` cannot start from a shared state, or None when it can: SUMO
    attached to or shown in sumo-gui, SUMO's own outputs that cover the warm-up and are not
    merged (fcd, ``sumo.options``), SSM devices on the background vehicles (their encounters
    are not in the state), no warm-up at all."""
    s = sc.sumo
    for why, bad in (("SUMO is attached to (sumo.attach_port)", s.attach_port is not None),
                     ("sumo-gui (sumo.gui)", s.gui), ("the traci backend", s.backend != "libsumo"),
                     ("SUMO's fcd output covers the warm-up (sumo.fcd)", s.fcd),
                     ("SUMO options of the scenario (sumo.options)", bool(s.options)),
                     ("SSM devices on every vehicle (sumo.ssm = 'all')", s.ssm == "all"),
                     ("no warm-up (traffic.warmup = 0)", sc.traffic.warmup <= 0)):
        if bad:
            return why
    return None


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _normalised(args: list[str], sumo_dir: Path) -> tuple[list[str], dict[str, str]]:
    """SUMO's arguments with the run's directory as ``{run}``, and the content digest of every
    file they name that exists (network, routes, additional files)."""
    run = str(sumo_dir)
    out, files = [], {}
    for a in args:
        out.append(a.replace(run, "{run}"))
        for part in a.split(","):
            if part.startswith("/") and Path(part).is_file():
                files[part.replace(run, "{run}")] = _file_digest(Path(part))
    return out, files


def warm_key(args: list[str], sumo_dir: Path, setup: WarmSetup, warm_steps: int) -> str:
    """Hash of exactly what SUMO's warm-up depends on (see the module docstring)."""
    from ..core.versions import installed_versions

    norm, files = _normalised(args, sumo_dir)
    doc = {"format": FORMAT, "args": norm, "files": files, "setup": setup.to_json(),
           "warm_steps": int(warm_steps), "sumo": installed_versions(["eclipse-sumo", "libsumo"])}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:24]


def load_args(args: list[str], state: Path) -> list[str]:
    """SUMO's arguments to start from ``state``: without the route file (the state holds the
    flows, their vTypes and routes)."""
    out = list(args)
    i = out.index("-r")
    del out[i:i + 2]
    return out + ["--load-state", str(state)]


def ensure_entry(cache: Path, key: str, args: list[str], sumo_dir: Path, setup: WarmSetup,
                 warm_steps: int) -> tuple[Path, dict, bool]:
    """``cache/<key>/`` (made now if missing or damaged, see :func:`produce`), its checked
    ``warm.json`` and whether this call made it (sumo/warm_entry.py: never a link, never an
    entry holding what the cache did not write)."""
    entry = cache / key
    with key_lock(cache, key):
        check_entry_path(entry)
        if entry.is_dir():
            doc, why = read_entry(entry, FORMAT)
            if doc is not None:
                return entry, doc, False
            remove_entry(entry, why)
        produce(entry, args, sumo_dir, setup, warm_steps)
        doc, why = read_entry(entry, FORMAT)
        if doc is None:
            raise SumoError(f"the shared warm-up just made in {entry} is not whole: {why}")
        return entry, doc, True


def produce(entry: Path, args: list[str], sumo_dir: Path, setup: WarmSetup, warm_steps: int) -> None:
    """Simulate the warm-up in a process of its own into a new temporary directory beside
    ``entry`` (which does not exist), renamed to ``entry`` when complete. The input files SUMO
    reads from the run's directory are copied there (SUMO then reads the same content)."""
    tmp = Path(tempfile.mkdtemp(dir=entry.parent, prefix=f".{entry.name}.", suffix=".tmp"))
    try:
        os.chmod(tmp, 0o755)
        for f in sumo_dir.iterdir():
            if f.is_file() and (f.name.endswith(".xml") and ".add." in f.name or f.name.endswith(".rou.xml")):
                shutil.copy2(f, tmp / f.name)
        job = {"args": [a.replace(str(sumo_dir), str(tmp)) for a in args] + STATE_OPTIONS,
               "setup": setup.to_json(), "warm_steps": int(warm_steps), "out": str(tmp)}
        (tmp / "job.json").write_text(json.dumps(job), encoding="utf-8")
        res = subprocess.run([sys.executable, "-m", "formation_traci.sumo.warm_state", str(tmp / "job.json")],
                             capture_output=True, text=True)
        if res.returncode != 0 or not (tmp / WARM_JSON).is_file():
            last = [ln.strip() for ln in (res.stderr or res.stdout).splitlines() if ln.strip()][-1:]
            raise SumoError(f"the shared warm-up did not complete (exit {res.returncode}): "
                            f"{last[0] if last else 'no output'}")  # its last line: the reason, no traceback
        os.rename(tmp, entry)  # entry is missing (checked under the key's lock)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def simulate(job: dict) -> None:
    """The producing process: SUMO's warm-up as a run does it, then its state and the
    vehicles it inserted (``warm.json``)."""
    from .adapter import SumoAdapter

    out = Path(job["out"])
    ad = SumoAdapter("libsumo")
    try:
        version = ad.start(job["args"])
        WarmSetup.from_json(job["setup"]).apply(ad)
        for _ in range(job["warm_steps"]):
            ad.simulation_step()
        t = ad.time
        ad.save_state(out / STATE_FILE)
        doc = {"format": FORMAT, "time": t, "sumo": version, "departed": ad.departed,
               "departures": ad.departures}
    finally:
        ad.close()
    _drop_save_messages(out / "messages.log")
    doc = seal(out, doc)  # the checksums of the entry's files and of warm.json itself
    tmp = out / f".{WARM_JSON}.tmp"
    tmp.write_text(json.dumps(doc), encoding="utf-8")
    os.replace(tmp, out / WARM_JSON)


SAVE_MESSAGE = "cannot save state"
"""SUMO's warning for a device without state (the friction device) when the state is saved:
said by the saving, not by the warm-up, so not one of the warm-up's messages."""


def _drop_save_messages(log: Path) -> None:
    if log.is_file():
        lines = log.read_text(encoding="utf-8", errors="replace").splitlines(keepends=True)
        log.write_text("".join(ln for ln in lines if SAVE_MESSAGE not in ln), encoding="utf-8")


def start_warm(ad, args: list[str], setup: WarmSetup, warm_steps: int, sumo_dir: Path,
               info: dict | None) -> str:
    """Start SUMO on adapter ``ad`` and bring it to the end of the warm-up; returns SUMO's
    version. ``info``: run.json's ``warm_state`` (``cache``: the cache directory) or None
    (the warm-up is simulated here, as always); it gets the key, the entry, whether this run
    made it, or why the warm-up was not shared (``info['unshared']``, set by the caller)."""
    if info is None or info.get("cache") is None or info.get("unshared"):
        version = ad.start(args)
        setup.apply(ad)
        for _ in range(warm_steps):
            ad.simulation_step()
        return version
    key = warm_key(args, sumo_dir, setup, warm_steps)
    entry, doc, made = ensure_entry(Path(info["cache"]), key, args, sumo_dir, setup, warm_steps)
    version = ad.start(load_args(args, entry / STATE_FILE))
    setup.apply(ad, loaded=True)
    ad.departed.update(doc["departed"])
    ad.departures.extend((vid, float(t)) for vid, t in doc["departures"])
    info.update(key=key, entry=str(entry), produced=made, shared=True)
    return version


_ROOT = re.compile(r"<([A-Za-z_][\w.\-]*)[^>]*>")


def _xml_parts(text: str) -> tuple[str, str, str]:
    """(head up to and with the root's opening tag, body, closing) of one of SUMO's outputs
    (``<?xml?>``, the configuration comment, then one root element)."""
    at = text.find("-->") + 3 if "-->" in text else 0
    m = _ROOT.search(text, at)
    if m is None or m.group(0).endswith("/>"):
        return text, "", ""
    close = text.rfind(f"</{m.group(1)}>")
    close = len(text) if close < 0 else close
    return text[:m.end()], text[m.end():close], text[close:]


def merge_outputs(sumo_dir: Path, info: dict | None) -> None:
    """After SUMO closed: put the warm-up part of SUMO's outputs (from the entry) in front of
    the run's own, so the outputs read as those of a run that simulated its warm-up."""
    if not info or not info.get("shared"):
        return
    entry = Path(info["entry"])
    for name in MERGED_TEXT + MERGED_XML:
        warm, run = entry / name, sumo_dir / name
        if not warm.is_file() or not run.is_file():
            continue
        w, r = warm.read_text(encoding="utf-8"), run.read_text(encoding="utf-8")
        if name in MERGED_TEXT:
            merged = w + r
        else:
            head, body, tail = _xml_parts(r)
            merged = head + _xml_parts(w)[1].rstrip() + body + tail if tail else r
        tmp = run.with_name(f".{name}.tmp")
        tmp.write_text(merged, encoding="utf-8")
        os.replace(tmp, run)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m formation_traci.sumo.warm_state JOB_JSON", file=sys.stderr)
        return 2
    simulate(json.loads(Path(argv[0]).read_text(encoding="utf-8")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
