"""Building blocks of the scenario schema: constrained numbers, the strict base model and
piecewise signals (shared by scenario/schema.py and the tables in their own modules)."""
from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, model_validator

PosFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Pair = Annotated[list[Finite], Field(min_length=2, max_length=2)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class ProfileSpec(Strict):
    """A piecewise signal: values at knot times, linear or smoothstep between."""

    t: list[NonNegFloat] = Field(min_length=1, description="knot times [s], strictly increasing")
    values: list[Finite] = Field(min_length=1, description="signal at the knots")
    interp: Literal["linear", "smooth"] = "linear"

    @model_validator(mode="after")
    def _knots(self):
        if len(self.t) != len(self.values):
            raise ValueError(f"t and values must have the same length (got {len(self.t)} and {len(self.values)})")
        if any(b <= a for a, b in zip(self.t, self.t[1:])):
            raise ValueError("t must be strictly increasing")
        return self


Signal = Union[Finite, ProfileSpec]
