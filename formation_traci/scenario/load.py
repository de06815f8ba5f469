"""``load_scenario(path, **overrides)``: the one way a scenario file becomes a Scenario."""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from .bounds import cost_problems
from .schema import Scenario


class ScenarioError(ValueError):
    """A scenario file that cannot be used; ``problems`` lists (field path, message)."""

    def __init__(self, path: str | Path, problems: list[tuple[str, str]]):
        self.path = str(path)
        self.problems = problems
        lines = [f"{self.path}: {field}: {msg}" for field, msg in problems]
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
            item = (_field_path(err["loc"]), _describe(err))
            if item not in seen:
                seen.add(item)
                problems.append(item)
        raise ScenarioError(source, problems) from None
    problems = cost_problems(sc)
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
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ScenarioError(path, [("(syntax)", f"not valid TOML: {exc}")]) from None
    return parse_scenario(doc, path, **overrides)
