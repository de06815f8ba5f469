"""Dotted paths of the scenario schema: is a path a field, and which field is nearest to one that
is not (for the message that refuses it)."""
from __future__ import annotations

import difflib
import types
import typing

from pydantic import BaseModel


def _models(annotation) -> list[type[BaseModel]]:
    """The pydantic models an annotation can hold (through Optional, unions, lists, Annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    out = []
    for arg in typing.get_args(annotation):
        out += _models(arg)
    if isinstance(annotation, types.GenericAlias) or typing.get_origin(annotation) is not None:
        return list(dict.fromkeys(out))
    return out


def _children(models: list[type[BaseModel]], key: str) -> list[type[BaseModel]] | None:
    """The models under ``key`` of any of ``models`` ([] for a plain value), None if no model has it."""
    found = None
    for m in models:
        if key in m.model_fields:
            found = (found or []) + _models(m.model_fields[key].annotation)
    return found


def nearest_field(root: type[BaseModel], dotted: str) -> str | None:
    """The schema's dotted path nearest to ``dotted`` (its first unknown name replaced by the
    closest field there), or None if the path is a field or nothing is close."""
    models, keys = [root], dotted.split(".")
    for i, key in enumerate(keys):
        if key.isdigit() or not models:  # a list index, or inside a plain value (a table of values)
            continue
        below = _children(models, key)
        if below is None:
            names = sorted({f for m in models for f in m.model_fields})
            close = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
            return ".".join(keys[:i] + close[:1] + keys[i + 1:]) if close else None
        models = below
    return None
