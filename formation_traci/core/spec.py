"""Building blocks of every parameter schema (the scenario's tables, scenario/; a law's
``SPEC``, control/laws): constrained numbers and the strict base model (pydantic)."""
from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

PosFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Pair = Annotated[list[Finite], Field(min_length=2, max_length=2)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


def defaults(spec: type[BaseModel]) -> dict:
    """{parameter: default} of a schema whose every field has a default."""
    return {name: field.default for name, field in spec.model_fields.items()}
