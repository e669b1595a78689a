"""Decisions about missions: building (compile, validate), import/export, checks against a UAV."""

from __future__ import annotations

import asyncio
import re
import uuid
from collections.abc import Sequence
from typing import Any

from server.airspace.check import ZoneShape
from server.airspace.plan import check_flight
from server.assets.models import Asset, AssetKind
from server.assets.repository import AssetRepository
from server.audit.service import record
from server.kit.errors import Unprocessable
from server.kit.etag import NO_PRECONDITION, IfMatch
from server.kit.paging import Page, Paged
from server.kit.principal import Principal
from server.kit.service import Service
from server.kit.uow import UnitOfWork
from server.missions import qgc, qgc_export, wpl
from server.missions.build import Built, build, home_of
from server.missions.flight import estimate_flight
from server.missions.items import MissionItem, item_dicts, items_of
from server.missions.models import Mission, MissionKind
from server.missions.reach import (
    DEFAULT_CRUISE_MPS,
    UavFigures,
    base_position,
    check_from_base,
    launch_home,
    uav_figures,
)
from server.missions.repository import MissionRepository
from server.missions.schemas import HomeIn, SurveyIn
from server.missions.validate import FlightEstimate, Home, MissionLimits, Problem


def limits_from(settings: Any) -> MissionLimits:
    """Mission limits from the server settings (`mission_*` fields when present), else defaults."""
    d = MissionLimits()
    return MissionLimits(
        min_alt_m=float(getattr(settings, "mission_min_alt_m", d.min_alt_m)),
        max_alt_m=float(getattr(settings, "mission_max_alt_m", d.max_alt_m)),
        max_area_m2=float(getattr(settings, "mission_max_area_m2", d.max_area_m2)),
        max_items=int(getattr(settings, "mission_max_items", d.max_items)),
    )


def rejected(problems: list[Problem], code: str = "invalid_mission") -> Unprocessable:
    """The 422 error listing every problem."""
    first = problems[0]
    more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
    return Unprocessable(
        f"{first.where}: {first.what}{more}", code=code, details=[p.as_dict() for p in problems]
    )


def estimate(mission: Mission, cruise_speed_mps: float = DEFAULT_CRUISE_MPS) -> FlightEstimate:
    """Path length and flight time of a stored mission."""
    speed = mission.speed_mps or cruise_speed_mps
    return estimate_flight(items_of(mission.items), speed, home_of(mission.home))


