"""Further formations of a scenario ([[formations]]) and formations inserted by a flow
([[formation_flows]]); docs/scenarios.md, "Several formations"."""
from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from .base import NonNegFloat, PosFloat, Strict
from .comm_spec import CommSpec
from .formation_parts import ControllerSpec, LeaderSpec, MemberSpec
from .maneuvers import ManeuverSpec

NonNegInt = Annotated[int, Field(ge=0)]


class FormationSpec(Strict):
    """A further formation of the run: its own virtual leader, members and controller; the
    top-level ``leader``/``members``/``controller``/``comm`` are the first. On a road it has
    its own start, lane and departure time (docs/scenarios.md, "Several formations")."""

    id: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$", description="formation_id in the tables")
    leader: LeaderSpec
    members: list[MemberSpec] = Field(min_length=1, description="at least one member")
    controller: ControllerSpec = ControllerSpec()
    comm: CommSpec | None = Field(None, description="leader-to-member radio; default: perfect")
    maneuvers: list[ManeuverSpec] = Field(
        default_factory=list, description="its maneuvers (road; no join: docs/scenarios.md)")
    start: NonNegFloat | None = Field(None, description="road: its virtual car's arc length at departure [m]; "
                                      "default road.start")
    lane: NonNegInt | None = Field(None, description="road: the lane its slots' 'lanes' count from (its "
                                   "virtual car's lane); default road.lane")
    depart: NonNegFloat = Field(0.0, description="road: when its members enter the road [s] (run time; "
                                "its leader.speed profile's time starts then)")


def formation_fits(j: int, f: FormationSpec, road: bool) -> None:
    """[[formations]] entry j's fields fit the run (free space or a road)."""
    if f.comm is not None and set(f.comm.links) - {m.id for m in f.members}:
        raise ValueError(f"formations.{j}.comm.links names members not in the formation")
    if not road:
        if any(m.offset is None or m.position is None for m in f.members):
            raise ValueError(f"formations.{j}: free space needs 'offset' and 'position' for every member")
        given = [k for k in ("start", "lane") if getattr(f, k) is not None]
        if given or f.depart or f.maneuvers:
            raise ValueError(f"formations.{j}: {', '.join(given + ['depart'] * bool(f.depart) + ['maneuvers'] * bool(f.maneuvers))} "
                             "need a [road] (free-space formations all start at t = 0)")
    elif f.lane is not None and any(m.slot is None for m in f.members):
        raise ValueError(f"formations.{j}.lane: every member needs a road 'slot' (a lane moves road-frame "
                         "slots; virtual-car-frame 'offset' members keep the reference line)")


class FormationTemplate(Strict):
    """The formation a [[formation_flows]] entry inserts: one [[formations]] entry without id
    (its members need road slots)."""

    leader: LeaderSpec
    members: list[MemberSpec] = Field(min_length=1, description="at least one member")
    controller: ControllerSpec = ControllerSpec()
    comm: CommSpec | None = Field(None, description="leader-to-member radio; default: perfect")


class FormationFlowSpec(Strict):
    """Formations inserted while the run goes: every ``period_s``, at ``veh_per_hour``
    formation vehicles, or as the ``penetration`` share of a traffic flow's vehicles."""

    id: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_\-]+$", description="its formations are '<id>.<k>'")
    formation: FormationTemplate
    lane: NonNegInt | list[NonNegInt] = Field(description="the lane its formations enter (their slots' 'lanes' "
                                              "count from it); a list: formation k enters lane[k % len]")
    start: NonNegFloat | None = Field(None, description="arc length where its virtual cars enter [m]; default road.start")
    period_s: PosFloat | None = Field(None, description="one formation every this many seconds")
    veh_per_hour: PosFloat | None = Field(None, description="formation vehicles per hour (formations: / members)")
    penetration: float | None = Field(None, ge=0.0, lt=1.0, description="share of formation vehicles among the "
                                      "vehicles of flow 'of_flow' (that flow keeps the rest of its demand)")
    of_flow: str | None = Field(None, description="penetration: the [[traffic.flows]] id it is a share of")
    begin: NonNegFloat = Field(0.0, description="first formation due at this run time [s]")
    end: NonNegFloat | None = Field(None, description="no formation due after this run time [s]; default run.duration")

    @model_validator(mode="after")
    def _one_rule(self):
        rules = [k for k in ("period_s", "veh_per_hour", "penetration") if getattr(self, k) is not None]
        if len(rules) != 1:
            raise ValueError("give exactly one of 'period_s', 'veh_per_hour' or 'penetration'")
        if (self.penetration is None) != (self.of_flow is None):
            raise ValueError("'of_flow' is given with (and only with) 'penetration'")
        if isinstance(self.lane, list) and not self.lane:
            raise ValueError("lane: give a lane or a non-empty list of lanes")
        if any(m.slot is None for m in self.formation.members):
            raise ValueError("formation.members: every member of a flow's formation needs a road 'slot'")
        return self
