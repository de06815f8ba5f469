"""``[sumo] options`` of a scenario: checked before SUMO starts, outputs kept in the run.

SUMO may neither read nor write a file outside the run directory: options that read files
(configuration, networks, routes, additionals, states, weights, ...), that redirect or prefix
outputs, or that open ports are refused as bad input; options that the tool sets itself are
refused with the scenario field to use instead. An output may be asked for by a bare file
name (``--summary-output summary.xml``): SUMO writes it into the run's ``sumo/`` directory.
The option names and types come from the SUMO binary itself (``sumo --help``).
"""
from __future__ import annotations

import functools
import math
import re
import subprocess
from pathlib import Path

from ..scenario.load import ScenarioError

MANAGED = {
    "net-file": "road.net", "route-files": "traffic.flows", "begin": "run and traffic.warmup",
    "end": "run.duration", "step-length": "run.step", "seed": "run.seed", "random": "run.seed",
    "lateral-resolution": "sumo.lateral_resolution", "log": "(the run's sumo/sumo.log)",
    "collision.action": "(always 'warn': collisions are events)", "fcd-output": "sumo.fcd",
    "device.ssm.file": "sumo.ssm", "device.ssm.probability": "sumo.ssm",
    "device.ssm.explicit": "sumo.ssm", "device.ssm.measures": "sumo.ssm",
    "device.ssm.thresholds": "sumo.ssm", "device.ssm.range": "sumo.ssm",
    "device.friction.probability": "sumo.friction_device",
    "collision.mingap-factor": "(always 0)", "collision.check-junctions": "(always on)",
    "no-step-log": "(always on)", "error-log": "(the run's sumo/messages.log)",
    "no-warnings": "(always on: warnings are sumo_message events)", "duration-log.disable": "(always on)",
    "device.friction.stdDev": "sumo.friction_device",
}
"""SUMO options the tool sets, and the scenario field that controls each."""
REFUSED_SECTIONS = ("Configuration", "Input", "Communication", "TraCI Server", "GUI Only")
"""Option sections refused whole: they load files or open connections."""
REFUSED_STR = {"output-prefix", "output-suffix", "save-state.suffix", "device.toc.file",
               "device.taxi.dispatch-algorithm.params", "xml-validation", "xml-validation.net",
               "xml-validation.routes"}
"""String options that name files or paths (or fetch schemas)."""
ENDS_SUMO = {"version", "print-options", "help"}
"""Options that make SUMO print something and exit instead of running."""
WRITES_CWD = {"save-state.times", "save-state.period"}
"""Options that make SUMO write files into the working directory (save-state.prefix is a path)."""
BOOL_VALUES = {"true", "false", "on", "off", "yes", "no", "1", "0", "t", "f", "x", "-"}
OWN_FILES = {"ssm.xml", "sumo.log", "traffic.rou.xml", "fcd.parquet"}
BARE_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*$")
_LINE = re.compile(r"^\s+(?:-(\w), )?--(\S+)(?: (\S+))?")


@functools.lru_cache(maxsize=1)
def sumo_option_table() -> dict[str, tuple[str, str, str]]:
    """Every option of the SUMO binary: name or abbreviation -> (name, type, section)."""
    from .adapter import sumo_binary

    text = subprocess.run([sumo_binary(), "--help"], capture_output=True, text=True, timeout=60).stdout
    table: dict[str, tuple[str, str, str]] = {}
    section = ""
    for line in text.splitlines():
        if line.endswith(" Options:") and not line.startswith(" "):
            section = line[: -len(" Options:")]
            continue
        m = _LINE.match(line)
        if m and section:
            short, name, typ = m.groups()
            kind = typ if typ and typ.isupper() or (typ or "").endswith("[]") else "BOOL"
            table[name] = (name, kind, section)
            if short:
                table[short] = (name, kind, section)
    return table


