"""``load_scenario(path, **overrides)``: the one way a scenario file becomes a Scenario."""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from .bounds import cost_problems
from .ids import id_clashes
from .kind import kind_problems
from .schema import Scenario


MAX_LISTED = 20
"""Problems listed in a ScenarioError's message at most (the count says how many in all)."""
MAX_FILE_BYTES = 1 << 20
"""Largest scenario file read [B]: a scenario is a page of TOML (the biggest bundled one is 3 kB)."""
MAX_DEPTH = 32
"""Deepest nesting of tables and arrays in a scenario (the schema needs 4)."""


class ScenarioError(ValueError):
    """A scenario file that cannot be used; ``problems`` lists (field path, message); the
    message lists the first :data:`MAX_LISTED`."""

    def __init__(self, path: str | Path, problems: list[tuple[str, str]]):
        self.path = str(path)
        self.problems = problems
        lines = [f"{self.path}: {field}: {msg}" for field, msg in problems[:MAX_LISTED]]
        if len(problems) > MAX_LISTED:
            lines.append(f"... and {len(problems) - MAX_LISTED} more")
        super().__init__(f"invalid scenario ({len(problems)} problem"
                         f"{'s' if len(problems) != 1 else ''}):\n  " + "\n  ".join(lines))


def _field_path(loc: tuple) -> str:
    parts = []
    for item in loc:
        if isinstance(item, int):
            parts.append(str(item))
        elif item in ("float", "int", "str", "ProfileSpec", "GainSpec", "constrained-float"):
            continue  # union branch names pydantic adds to the location
        elif str(item).startswith(("literal[", "function-", "tuple[", "list[")):
            continue
        else:
            parts.append(str(item))
    return ".".join(parts) or "(document)"


SPEC_TABLES = ("law_params", "variant_params")
"""Fields holding the tables a registered module's SPEC validates ([controller.<law>],
[vehicle.<variant>]: scenario/formation_parts.py): their problems are named by the table's own
path, ``controller.<law>.<field>``."""


def _problems(err: dict) -> list[tuple[str, str]]:
    """(field path, what is wrong) of one pydantic error."""
    path = _field_path(err["loc"])
    head, _, last = path.rpartition(".")
    if last in SPEC_TABLES and err["type"] == "value_error":
        out = []
        for part in err["msg"].removeprefix("Value error, ").split("; "):
            where, sep, what = part.partition(": ")
            out.append((f"{head}.{where}", what) if sep else (path, part))
        return out
    if err["type"] == "extra_forbidden":
        from .fields import nearest_field
        near = nearest_field(Scenario, path)
        return [(path, _describe(err) + (f"; nearest field: {near}" if near else ""))]
    return [(path, _describe(err))]


def _describe(err: dict) -> str:
    msg = err["msg"]
    if err["type"] == "extra_forbidden":
        return "unknown field (not part of the scenario schema; check spelling)"
    if err["type"] == "missing":
        return "required field is missing"
    got = err.get("input")
    if err["type"] not in ("extra_forbidden", "missing") and not isinstance(got, (dict, list)):
        return f"{msg} (got {got!r})"
    return msg


def _set_dotted(doc: dict, dotted: str, value: Any) -> str | None:
    """Set ``doc[a][b]... = value`` for ``dotted = "a.b..."`` (list items by index); returns
    why it cannot be applied, or None."""
    keys = dotted.split(".")
    node = doc
    for i, key in enumerate(keys):
        last = i == len(keys) - 1
        where = ".".join(keys[:i]) or "(document)"
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                return f"{where} has no item {key!r}"
            if last:
                node[int(key)] = value
            else:
                node = node[int(key)]
        elif isinstance(node, dict):
            if last:
                node[key] = value
            else:
                node = node.setdefault(key, {})
        else:
            return f"{where} is not a table, so {dotted} cannot be set"
    return None


def parse_scenario(doc: dict, source: str | Path = "<scenario>", **overrides: Any) -> Scenario:
    """Validate a TOML-like dict, with dotted-path overrides (``run.seed=3``), into a Scenario."""
    doc = copy.deepcopy(doc)
    problems = []
    for dotted, value in overrides.items():
        if value is not None:
            why = _set_dotted(doc, dotted, value)
            if why:
                problems.append((dotted, f"override not applied: {why}"))
    if problems:
        raise ScenarioError(source, problems)
    try:
        sc = Scenario.model_validate(doc)
    except ValidationError as exc:
        problems, seen = [], set()
        for err in exc.errors():
            for item in _problems(err):
                if item not in seen:
                    seen.add(item)
                    problems.append(item)
        raise ScenarioError(source, problems) from None
    problems = cost_problems(sc) + kind_problems(sc) + id_clashes(sc)  # ids with the formation flows expanded
    if problems:
        raise ScenarioError(source, problems)
    return sc


def load_scenario(path: str | Path, **overrides: Any) -> Scenario:
    """Read a scenario TOML file and validate it; ``overrides`` map dotted field paths to values.

    Raises
    ------
    ScenarioError
        If the file is missing, is not valid TOML, or breaks the schema; the message names
        the file, the dotted field path and what was expected.
    """
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(path, [("(file)", "file not found")])
    return parse_scenario(read_toml(path, ScenarioError), path, **overrides)


def read_toml(path: Path, error=ScenarioError) -> dict:
    """The TOML document in ``path``, or ``error(path, problems)``: a file over
    :data:`MAX_FILE_BYTES`, nested deeper than :data:`MAX_DEPTH`, not UTF-8 or not TOML."""
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise error(path, [("(file)", f"at most {MAX_FILE_BYTES} bytes (got {size})")])
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise error(path, [("(syntax)", f"not valid TOML: {exc}")]) from None
    except OSError as exc:
        raise error(path, [("(file)", f"cannot be read: {exc.strerror}")]) from None
    depth = _nesting(text)
    if depth > MAX_DEPTH:
        raise error(path, [("(document)", f"tables and arrays nested at most {MAX_DEPTH} deep (got {depth})")])
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(path, [("(syntax)", f"not valid TOML: {exc}")]) from None
    except RecursionError:
        raise error(path, [("(document)", f"tables and arrays nested at most {MAX_DEPTH} deep")]) from None


def _nesting(text: str) -> int:
    """An upper bound of the nesting of inline arrays and tables: the most brackets open at once
    (brackets inside strings count too; a scenario has few)."""
    depth = most = 0
    for ch in text:
        if ch in "[{":
            depth += 1
            most = max(most, depth)
        elif ch in "]}":
            depth = max(0, depth - 1)
    return most
