"""Scenario schema of the SUMO road (``[road]``) and the background traffic (``[traffic]``,
``[[traffic.flows]]``), routes given as edge lists or by their two ends. See docs/scenarios.md."""
from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import ConfigDict, Field, model_validator

from .base import NonNegFloat, Pair, PosFloat, Strict


class RouteEnds(Strict):
    """A route by its two ends (and via points), joined along the mainline (sumo/routes.py)."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True, strict=True)
    from_: str | Pair = Field(alias="from", description="first edge id, or an [x, y] network position [m]")
    to: str | Pair = Field(description="last edge id, or an [x, y] network position [m]")
    via: list[str | Pair] = Field(default_factory=list, description="edges or [x, y] positions [m] the route passes, in order "
                                        "(to pick one of several paths)")


RouteValue = Union[Annotated[list[str], Field(min_length=1)], RouteEnds]


class RoadSpec(Strict):
    """The SUMO road the virtual car drives along (its presence makes the run a SUMO run)."""

    net: str = Field(description="bundled network name (sumo_nets/) or a .net.xml path relative to the scenario file")
    route: RouteValue | None = Field(None, description="edges of the main route, or {from, to} ends; default: the network's main route")
    lane: int = Field(1, ge=0, description="reference lane index the virtual car follows (0 = rightmost)")
    start: NonNegFloat = Field(200.0, description="virtual car's arc length along the route at t = 0 [m]")
    end_margin: NonNegFloat = Field(150.0, description="the run stops when the formation's front is this close to the route end [m]")
    fit_tolerance: PosFloat | None = Field(None, description="largest distance of the fitted reference line from SUMO's "
                                           "lane centre [m]: the 160 m fit held within it (road/smoothing.py); default: "
                                           "0.6, and on a coarsely drawn road a longer fit within half the narrowest "
                                           "lane less 0.2 m (road/coarse.py)")


class FlowSpec(Strict):
    id: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$")
    route: RouteValue | None = Field(None, description="edges, or {from, to} ends; default: the main route")
    veh_per_hour_per_lane: PosFloat | None = Field(None, description="demand per lane of the first edge [veh/h]")
    veh_per_hour: PosFloat | None = Field(None, description="total demand [veh/h]")
    depart_lane: Literal["best", "random", "free", "allowed", "first"] | Annotated[int, Field(ge=0)] = Field(
        "best", description="SUMO departLane; 'best' spreads the flow over the lanes that continue")
    depart_speed: Literal["desired", "max", "avg", "random", "speedLimit", "last"] | NonNegFloat = Field(
        "max", description="SUMO departSpeed; 'max': the highest safe speed, so dense demand fits in")
    depart_pos: Literal["base", "free", "random_free", "random", "last"] | NonNegFloat = Field(
        "base", description="SUMO departPos [m from the edge start if a number]")
    begin: NonNegFloat = Field(0.0, description="SUMO time the flow starts [s] (warm-up included)")
    end: PosFloat | None = Field(None, description="SUMO time the flow ends [s]; default: end of the run")
    mix: dict[Literal["car", "truck"], Annotated[float, Field(ge=0, le=1)]] = Field(
        default_factory=lambda: {"car": 0.85, "truck": 0.15}, description="vehicle type shares, summing to 1")
    speed_dev: NonNegFloat = Field(0.1, le=0.5, description="spread of the speed factor (normal, mean 1) [-]")
    populate: bool = Field(False, description="also place the flow's vehicles along its whole route when it "
                           "begins (SUMO ids '<id>.p<n>'), at the density its demand has in free flow at the "
                           "route's speed limit, so a long road is full from the start instead of after a "
                           "warm-up as long as the route's travel time; the flow's route must lie on the main route")

    @model_validator(mode="after")
    def _demand(self):
        if (self.veh_per_hour is None) == (self.veh_per_hour_per_lane is None):
            raise ValueError("give exactly one of 'veh_per_hour' or 'veh_per_hour_per_lane'")
        if abs(sum(self.mix.values()) - 1.0) > 1e-9:
            raise ValueError(f"mix shares must sum to 1 (got {sum(self.mix.values())})")
        return self


class SectionsSpec(Strict):
    """Measurement cross-sections along the main route (docs/metrics.md, "Sections"): every
    background vehicle is timed through each of them in a formation run and in its twin."""

    enabled: bool = Field(True, description="place the sections and drain the stretch after the run")
    upstream: NonNegFloat = Field(200.0, description="first section this far before road.start [m] (clamped to the route)")
    downstream: NonNegFloat = Field(200.0, description="last section this far beyond the formation's furthest "
                                    "reach at its top set speed over run.duration [m] (clamped to the route)")
    inner: int = Field(3, ge=0, le=20, description="sections spread evenly over the formation's path")
    drain_max: NonNegFloat = Field(600.0, description="after the formation's last step SUMO runs on, without the "
                                   "formation, until every vehicle in the stretch has left it, at most this long [s]")


class TrafficSpec(Strict):
    flows: list[FlowSpec] = Field(default_factory=list)
    sections: SectionsSpec = Field(default_factory=SectionsSpec)
    warmup: NonNegFloat = Field(0.0, description="SUMO time simulated before the formation is inserted [s]")
    record_radius: PosFloat | None = Field(300.0, description="the formation senses (one context subscription per formation) and records the "
                                        "background vehicles within this distance of its members [m]: a smaller radius also "
                                        "hides vehicles from the governor and the maneuvers; omit for all")
    measure_at: NonNegFloat | None = Field(1000.0, description="arc length along the main route where flow and "
                                           "density are measured [m] (clamped to the route); None: not measured")
