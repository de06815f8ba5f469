"""Building blocks of the scenario schema: constrained numbers and the strict base model
(core/spec.py, shared with the laws' schemas) and piecewise signals (shared by
scenario/schema.py and the tables in their own modules)."""
from __future__ import annotations

from typing import Literal, Union

from pydantic import Field, model_validator

from ..core.spec import Finite, NonNegFloat, Pair, PosFloat, Strict  # noqa: F401


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
