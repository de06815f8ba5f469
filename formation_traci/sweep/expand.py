"""From a sweep file to its cases: ``expand_sweep(path) -> list[Case]``.

Order (stable): grid points (itertools.product over the [grid] keys in file order, the last
key varying fastest), then the random samples, then the seeds (innermost). Case ids read
``c0007-k1.0-vph1600-s2``: index, one ``<label><value>`` per swept field, seed.
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import json
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, JsonValue

from run_contract.errors import SweepError

from ..scenario.load import ScenarioError, read_toml
from .spec import SEED_PATH, SweepFile, read_sweep_file


MAX_TAGS = 120
"""Longest value part of a case id [characters]."""


class Case(BaseModel):
    """One run of a sweep: its swept values, seed and the full override dict."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    index: int
    id: str
    seed: int
    values: dict[str, JsonValue]  # swept dotted path -> value
    overrides: dict[str, JsonValue]  # [overrides], then values, then run.seed (applied in order)


@dataclass(frozen=True)
class Sweep:
    """A loaded sweep: the file, its validated content, the base scenario and the cases."""

    path: Path
    spec: SweepFile
    raw: dict  # the sweep file as parsed TOML
    base: Path  # resolved scenario file
    cases: tuple[Case, ...]
    random_keys: tuple[str, ...]
    sets: dict = field(default_factory=dict)  # --set: dotted path -> value, in every case


def _labels(keys: list[str], given: dict[str, str]) -> dict[str, str]:
    """Case-id label of each swept path: [labels], else its last name (initials if long)."""
    def short(k: str) -> str:
        name = [p for p in k.split(".") if not p.isdigit()][-1]
        return name if len(name) <= 8 else "".join(w[0] for w in name.split("_") if w)

    auto = {k: short(k) for k in keys if k not in given}
    taken = list(auto.values()) + list(given.values())
    for k, lab in list(auto.items()):
        if taken.count(lab) > 1:  # members.0.k, members.1.k -> m0k, m1k
            auto[k] = "".join(p if p.isdigit() else p[0] for p in k.split(".")[:-1]) + lab
    return {k: given.get(k) or auto[k] for k in keys}


def _fmt(value: Any, sampled: bool) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        s = f"{value:.4g}" if sampled or len(repr(value)) > 8 else repr(value)
    elif isinstance(value, (int, str)):
        s = str(value)
    else:
        return "h" + hashlib.sha1(json.dumps(value, sort_keys=True).encode()).hexdigest()[:6]
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", s)[:16]


def _check_path(doc: Any, dotted: str) -> str | None:
    """Why ``dotted`` cannot be set in ``doc`` (structure only), or None."""
    node = doc
    keys = dotted.split(".")
    for i, key in enumerate(keys):
        where = ".".join(keys[:i]) or "(document)"
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                return f"{where} is a list of {len(node)} entries: {key!r} is not an index into it"
            node = node[int(key)]
        elif isinstance(node, dict):
            node = node.get(key, {})
        else:
            return f"{where} is a value ({node!r}), not a table: cannot set {dotted!r}"
    return None


def _set(doc: dict, dotted: str, value: Any) -> None:
    *head, last = dotted.split(".")
    node = doc
    for key in head:
        node = node[int(key)] if isinstance(node, list) else node.setdefault(key, {})
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value


def _unknown_fields(base: Path, doc: dict, spec: SweepFile) -> list[tuple[str, str]]:
    """The [overrides], [grid] and [random] paths that are not scenario fields (with the
    nearest field), found before any case runs; ``doc``: the base with [overrides] set. Values
    are not judged here: a bad grid value fails its case alone."""
    from ..scenario.fields import nearest_field
    from ..scenario.load import parse_scenario
    from ..scenario.schema import Scenario

    sample = {**spec.overrides, **{k: v[0] for k, v in spec.grid.items()}}
    if spec.random is not None:
        sample.update({k: d.draw(np.random.default_rng(0)) for k, d in spec.random.fields.items()})
    where = {**{k: "random" for k in sample if k not in spec.overrides and k not in spec.grid},
             **{k: "grid" for k in spec.grid}, **{k: "overrides" for k in spec.overrides}}
    out = []
    for k, v in sample.items():
        try:
            parse_scenario(doc, base, **{k: v})
        except ScenarioError as exc:
            hit = next((f for f, msg in exc.problems if msg.startswith("unknown field")
                        and (k == f or k.startswith(f + "."))), None)
            if hit is not None:
                near = nearest_field(Scenario, k)
                out.append((f'{where[k]}."{k}"', f"{hit} is not a scenario field"
                            + (f"; nearest field: {near}" if near else "")))
    return out


