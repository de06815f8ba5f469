"""The sweep file: a TOML document validated into one frozen model (docs/sweeps.md).

Only the sweep's own structure is checked here; the scenario values it sets are checked
by :func:`formation_traci.scenario.load_scenario` when each case runs, so one bad grid
point fails one case, not the sweep.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (BaseModel, ConfigDict, Field, JsonValue, StringConstraints, ValidationError,
                      field_validator, model_validator)

from run_contract.errors import SweepError

DOTTED = r"^[A-Za-z_][A-Za-z0-9_]*(\.([A-Za-z_][A-Za-z0-9_]*|[0-9]+))*$"
DottedPath = Annotated[str, StringConstraints(pattern=DOTTED)]
Label = Annotated[str, StringConstraints(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,15}$")]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Pair = Annotated[list[Finite], Field(min_length=2, max_length=2)]
SEED_PATH = "run.seed"


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class Distribution(Strict):
    """One randomly sampled field: exactly one of ``uniform``, ``log_uniform``, ``choice``."""

    uniform: Pair | None = Field(None, description="[low, high): uniform draw")
    log_uniform: Pair | None = Field(None, description="[low, high), low > 0: uniform in log")
    choice: list[JsonValue] | None = Field(None, min_length=1, description="equally likely values")

    @model_validator(mode="after")
    def _one(self):
        given = [k for k in ("uniform", "log_uniform", "choice") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of 'uniform', 'log_uniform' or 'choice'")
        lo_hi = self.uniform or self.log_uniform
        if lo_hi is not None and not lo_hi[0] < lo_hi[1]:
            raise ValueError(f"need low < high (got {lo_hi})")
        if self.log_uniform is not None and self.log_uniform[0] <= 0:
            raise ValueError(f"log_uniform needs low > 0 (got {self.log_uniform[0]})")
        return self

    def draw(self, rng) -> JsonValue:
        """One sample, as a plain Python value.

        Parameters
        ----------
        rng : numpy.random.Generator
            The sweep's sampler.

        Returns
        -------
        float or JSON value
            A draw of the distribution.
        """
        if self.uniform is not None:
            return float(rng.uniform(*self.uniform))
        if self.log_uniform is not None:
            lo, hi = self.log_uniform
            return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        return self.choice[int(rng.integers(len(self.choice)))]


class RandomSpec(Strict):
    """``[random]``: ``n`` samples drawn with their own ``seed``; every other key is a field."""

    n: int = Field(ge=1, le=100_000, description="number of samples")
    seed: int = Field(ge=0, description="seed of the sampler (numpy default_rng)")
    fields: dict[DottedPath, Distribution] = Field(min_length=1)

    @model_validator(mode="before")
    @classmethod
    def _collect(cls, data: Any) -> Any:
        if isinstance(data, dict) and "fields" not in data:
            data = dict(data)
            data["fields"] = {k: data.pop(k) for k in list(data) if k not in ("n", "seed")}
        return data


class SweepFile(Strict):
    """The validated sweep file (field reference: docs/sweeps.md)."""

    name: str = ""
    description: str = ""
    base: str = Field(min_length=1, description="scenario TOML, relative to the sweep file")
    seeds: list[Annotated[int, Field(ge=0)]] = Field(min_length=1, description="run.seed values")
    overrides: dict[DottedPath, JsonValue] = Field(default_factory=dict)
    grid: dict[DottedPath, Annotated[list[JsonValue], Field(min_length=1)]] = Field(default_factory=dict)
    random: RandomSpec | None = None
    labels: dict[DottedPath, Label] = Field(default_factory=dict)
    timeout_s: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = Field(
        None, description="wall-clock limit per case [s]; a case over it fails")
    baseline: Literal["same", "absent"] | None = Field(
        None, description="run each case's twin too, as `sweep --baseline` does (formation_traci/run/twins.py); "
        "the command line's --baseline wins")

    @field_validator("seeds")
    @classmethod
    def _unique_seeds(cls, v):
        if len(set(v)) != len(v):
            raise ValueError(f"seeds must be unique (got {v})")
        return v

    @model_validator(mode="after")
    def _keys(self):
        rand = list(self.random.fields) if self.random else []
        swept = list(self.grid) + rand
        problems = []
        for where, keys in (("overrides", self.overrides), ("grid", self.grid), ("random", rand)):
            if SEED_PATH in keys:
                problems.append(f"{where} sets {SEED_PATH!r}: list the seeds in 'seeds'")
        for k in sorted(set(self.grid) & set(rand)):
            problems.append(f"{k!r} is both in [grid] and in [random]")
        for k in sorted(set(self.overrides) & set(swept)):
            problems.append(f"{k!r} is both in [overrides] and swept")
        for a in swept:
            for b in swept:
                if a != b and b.startswith(a + "."):
                    problems.append(f"swept fields {a!r} and {b!r} overlap")
        for k in self.labels:
            if k not in swept:
                problems.append(f"[labels] names {k!r}, which is not swept")
        if len(set(self.labels.values())) != len(self.labels):
            problems.append("[labels] values must be unique")
        if problems:
            raise ValueError("; ".join(problems))
        return self

    def swept(self) -> list[str]:
        """Swept dotted paths in case-id order: the grid's, then the random ones.

        Returns
        -------
        list of str
            The paths.
        """
        return list(self.grid) + (list(self.random.fields) if self.random else [])


def _quote(part: Any) -> str:
    s = str(part)
    return f'"{s}"' if "." in s else s


def _field_path(loc: tuple) -> str:
    parts = []
    for i, item in enumerate(loc):
        if item in ("[key]",) or (item == "fields" and i > 0 and loc[i - 1] == "random"):
            continue
        if isinstance(item, str) and (item.startswith(("list[", "function-", "constrained-"))
                                      or item in ("int", "float", "str", "bool", "dict")):
            continue
        parts.append(_quote(item))
    return ".".join(parts) or "(document)"


def _describe(err: dict) -> str:
    if err["type"] == "extra_forbidden":
        return "unknown field (not part of the sweep schema; check spelling)"
    if err["type"] == "missing":
        return "required field is missing"
    msg = err["msg"].removeprefix("Value error, ")
    got = err.get("input")
    if not isinstance(got, (dict, list)) and err["type"] != "value_error":
        return f"{msg} (got {got!r})"
    return msg


def read_sweep_file(path: str | Path) -> tuple[SweepFile, dict]:
    """Read and validate a sweep TOML file.

    Parameters
    ----------
    path : str or Path
        Sweep TOML file.

    Returns
    -------
    (SweepFile, dict)
        The validated model and the parsed TOML document.

    Raises
    ------
    SweepError
        If the file is missing, not TOML, or breaks the sweep schema (file, field, reason).
    """
    path = Path(path)
    if not path.is_file():
        raise SweepError(path, [("(file)", "file not found")])
    from ..scenario.load import read_toml

    doc = read_toml(path, SweepError)
    try:
        return SweepFile.model_validate(doc), doc
    except ValidationError as exc:
        problems = []
        for err in exc.errors():
            item = (_field_path(err["loc"]), _describe(err))
            if item not in problems:
                problems.append(item)
        raise SweepError(path, problems) from None
