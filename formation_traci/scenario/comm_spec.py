"""The ``[comm]`` table of a scenario: the radio between the virtual leader and the members
(docs/communication.md)."""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from ..comm.channel import gilbert_rates
from .base import NonNegFloat, PosFloat, Strict

JITTER_DISTRIBUTIONS = Literal["exponential", "uniform"]
LOSS_MODELS = Literal["none", "independent", "bursty"]


class CommLinkSpec(Strict):
    """One member's link from the virtual leader: fields left out take the [comm] value."""

    delay_s: NonNegFloat | None = Field(None, description="constant part of the delay [s]")
    jitter_s: NonNegFloat | None = Field(None, description="mean of the random extra delay [s]")
    jitter: JITTER_DISTRIBUTIONS | None = Field(None, description="distribution of the extra delay")
    loss: LOSS_MODELS | None = Field(None, description="loss model")
    loss_p: Annotated[float, Field(ge=0, lt=1)] | None = Field(None, description="mean loss probability [-]")
    loss_burst: Annotated[float, Field(ge=1, allow_inf_nan=False)] | None = Field(
        None, description="mean burst length of the bursty model [beacons]")


class CommSpec(CommLinkSpec):
    """The radio between the virtual leader and the members (docs/communication.md).

    Every link carries the same beacons (one broadcast); delay, jitter and loss are drawn per
    link from the run's seed in their own random stream. The defaults are perfect
    communication: every control instant, no delay, no loss."""

    beacon_hz: PosFloat | None = Field(None, description="beacon rate [Hz]; default: every control step")
    delay_s: NonNegFloat = Field(0.0, description="constant part of the delay [s]")
    jitter_s: NonNegFloat = Field(0.0, description="mean of the random extra delay [s]")
    jitter: JITTER_DISTRIBUTIONS = Field(
        "exponential", description="extra delay: 'exponential' (std = mean) or 'uniform' on [0, 2 jitter_s]")
    loss: LOSS_MODELS = Field("none", description="'none', 'independent' (Bernoulli) or 'bursty' (Gilbert-Elliott)")
    loss_p: Annotated[float, Field(ge=0, lt=1)] = Field(0.0, description="mean loss probability [-]")
    loss_burst: Annotated[float, Field(ge=1, allow_inf_nan=False)] = Field(
        4.0, description="mean burst length of the bursty model [beacons]")
    timeout_s: PosFloat = Field(1.0, description="a member that has heard nothing for longer falls back [s]")
    links: dict[str, CommLinkSpec] = Field(default_factory=dict, description="per-member overrides, by member id")
    outages: list[Annotated[list[NonNegFloat], Field(min_length=2, max_length=2)]] = Field(
        default_factory=list, description="[t0, t1] windows [s] in which every beacon sent is lost on every link")

    @model_validator(mode="after")
    def _windows(self):
        for k, (t0, t1) in enumerate(self.outages):
            if t1 <= t0:
                raise ValueError(f"outages[{k}]: t1 ({t1}) must be after t0 ({t0})")
        return self

    @model_validator(mode="after")
    def _bursts(self):
        for where, spec in [("", self)] + [(f"links.{k}: ", v) for k, v in self.links.items()]:
            p = spec.loss_p if spec.loss_p is not None else self.loss_p
            burst = spec.loss_burst if spec.loss_burst is not None else self.loss_burst
            if (spec.loss or self.loss) == "bursty":
                try:
                    gilbert_rates(p, burst)
                except ValueError as exc:
                    raise ValueError(f"{where}{exc}") from None
        return self