def _base_doc(path: Path, spec: SweepFile) -> tuple[Path, dict]:
    base = (path.parent / spec.base).resolve()
    if not base.is_file():
        raise SweepError(path, [("base", f"scenario file not found: {base}")])
    try:
        doc = read_toml(base)
    except ScenarioError as exc:
        raise SweepError(path, [("base", f"{base}: {msg}") for _, msg in exc.problems]) from None
    return base, doc


def load_sweep(path: str | Path, sets: dict[str, Any] | None = None) -> Sweep:
    """Read, validate and expand a sweep file.

    Parameters
    ----------
    path : str or Path
        Sweep TOML file (docs/sweeps.md).
    sets : dict, optional
        Dotted path -> value set in every case after ``[overrides]`` (the command line's
        ``--set``); checked here with the base scenario (values too), so a bad one refuses
        the whole sweep.

    Returns
    -------
    Sweep
        The validated file, the resolved base scenario and the cases in order.

    Raises
    ------
    SweepError
        If the file breaks the sweep schema, the base scenario is missing or not TOML, or
        a dotted path cannot exist in the base scenario (an index past the end of a list,
        a path through a value). Scenario values are checked per case, not here.
    """
    path = Path(path).resolve()
    spec, raw = read_sweep_file(path)
    base, doc = _base_doc(path, spec)
    problems = []
    doc = copy.deepcopy(doc)
    for where, keys in (("overrides", list(spec.overrides)), ("grid", list(spec.grid)),
                        ("random", list(spec.random.fields) if spec.random else [])):
        for k in keys:
            why = _check_path(doc, k)
            if why:
                problems.append((f'{where}."{k}"', why))
            elif where == "overrides":
                _set(doc, k, spec.overrides[k])
    problems += _unknown_fields(base, doc, spec)
    sets = dict(sets or {})
    for k in sets:
        why = _check_path(doc, k)
        if k.split(".")[0] == "road" and doc.get("road") is None:
            why = why or "the base scenario has no [road] (free space): --set does not make it a road scenario"
        if k == SEED_PATH or k in spec.swept() or any(k.startswith(a + ".") or a.startswith(k + ".")
                                                       for a in spec.swept()):
            why = why or "is swept (or is run.seed): it cannot be set for every case"
        if why:
            problems.append((f"--set {k}", why))
    if problems:
        raise SweepError(path, problems)
    if sets:
        from ..scenario import load_scenario  # the values, as the case will read them

        load_scenario(base, **{**spec.overrides, **sets})

    labels = _labels(spec.swept(), spec.labels)
    if len(set(labels.values())) != len(labels):
        raise SweepError(path, [("labels", f"case-id labels collide ({labels}); name them in [labels]")])
    grid_points = [dict(zip(spec.grid, combo)) for combo in itertools.product(*spec.grid.values())]
    samples: list[dict] = [{}]
    random_keys: tuple[str, ...] = ()
    if spec.random is not None:
        rng = np.random.default_rng(spec.random.seed)
        random_keys = tuple(spec.random.fields)
        samples = [{k: d.draw(rng) for k, d in spec.random.fields.items()}
                   for _ in range(spec.random.n)]
    combos = [(g, s, seed) for g in grid_points for s in samples for seed in spec.seeds]
    width = max(4, len(str(len(combos) - 1)))
    cases = []
    for i, (g, s, seed) in enumerate(combos):
        values = {**g, **s}
        tags = "".join(f"-{labels[k]}{_fmt(v, k in random_keys)}" for k, v in values.items())
        tags = tags[:MAX_TAGS]  # the index keeps ids unique; directory names stay short
        cases.append(Case(index=i, id=f"c{i:0{width}d}{tags}-s{seed}", seed=seed, values=values,
                          overrides={**spec.overrides, **sets, **values, SEED_PATH: seed}))
    return Sweep(path=path, spec=spec, raw=raw, base=base, cases=tuple(cases),
                 random_keys=random_keys, sets=sets)


def expand_sweep(path: str | Path) -> list[Case]:
    """The cases of a sweep file, in their stable order.

    Parameters
    ----------
    path : str or Path
        Sweep TOML file.

    Returns
    -------
    list of Case
        ``id`` (e.g. ``c0007-k1.0-vph1600-s2``), ``values`` (swept dotted path -> value),
        ``seed`` and ``overrides`` (what ``load_scenario(base, **overrides)`` receives).

    Raises
    ------
    SweepError
        As :func:`load_sweep`.
    """
    return list(load_sweep(path).cases)