def safe_filename(name: str, suffix: str) -> str:
    """A file name made of the mission's name, safe in a Content-Disposition header."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "mission"
    return f"{stem[:80]}{suffix}"


class MissionService(Service):
    """Creates, changes, imports, exports and checks missions of the caller's organisation."""

    def __init__(self, uow: UnitOfWork, principal: Principal, limits: MissionLimits) -> None:
        super().__init__(uow, principal)
        self.repo = MissionRepository(self.db, principal)
        self.limits = limits

    async def _audit(self, action: str, mission: Mission, **details: Any) -> None:
        await record(self.uow, self.principal, action, target=str(mission.id), **details)

    async def list_missions(self, page: Page, kind: MissionKind | None) -> Paged[Mission]:
        """Missions of the caller's organisation, oldest first."""
        return await self.repo.list_filtered(page, kind)

    async def delete(self, mission_id: uuid.UUID, expect: IfMatch = NO_PRECONDITION) -> None:
        """Delete a mission (PreconditionFailed when `expect` names another version)."""
        mission = await self.repo.get(mission_id, lock=True)
        expect.check(mission.version, f"mission {mission.id}")
        await self._audit("mission.deleted", mission, name=mission.name)
        await self.repo.delete(mission)

    async def uav(self, uav_id: uuid.UUID | None) -> Asset | None:
        """The UAV a check is against (NotFound for another organisation's, 422 for a base)."""
        if uav_id is None:
            return None
        uav = await AssetRepository(self.db, self.principal).get(uav_id)
        if uav.kind != AssetKind.uav:
            raise Unprocessable(f"asset {uav.id} is not a UAV", code="not_a_uav")
        return uav

    async def _built(
        self,
        kind: MissionKind,
        items: list[MissionItem] | None,
        survey: SurveyIn | None,
        home: Home | None,
    ) -> Built:
        # a survey of a thousand vertices takes a noticeable fraction of a second: off the event loop
        built, problems = await asyncio.to_thread(build, kind, items, survey, home, self.limits)
        if problems:
            raise rejected(problems)
        return built

    async def create(
        self,
        *,
        name: str,
        description: str,
        kind: MissionKind,
        items: list[MissionItem] | None,
        survey: SurveyIn | None,
        home: HomeIn | None,
        speed_mps: float | None,
        source: str = "api",
        extras: dict[str, Any] | None = None,
    ) -> Mission:
        """A new mission, validated (and compiled, for a survey); raises Unprocessable listing problems."""
        built = await self._built(kind, items, survey, home_of(home))
        mission = Mission(
            organization_id=self.repo.principal.organization_id,
            name=name,
            description=description,
            kind=kind,
            source=source,
            items=item_dicts(built.items),
            home=home.model_dump() if home else None,
            speed_mps=speed_mps,
            survey=survey.model_dump(mode="json") if survey else None,
            survey_plan=built.survey_plan,
            extras=extras or {},
            created_by=self.repo.principal.actor_id,
        )
        mission = await self.repo.add(mission)
        if source == "api":
            await self._audit("mission.created", mission, name=mission.name, kind=kind.value)
        else:
            await self._audit(
                "mission.imported", mission, name=name, source=source, items=len(mission.items)
            )
        return mission

    async def update(
        self,
        mission_id: uuid.UUID,
        changes: dict[str, Any],
        body: Any,
        expect: IfMatch = NO_PRECONDITION,
    ) -> Mission:
        """Apply a partial update; items and survey are validated (and compiled) again.
        PreconditionFailed when `expect` names another version than the stored one."""
        mission = await self.repo.get(mission_id, lock=True)
        expect.check(mission.version, f"mission {mission.id}")
        home = (
            body.home if "home" in changes else (HomeIn(**mission.home) if mission.home else None)
        )
        items = body.items if "items" in changes else None
        if mission.kind == MissionKind.waypoints and "items" not in changes:
            items = items_of(mission.items)
        survey = (
            body.survey
            if "survey" in changes
            else (SurveyIn.model_validate(mission.survey) if mission.survey else None)
        )
        if {"items", "survey", "home"} & changes.keys():
            built = await self._built(mission.kind, items, survey, home_of(home))
            mission.items = item_dicts(built.items)
            mission.survey = survey.model_dump(mode="json") if survey else None
            mission.survey_plan = built.survey_plan
            mission.home = home.model_dump() if home else None
        for key in ("name", "description", "speed_mps"):
            if key in changes and (changes[key] is not None or key == "speed_mps"):
                setattr(mission, key, changes[key])
        await self.repo.db.flush()
        await self._audit("mission.updated", mission, changes=sorted(changes))
        return mission

    async def import_file(
        self, imported: qgc.Imported, *, name: str, description: str, source: str
    ) -> Mission:
        """A waypoints mission from an imported file."""
        home = (
            HomeIn(lat=imported.home.lat, lon=imported.home.lon, alt=imported.home.alt)
            if imported.home
            else None
        )
        return await self.create(
            name=name,
            description=description,
            kind=MissionKind.waypoints,
            items=imported.items,
            survey=None,
            home=home,
            speed_mps=imported.speed_mps
            if imported.speed_mps and imported.speed_mps <= 30
            else None,
            source=source,
            extras=imported.extras,
        )

    @staticmethod
    def export(mission: Mission, fmt: str) -> tuple[str | dict[str, Any], str]:
        """The mission as a QGC plan (dict) or WPL text, and a file name."""
        items, home = items_of(mission.items), home_of(mission.home)
        if fmt == "wpl":
            return wpl.export_wpl(items, home), safe_filename(mission.name, ".waypoints")
        return (
            qgc_export.export_plan(items, home, mission.speed_mps, mission.extras),
            safe_filename(mission.name, ".plan"),
        )

    async def get(self, mission_id: Any) -> Mission:
        """A mission of the caller's organisation (NotFound otherwise)."""
        return await self.repo.get(mission_id)

    async def base(self, base_id: uuid.UUID | None) -> Asset | None:
        """The base a check flies from (NotFound for another organisation's, 422 for a UAV)."""
        if base_id is None:
            return None
        base = await AssetRepository(self.db, self.principal).get(base_id)
        if base.kind != AssetKind.landing_base:
            raise Unprocessable(f"asset {base.id} is not a landing base", code="not_a_base")
        return base

    async def zones(self, base_id: uuid.UUID | None, at: Any = None) -> list[ZoneShape]:
        """The airspace zones a flight from `base_id` at `at` must respect."""
        from server.airspace.service import AirspaceService

        await self.base(base_id)
        return await AirspaceService(self.uow, self.principal).applicable(base_id, at)

    def check(
        self,
        mission: Mission,
        uav: Asset | None,
        zones: Sequence[ZoneShape] = (),
        base: Asset | None = None,
    ) -> dict[str, Any]:
        """Every problem of a stored mission, its path against the airspace `zones` and the
        plan's geoFence, and its flight against the UAV's endurance and reach.

        With `base` (and its position known) the flight starts and ends there: the legs
        base -> first item and last item -> base count in the estimate, the endurance and the
        airspace. Pure computation on loaded rows: callers on the event loop run it with
        asyncio.to_thread.
        """
        problems: list[Problem] = []
        survey = SurveyIn.model_validate(mission.survey) if mission.survey else None
        items = items_of(mission.items) if mission.kind == MissionKind.waypoints else None
        _, found = build(mission.kind, items, survey, home_of(mission.home), self.limits)
        problems += found
        launch = launch_home(base.attributes if base else None, home_of(mission.home))
        airspace = check_flight(items_of(mission.items), launch, list(zones), mission.extras)
        figures = UavFigures()
        if uav is not None:
            if uav.kind != AssetKind.uav:
                raise Unprocessable(f"asset {uav.id} is not a UAV", code="not_a_uav")
            figures = uav_figures(uav.attributes, problems)
        located = base is not None and base_position(base.attributes) is not None
        judged = check_from_base(
            items_of(mission.items),
            mission.speed_mps or figures.cruise_mps,
            launch,
            base.name if base is not None and located else None,
            figures,
        )
        uav_out: dict[str, Any] | None = None
        if uav is not None:
            problems += judged.problems
            uav_out = {
                "id": uav.id,
                "name": uav.name,
                "endurance_s": figures.endurance_s,
                "usable_endurance_s": round(figures.usable_endurance_s, 1),
                "cruise_speed_mps": figures.cruise_mps,
                "reach_m": round(judged.reach_m, 1),
            }
        base_out = None
        if base is not None:
            base_out = {
                "id": base.id,
                "name": base.name,
                "lat": launch.lat if located and launch else None,
                "lon": launch.lon if located and launch else None,
                "farthest_m": round(judged.farthest_m, 1)
                if located and judged.farthest_m is not None
                else None,
            }
        return {
            "valid": not problems and not airspace,
            "problems": [p.as_dict() for p in problems] + [a.as_dict() for a in airspace],
            "estimate": judged.estimate.as_dict(),
            "uav": uav_out,
            "base": base_out,
        }