def _split(options: list[str]) -> list[tuple[int, str, str | None, bool]]:
    """(index, option name, inline value or None, is an option) for each item."""
    out = []
    for i, item in enumerate(options):
        if item.startswith("--"):
            name, eq, val = item[2:].partition("=")
            out.append((i, name, val if eq else None, True))
        elif item.startswith("-") and len(item) > 1 and not item[1].isdigit() and item[1] != ".":
            out.append((i, item[1:], None, True))
        else:
            out.append((i, item, None, False))
    return out


def _value_problem(name: str, kind: str, value: str | None) -> str | None:
    """Why ``value`` cannot be the value of option ``name`` of type ``kind``, or None."""
    if kind == "BOOL":
        if value is not None and value.lower() not in BOOL_VALUES:
            return f"--{name} is a switch: give --{name} or --{name}=true|false (got {value!r})"
        return None
    if value is None:
        return f"--{name} needs a value ({kind.lower()})"
    try:
        if kind == "INT":
            int(value)
        elif kind in ("FLOAT", "TIME") and not math.isfinite(float(value)):
            return f"--{name} needs a finite {kind.lower()} value (got {value!r})"
    except ValueError:
        return f"--{name} needs a {kind.lower()} value (got {value!r})"
    return None


def _problem(name: str, kind: str, section: str, value: str | None) -> str | None:
    if name in ENDS_SUMO:
        return f"--{name} makes SUMO print and exit instead of running"
    if name in WRITES_CWD:
        return f"--{name} makes SUMO write state files into the working directory, outside the run"
    if name in MANAGED:
        return f"--{name} is set by formation-traci; use {MANAGED[name]}"
    if section in REFUSED_SECTIONS:
        return f"--{name} ({section.lower()} option) would make SUMO read files or open connections"
    if name in REFUSED_STR:
        return f"--{name} names files outside the run"
    if kind == "FILE":
        if not (name.endswith("-output") or name.endswith(".output") or name == "netstate-dump"):
            return f"--{name} reads or writes a file outside the run"
        if value is None or not BARE_NAME.match(value) or value in OWN_FILES or value.startswith("."):
            return (f"--{name} needs a bare file name (no directory; not {sorted(OWN_FILES)}); SUMO writes "
                    f"it into the run's sumo/ directory (got {value!r})")
    return _value_problem(name, kind, value)


def check_options(options: list[str], source) -> None:
    """Refuse (ScenarioError, field ``sumo.options``) any option SUMO does not know, or one
    that reads or writes outside the run."""
    if not options:
        return
    table = sumo_option_table()
    problems, seen, values = [], {}, set()
    items = _split(options)
    for j, (i, name, inline, is_opt) in enumerate(items):
        if not is_opt:
            if i not in values:
                problems.append((f"sumo.options.{i}", f"{options[i]!r} is not an option (SUMO would read a "
                                                      "bare argument as a configuration file)"))
            continue
        if name not in table:
            problems.append((f"sumo.options.{i}", f"unknown SUMO option {options[i]!r}"))
            continue
        full, kind, section = table[name]
        value = inline
        nxt = items[j + 1] if j + 1 < len(items) else None
        if value is None and nxt is not None and not nxt[3] and (kind != "BOOL" or nxt[1].lower() in BOOL_VALUES):
            value = nxt[1]
            values.add(nxt[0])
        why = _problem(full, kind, section, value)
        if full in seen:
            why = f"--{full} is given twice (also sumo.options.{seen[full]})"
        seen.setdefault(full, i)
        if why:
            problems.append((f"sumo.options.{i}", why))
    if problems:
        raise ScenarioError(source or "<scenario>", problems)


def place_outputs(options: list[str], sumo_dir: Path) -> list[str]:
    """The options with every output file name made a path inside ``sumo_dir`` (checked
    by :func:`check_options` first)."""
    if not options:
        return []
    table = sumo_option_table()
    out = list(options)
    items = _split(options)
    for j, (i, name, inline, is_opt) in enumerate(items):
        if not is_opt or name not in table or table[name][1] != "FILE":
            continue
        full = table[name][0]
        if inline is not None:
            out[i] = f"--{full}={sumo_dir / inline}"
        elif j + 1 < len(items):
            out[items[j + 1][0]] = str(sumo_dir / items[j + 1][1])
    return out
